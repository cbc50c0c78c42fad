"""Checks of what a user hands the command line, made before any work starts.

A bad input is reported as one :class:`InputError` line naming it; the CLI's ``main`` prints it
as ``stucco-drake <command>: error: <message>`` and exits with 2. Counts and seeds are checked by
argparse through the ``type=`` functions here; output files and folders are prepared (their
missing parent folders created, a write into them tried) by :func:`prepare_output_file` and
:func:`prepare_output_folder` after a command's other checks and before its work, so that an
unwritable path fails at once instead of after minutes of simulation.

Only the standard library is imported at module level: every layer's command may use this.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path


class InputError(ValueError):
    """A bad input (an argument, or a file one names); the message is one line naming it."""


# ------------------------------------------------------------------------- argparse types
def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def positive_int(text: str) -> int:
    """argparse ``type=`` of a count that must be 1 or more."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, got {value}")
    return value


def probability(text: str) -> float:
    """argparse ``type=`` of a probability threshold: a number in [0, 1]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1], got {text}")
    return value


def non_negative_int(text: str) -> int:
    """argparse ``type=`` of a seed or an index that must be 0 or more."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


# ---------------------------------------------------------------------------- output paths
def _reason(error: OSError) -> str:
    return error.strerror or type(error).__name__


def _create_folder(option: str, given: Path, folder: Path) -> None:
    """Creates ``folder`` and its missing parents for the path ``given`` to ``option``;
    InputError naming the file in the way."""
    existing = next(p for p in (folder, *folder.parents) if p.exists() or p == Path(p.anchor))
    if not existing.is_dir():
        where = "" if existing == given else f"{existing} "
        raise InputError(f"{option} {given}: {where}is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"{option} {given}: cannot create {folder} ({_reason(error)})") from None


def prepare_output_folder(option: str, path: str | os.PathLike) -> Path:
    """The output folder ``path`` of command-line option ``option``, created if missing and
    tried with a scratch file; InputError (one line) when it cannot be written."""
    folder = Path(path)
    _create_folder(option, folder, folder)
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise InputError(f"{option} {folder}: cannot write in it ({_reason(error)})") from None
    return folder


def prepare_output_file(option: str, path: str | os.PathLike | None) -> Path | None:
    """The output file ``path`` of command-line option ``option`` (None passes through), its
    parent folders created and the file opened for appending (and removed again when it did
    not exist): InputError (one line) when it cannot be written. An existing file is left as
    it is."""
    if path is None:
        return None
    file = Path(path)
    if file.is_dir():
        raise InputError(f"{option} {file}: is a folder, not a file")
    _create_folder(option, file, file.parent)
    existed = file.exists()
    try:
        with open(file, "a"):
            pass
    except OSError as error:
        raise InputError(f"{option} {file}: cannot be written ({_reason(error)})") from None
    if not existed:
        file.unlink()
    return file


# ----------------------------------------------------------------------------- input files
def read_stucco_params(path: str | os.PathLike | None):
    """STUCCO's parameters from the YAML file given to ``--stucco-params`` (None: None, the
    command's default); InputError (one line) when it cannot be read or holds a bad value."""
    if path is None:
        return None
    from stucco_drake.core.params import SoftTrackingParams

    try:
        return SoftTrackingParams.from_yaml(Path(path))
    except ValueError as error:
        raise InputError(f"--stucco-params: {error}") from None


def read_settings(option: str, path: str | os.PathLike | None, default):
    """``default`` (a settings dataclass instance) with the overrides of the YAML file given to
    ``option`` (None: ``default``; see :func:`~stucco_drake.core.settings.settings_with`);
    InputError (one line naming the option, the file and the key) when it cannot be read or
    holds a bad key or value."""
    if path is None:
        return default
    from stucco_drake.core.settings import settings_with, yaml_file_data

    try:
        data = yaml_file_data(path, option)
        return settings_with(default, data if data is not None else {}, f"{option} {path}: ")
    except ValueError as error:
        raise InputError(str(error)) from None


def policy_settings_of(policy: str, path, settings_classes: Mapping):
    """(settings, how they differ from the defaults) of the policy named ``policy``: its
    settings class (``settings_classes[policy]``) with the overrides of the YAML file at
    ``path`` (None: the defaults); (None, None) for ``prescribed``. InputError (one line) for
    a bad file, or a file for a policy without settings."""
    if policy == "prescribed" or policy not in settings_classes:
        if path is not None:
            raise InputError(f"--policy-params: --policy {policy} takes no settings")
        return None, None
    from stucco_drake.core.settings import settings_changes

    default = settings_classes[policy]()
    settings = read_settings("--policy-params", path, default)
    return settings, settings_changes(settings, default)


def hypothesis_settings_of(path):
    """(settings, how they differ from the defaults) of the target-pose hypotheses
    (:class:`~stucco_drake.core.hypothesis_params.HypothesisParams`) with the overrides of
    the YAML file given to ``--hypothesis-params`` at ``path``; (None, {}) for None, the
    estimator's defaults. InputError (one line) for a missing file or a bad key or value."""
    if path is None:
        return None, {}
    from stucco_drake.core.hypothesis_params import HypothesisParams
    from stucco_drake.core.settings import settings_changes

    default = HypothesisParams()
    settings = read_settings("--hypothesis-params", path, default)
    return settings, settings_changes(settings, default)
