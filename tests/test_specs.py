"""Peg-hole specs: presets, extractability (eqs 2.1-2.3, w' < w, v' < v), bad input."""

import dataclasses

import pytest

from peghole_mjx.geometry.specs import (
    PRESETS,
    DualSpec,
    InfeasibleGeometryError,
    check_dual_extractable,
    dual_spec,
    get_preset,
    rect_spec,
    validate,
)


def test_presets_are_the_corrected_thesis_samples():
    # Table 3.2 with E2 applied, Table 2.2 with E1 applied
    assert PRESETS["rect-1"].clearance_mm == pytest.approx(0.6)
    assert PRESETS["rect-2"].clearance_mm == pytest.approx(0.1)
    assert PRESETS["rect-3"].clearance_mm == pytest.approx(0.05)
    for name, r in (("dual-1", 5.7), ("dual-2", 6.0), ("dual-3", 6.05)):
        spec = PRESETS[name]
        assert spec.peg_radii_mm == (r, r) and spec.hole_radii_mm == (6.1, 6.1)
        assert spec.hole_distance_mm == spec.peg_distance_mm == 40.0
        assert spec.length_mm == 50.0
    # the printed clearance ratios C = (R - r) / R of Table 2.2 match r = 5.7 and 6.0 mm
    assert PRESETS["dual-1"].clearance_ratio == pytest.approx(0.06557, abs=1e-5)
    assert PRESETS["dual-2"].clearance_ratio == pytest.approx(0.01639, abs=1e-5)
    assert PRESETS["dual-3"].clearance_ratio == pytest.approx(0.00819, abs=1e-5)
    for spec in PRESETS.values():
        assert validate(spec) is spec


def test_printed_rect_sample_3_is_rejected_naming_the_condition():  # erratum E2
    with pytest.raises(InfeasibleGeometryError) as err:
        rect_spec((60.1, 40.1), (60.5, 40.5), 150.0)
    assert err.value.condition == "w' < w"
    assert "60.5" in str(err.value) and "60.1" in str(err.value)


def test_printed_dual_sample_3_is_rejected_by_eq_2_1():  # erratum E1
    with pytest.raises(InfeasibleGeometryError) as err:
        dual_spec(6.1, 6.5, 40.0, 50.0)
    assert "2.1" in err.value.condition
    assert err.value.values["r_P1"] == 6.5


def test_v_condition_checked_separately():
    with pytest.raises(InfeasibleGeometryError, match="v' < v"):
        rect_spec((60.1, 40.1), (60.0, 40.2), 150.0)


def test_eq_2_2_and_2_3_outer_and_inner_edges():
    # pegs 1 mm further apart than the holes with 0.4 mm clearance: outer edges collide
    with pytest.raises(InfeasibleGeometryError, match="eq 2.2"):
        check_dual_extractable(6.1, 6.1, 5.7, 5.7, 40.0, 41.0)
    with pytest.raises(InfeasibleGeometryError, match="eq 2.3"):
        check_dual_extractable(6.1, 6.1, 5.7, 5.7, 40.0, 39.0)
    check_dual_extractable(6.1, 6.1, 5.7, 5.7, 40.0, 40.5)  # within 2 x 0.4 mm: extractable


@pytest.mark.parametrize("field", ["hole_w_mm", "peg_v_mm", "length_mm", "peg_mass_kg"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_zero_negative_or_nan_sizes_are_rejected(field, value):
    bad = dataclasses.replace(PRESETS["rect-1"], **{field: value})
    with pytest.raises(InfeasibleGeometryError, match=field if value == value else "finite"):
        validate(bad)


def test_dual_bad_sizes_and_polygon():
    with pytest.raises(InfeasibleGeometryError, match="peg_radius_1_mm"):
        validate(DualSpec((6.1, 6.1), (-5.7, 5.7), 40.0, 40.0, 50.0))
    with pytest.raises(InfeasibleGeometryError, match="overlap"):
        dual_spec(6.1, 6.0, 10.0, 50.0)
    with pytest.raises(InfeasibleGeometryError, match="n_sides"):
        validate(dataclasses.replace(PRESETS["dual-1"], n_sides=6))
    with pytest.raises(InfeasibleGeometryError, match="depth"):
        validate(dataclasses.replace(PRESETS["dual-1"], depth_mm=60.0))


def test_unknown_preset_message_lists_choices():
    with pytest.raises(KeyError, match="rect-1"):
        get_preset("rect-9")
