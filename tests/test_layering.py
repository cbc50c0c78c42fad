"""The layering rule: imports point down the packages, and the method's core never imports
Drake."""

import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "stucco_drake"

#: Each package's layer (docs/architecture.md): a module may import its own package and the
#: packages of lower layers only. Packages of one layer do not import each other.
LAYERS = {
    "runtime": 0,
    "core": 1,
    "eval": 2,
    "robot": 2,
    "systems": 3,
    "scenes": 4,
    "tracking": 4,
    "bor": 5,
    "second_robot": 5,
    "training": 6,
    "cli": 7,
}


def _imported_packages(path: Path) -> set[str]:
    """The stucco_drake packages a file imports, at module level or inside functions."""
    imported = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module:
            names = ([f"{node.module}.{alias.name}" for alias in node.names]
                     if node.module == "stucco_drake" else [node.module])  # fmt: skip
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        imported.update(n.split(".")[1] for n in names
                        if n.startswith("stucco_drake.") and not n.startswith("stucco_drake._"))
    return imported


def test_every_module_sits_in_a_layered_package():
    flat = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert flat == [], f"modules outside the packages: {flat}"
    packages = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert packages == set(LAYERS)


def test_imports_point_down():
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE)
        if len(relative.parts) == 1:  # stucco_drake/__init__.py: the kernels pin only
            assert _imported_packages(path) == {"runtime"}
            continue
        own = relative.parts[0]
        for other in _imported_packages(path) - {own}:
            if LAYERS[other] >= LAYERS[own]:
                upward.append(f"{relative} ({own}) imports {other}")
    assert upward == []


def test_core_and_eval_import_without_drake():
    code = (
        "import pkgutil, importlib, sys\n"
        "import stucco_drake.core as core, stucco_drake.eval as ev\n"
        "for package in (core, ev):\n"
        "    for info in pkgutil.walk_packages(package.__path__, package.__name__ + '.'):\n"
        "        importlib.import_module(info.name)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'pydrake'))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "[]", result.stdout
