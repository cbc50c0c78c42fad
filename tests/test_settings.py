"""Settings dataclasses overridden from YAML mappings (core/settings.py): fields replaced by
kind, nested settings by nested mappings, every bad key or value a one-line error naming its
path, and the plain form written beside results reading back to the same settings."""

import dataclasses

import numpy as np
import pytest
import yaml

from stucco_drake.core.probe_params import ProbeParams
from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.core.settings import plain_settings, settings_changes, settings_with


def test_fields_are_replaced_by_kind_and_nested_settings_by_nested_mappings():
    base = RummageParams()
    given = yaml.safe_load("max_actions: 80\nstop_confidence: 1\n"
                           "probe: {clearance: 0.05, end_face_first: true,"
                           " long_face_offsets: [-0.8, 0, 0.8]}\n")
    settings = settings_with(base, given)
    assert settings.max_actions == 80 and isinstance(settings.max_actions, int)
    assert settings.stop_confidence == 1.0 and isinstance(settings.stop_confidence, float)
    assert settings.probe.clearance == 0.05 and settings.probe.end_face_first is True
    assert settings.probe.long_face_offsets == (-0.8, 0.0, 0.8)
    # Everything not named keeps its default, nested fields included.
    assert settings.probe.max_bumps == base.probe.max_bumps
    assert settings.coverage == base.coverage
    assert settings_with(base, None) is base and settings_with(base, {}) is base


@pytest.mark.parametrize("given, message", [
    ({"max_bump": 2}, "probe-params: max_bump: not a setting of ProbeParams (known: "),
    ({"max_bumps": 1.5}, "probe-params: max_bumps: expected an integer, got 1.5"),
    ({"max_bumps": True}, "probe-params: max_bumps: expected an integer, got True"),
    ({"clearance": "wide"}, "probe-params: clearance: expected a number, got 'wide'"),
    ({"direct_only": 1}, "probe-params: direct_only: expected true or false, got 1"),
    ({"long_face_offsets": 0.5}, "probe-params: long_face_offsets: expected a list of numbers"),
    ([1, 2], "probe-params: expected a mapping of ProbeParams fields, got list"),
    ({"face_step": 0}, "face_step: expected a positive step (m) or null, got 0.0"),
])  # fmt: skip
def test_a_bad_key_or_value_names_its_path(given, message):
    with pytest.raises(ValueError) as error:
        settings_with(ProbeParams(), given, "probe-params: ")
    assert message in str(error.value) and "\n" not in str(error.value)


def test_a_bad_nested_value_names_its_full_path():
    with pytest.raises(ValueError, match=r"^probe\.standoff: expected a number, got None$"):
        settings_with(RummageParams(), {"probe": {"standoff": None}})


def test_the_plain_form_reads_back_as_the_same_settings_and_changes_name_only_differences():
    settings = settings_with(RummageParams(), {"retouches": 3, "probe": {"max_bumps": 2}})
    plain = yaml.safe_load(yaml.safe_dump(plain_settings(settings)))
    assert settings_with(RummageParams(), plain) == settings
    # numpy floats among the defaults come out as plain floats YAML can write.
    assert plain["probe"]["cylinder_angles"] == pytest.approx([np.pi / 4, -np.pi / 4])
    changes = settings_changes(settings, RummageParams())
    assert set(changes) == {"retouches", "probe"} and changes["retouches"] == 3
    assert changes["probe"]["max_bumps"] == 2
    assert settings_changes(RummageParams(), RummageParams()) == {}
    assert dataclasses.is_dataclass(settings.probe)
