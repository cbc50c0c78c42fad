"""``runs.csv``: one line per finished run, durable line by line, so a table resumes.

Each :meth:`RunResults.append` writes one complete line in a single write, then flushes and
fsyncs it, so a killed process loses at most the run it was computing. A crash in the middle
of a write leaves a last line without its newline: it is ignored when reading and cut off
before the next append. The file has one writer (the table runner's process); a run is keyed
by (scene, seed, method) and a key is never written twice.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from stucco_drake.eval.replay import ROW_FIELDS

_HEADER = ",".join(ROW_FIELDS) + "\n"


def row_key(row: dict) -> tuple[str, int, str]:
    """The (scene, seed, method) that identifies a run."""
    return str(row["scene"]), int(row["seed"]), str(row["method"])


def _format(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool | np.bool_):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value)  # round-trips exactly; NaN is written "nan"
    return str(value)


def _parse(record: list[str]) -> dict:
    row = dict(zip(ROW_FIELDS, record, strict=True))
    grasp = row["grasp_success"]
    return {
        "scene": row["scene"],
        "seed": int(row["seed"]),
        "method": row["method"],
        "grasp_success": None if grasp == "" else grasp == "1",
        "ce_cm": float(row["ce_cm"]),
        "fmi": float(row["fmi"]),
        "ambiguity": float(row["ambiguity"]),
        "n_contacts": int(row["n_contacts"]),
        "wall_time_s": float(row["wall_time_s"]),
    }


class RunResults:
    """The results file at ``path`` (created with its header on the first append)."""

    fields = ROW_FIELDS

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._keys: set | None = None

    def _scan(self) -> tuple[list[dict], int]:
        """(rows, byte length of the complete lines); the header is checked."""
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            return [], 0
        complete = data[: data.rfind(b"\n") + 1]  # drops an unterminated (truncated) last line
        if not complete:
            return [], 0
        lines = complete.decode("utf-8").splitlines()
        if lines[0] + "\n" != _HEADER:
            raise ValueError(
                f"{self.path}: not a runs file of this version (header {lines[0][:80]!r}, "
                f"expected {_HEADER.strip()!r})"
            )
        rows = []
        for number, record in enumerate(csv.reader(lines[1:]), start=2):
            try:
                rows.append(_parse(record))
            except ValueError as error:
                raise ValueError(f"{self.path}:{number}: malformed run line ({error})") from None
        return rows, len(complete)

    def rows(self) -> list[dict]:
        """Every complete run, typed: grasp_success True/False/None, NaN for missing metrics."""
        return self._scan()[0]

    def done(self) -> set[tuple[str, int, str]]:
        """Keys (scene, seed, method) of the runs already recorded."""
        if self._keys is None:
            self._keys = {row_key(row) for row in self.rows()}
        return set(self._keys)

    def append(self, row: dict) -> bool:
        """Record one finished run durably; False (nothing written) if its key is done."""
        missing = [f for f in ROW_FIELDS if f not in row]
        if missing:
            raise ValueError(f"append: row lacks field(s) {', '.join(missing)}")
        key = row_key(row)
        if key in self.done():
            return False
        for name in ("ce_cm", "fmi", "ambiguity", "wall_time_s"):
            if not isinstance(row[name], float | int) or math.isinf(row[name]):
                raise ValueError(
                    f"append: {name} must be a finite number or NaN, got {row[name]!r}"
                )
        _, length = self._scan()
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerow([_format(row[f]) for f in ROW_FIELDS])
        line = buffer.getvalue()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT, 0o644)
        try:
            # Cut a truncated last line (or a torn header) so the new line starts cleanly.
            os.ftruncate(fd, length)
            os.lseek(fd, length, os.SEEK_SET)
            payload = (line if length else _HEADER + line).encode("utf-8")
            os.write(fd, payload)  # one write per line: a crash tears at most this line
            os.fsync(fd)
        finally:
            os.close(fd)
        self._keys.add(key)
        return True
