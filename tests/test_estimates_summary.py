"""``stucco-drake estimates``: the rows of one and of two processes, and the settings a table
folder recorded."""


def test_logs_scored_in_parallel_give_the_rows_of_one_process_in_log_order(tmp_path):
    """Two committed development logs (an IB box, a TC can), scored by ``estimates`` in one
    process and in two: the same rows, byte for byte, in the logs' order."""
    import shutil
    from pathlib import Path

    from stucco_drake.cli import main

    source = Path(__file__).resolve().parents[1] / "results" / "development" / "probe"
    (tmp_path / "logs").mkdir()
    for name in ("TC-L1001_0.npz", "IB-L1002_0.npz"):
        shutil.copy(source / "logs" / name, tmp_path / "logs" / name)
    for name in ("table_config.yaml", "runs.csv"):
        shutil.copy(source / name, tmp_path / name)
    written = []
    for workers in ("1", "2"):
        assert main(["estimates", "--table", str(tmp_path), "--workers", workers]) == 0
        written.append((tmp_path / "estimates_stucco.csv").read_text(encoding="utf-8"))
    assert written[0] == written[1]
    scenes = [line.split(",")[1] for line in written[0].splitlines()[1:]]
    assert scenes == ["IB-L1002", "TC-L1001"]


def test_a_tables_recorded_hypothesis_settings_are_replayed_unless_overridden(tmp_path):
    """A table folder whose config records hypothesis settings (``table --hypothesis-params``)
    is scored with them: the same rows as the same settings given to ``--hypothesis-params``,
    and other rows than the defaults give (a tempered confidence)."""
    import shutil
    from pathlib import Path

    import yaml

    from stucco_drake.cli import main

    source = Path(__file__).resolve().parents[1] / "results" / "development" / "probe"
    (tmp_path / "logs").mkdir()
    shutil.copy(source / "logs" / "TC-L1001_0.npz", tmp_path / "logs")
    for name in ("table_config.yaml", "runs.csv"):
        shutil.copy(source / name, tmp_path / name)
    target = tmp_path / "estimates_stucco.csv"
    assert main(["estimates", "--table", str(tmp_path)]) == 0  # recorded without the key
    defaults = target.read_text(encoding="utf-8")
    (tmp_path / "tempered.yaml").write_text("confidence_temperature: 3.0\n")
    assert main(["estimates", "--table", str(tmp_path), "--hypothesis-params",
                 str(tmp_path / "tempered.yaml")]) == 0  # fmt: skip
    given = (tmp_path / "estimates_stucco_tempered.csv").read_text(encoding="utf-8")
    config = yaml.safe_load((tmp_path / "table_config.yaml").read_text())
    config["hypothesis_params"] = {"confidence_temperature": 3.0}
    (tmp_path / "table_config.yaml").write_text(yaml.safe_dump(config))
    assert main(["estimates", "--table", str(tmp_path)]) == 0
    recorded = target.read_text(encoding="utf-8")
    assert recorded == given

    def confidence(rows: str) -> float:
        header, row = rows.splitlines()
        return float(row.split(",")[header.split(",").index("confidence")])

    assert confidence(recorded) < confidence(defaults)  # tempered: less sure
