# Two commands on a fresh machine: `make test` and `make demo`. Each creates .venv when it is
# missing and (re)installs the project only when pyproject.toml or constraints.txt changed since
# the last install; constraints.txt holds the exact package versions the results were made with.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: test demo lint bench clean system-deps

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml constraints.txt | $(BIN)/python
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test,dask]'
	touch $(STAMP)

# Debian packages: headless Chromium renders a Meshcat recording in a test; Graphviz's dot
# renders the Diagram picture.
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
system-deps:
	@command -v chromium >/dev/null && command -v dot >/dev/null || { \
	  $(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q chromium graphviz; }

test: $(STAMP) system-deps
	$(BIN)/python -m pytest -q -n auto

# Blind Object Retrieval on scene FB end to end at Table II's setting (contact motion, STUCCO's
# parameters): rummage, track, estimate, grasp; writes a standalone Meshcat recording and a
# plot of the tracked points under out/.
demo: $(STAMP)
	mkdir -p out
	$(BIN)/stucco-drake run --scene FB --method stucco --seed 0 --dx-model cone \
	    --stucco-params results/table_ii/stucco.yaml --record out/fb.html --plot out/fb.png

lint: $(STAMP)
	$(BIN)/ruff check .

# Speed, printed (docs/performance.md): the tracker alone, the target-pose hypotheses on logged
# episodes, then a whole BOR episode beside the scene alone (several minutes).
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_soft_tracker.py
	$(BIN)/python benchmarks/bench_pose_hypotheses.py
	$(BIN)/python benchmarks/bench_bor.py

clean:
	rm -rf $(VENV) build *.egg-info
