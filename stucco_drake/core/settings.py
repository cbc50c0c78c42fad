"""Frozen settings dataclasses overridden from plain mappings (a YAML file's contents).

The policies' and estimators' settings are frozen dataclasses with the defaults the results
were made with. :func:`settings_with` returns a copy with some fields replaced from a mapping,
nested dataclasses by nested mappings, each value checked against the type of the field's
default, so that a misspelt key or a value of the wrong kind is a one-line error naming the
key's path before any work starts. :func:`plain_settings` is the reverse: the settings as
plain Python values, for writing beside results.
"""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Mapping
from pathlib import Path


def yaml_text_data(text: str, who: str, where: str):
    """The data of the YAML ``text`` read from ``where`` (None for an empty document);
    ValueError ``"{who}: {where} is not valid YAML (...)"`` on one line otherwise."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        reason = " ".join(str(error).split())  # PyYAML's message spans several lines
        raise ValueError(f"{who}: {where} is not valid YAML ({reason})") from None


def yaml_file_data(path, who: str):
    """The data of the YAML file at ``path`` (None for an empty file); ValueError on one line
    starting ``"{who}: "`` when it is missing, unreadable or not valid YAML."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"{who}: no such file {path}") from None
    except (OSError, UnicodeDecodeError) as error:
        reason = getattr(error, "strerror", None) or "not UTF-8 text"
        raise ValueError(f"{who}: cannot read {path} ({reason})") from None
    return yaml_text_data(text, who, str(path))


def _checked(default, value, where: str):
    """``value`` as the kind of ``default`` (a bool, int, float, str, tuple of numbers, a
    nested settings dataclass, or None: an optional number); ValueError naming ``where``
    otherwise."""
    if dataclasses.is_dataclass(default):
        return settings_with(default, value, where + ".")
    if default is None:  # an optional number, unset by default
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise ValueError(f"{where}: expected a number or null, got {value!r}")
        return None if value is None else float(value)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{where}: expected true or false, got {value!r}")
        return value
    if isinstance(default, numbers.Integral):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise ValueError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    if isinstance(default, numbers.Real):
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ValueError(f"{where}: expected a string, got {value!r}")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple) or not all(
                isinstance(v, numbers.Real) and not isinstance(v, bool) for v in value):
            raise ValueError(f"{where}: expected a list of numbers, got {value!r}")
        return tuple(float(v) for v in value)
    raise ValueError(f"{where}: cannot be set from a file")


def settings_with(default, mapping: Mapping | None, where: str = ""):
    """A copy of the frozen settings dataclass instance ``default`` with the fields that
    ``mapping`` names replaced (None or empty: ``default`` itself).

    Args:
        default: the settings to start from (a dataclass instance).
        mapping: field name -> value; a nested settings dataclass takes a nested mapping.
        where: prefix of the key paths in error messages (e.g. ``"--policy-params "``).

    Raises:
        ValueError: naming the key's path: not a mapping, an unknown field, or a value of
            another kind than the field's default (an integer where a number is expected is
            accepted; a number where an integer is, is not).
    """
    if mapping is None:
        return default
    if not isinstance(mapping, Mapping):
        label = where.rstrip(". :")
        raise ValueError(f"{label + ': ' if label else ''}expected a mapping of "
                         f"{type(default).__name__} fields, got {type(mapping).__name__}")
    fields = {field.name for field in dataclasses.fields(default)}
    changes = {}
    for key, value in mapping.items():
        if key not in fields:
            raise ValueError(f"{where}{key}: not a setting of {type(default).__name__} "
                             f"(known: {', '.join(sorted(fields))})")
        changes[key] = _checked(getattr(default, key), value, f"{where}{key}")
    return dataclasses.replace(default, **changes) if changes else default


def plain_settings(settings) -> dict:
    """The settings dataclass instance as plain Python values (dicts, lists, floats, ints,
    bools, strings): what a YAML dump can write and read back the same."""
    def plain(value):
        if isinstance(value, dict):
            return {key: plain(item) for key, item in value.items()}
        if isinstance(value, list | tuple):
            return [plain(item) for item in value]
        if isinstance(value, bool | str) or value is None:
            return value
        if isinstance(value, numbers.Integral):
            return int(value)
        return float(value)

    return plain(dataclasses.asdict(settings))


def settings_changes(settings, default) -> dict:
    """The fields (plain values, see :func:`plain_settings`) in which ``settings`` differs
    from ``default`` (two instances of one settings dataclass); a nested settings dataclass
    that differs is given whole. Empty when they are equal."""
    new, old = plain_settings(settings), plain_settings(default)
    return {key: value for key, value in new.items() if value != old[key]}


__all__ = ["plain_settings", "settings_changes", "settings_with"]
