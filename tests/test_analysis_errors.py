"""Bad input gives clear errors; errata decisions are enforced."""

from __future__ import annotations

import numpy as np
import pytest

from peghole_mjx.analysis import common, dual, rect
from peghole_mjx.cli.main import main
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.specs import DualSpec, InfeasibleGeometryError, RectSpec


def test_negative_stiffness_rejected():
    with pytest.raises(UserInputError, match="K_x_N_per_mm must be > 0"):
        dual.two_point_region("dual-2", "5", 25.0, K_x_N_per_mm=-0.4)
    with pytest.raises(UserInputError, match="K_theta_Nmm_per_rad"):
        dual.two_point_region("dual-2", "5", 25.0, K_theta_Nmm_per_rad=np.array([3e5, 0.0]))
    with pytest.raises(UserInputError, match="K_psi"):
        rect.edge_contact("rect-1", 4, 10.0, K_psi_Nmm_per_rad=-1.0)


@pytest.mark.parametrize("lc", [-1.0, 50.01, float("nan")])
def test_compliance_centre_outside_peg_rejected(lc):
    with pytest.raises(UserInputError, match="L_C_mm"):
        dual.two_point_region("dual-2", "5", lc)


def test_E3_theta0_in_radians_rejected_with_hint():
    with pytest.raises(UserInputError, match="E3"):
        dual.two_point_region("dual-2", "5", 25.0, theta0_rad=-0.9)
    assert np.isclose(common.THETA0_RAD, np.deg2rad(-0.9))


def test_infeasible_geometry_rejected():
    bad = DualSpec((6.1, 6.1), (6.5, 6.5), 40.0, 40.0, 50.0)  # E1: printed r = 6.5 mm
    with pytest.raises(InfeasibleGeometryError, match="eq 2.1"):
        dual.two_point_region(bad, "5", 25.0)
    outer = DualSpec((6.1, 6.1), (6.0, 6.0), 40.0, 40.5, 50.0)  # violates eq 2.2
    with pytest.raises(InfeasibleGeometryError, match="eq 2.2"):
        dual.two_point_region(outer, "10", 25.0)
    big = RectSpec(60.1, 40.1, 60.5, 40.5, 150.0)  # E2: printed 60.5 x 40.5 mm
    with pytest.raises(InfeasibleGeometryError, match="w' < w"):
        rect.two_contact_region(big, 2, 75.0)


def test_unknown_category_and_case():
    with pytest.raises(UserInputError):
        dual.two_point_region("dual-2", "7", 25.0)
    with pytest.raises(UserInputError):
        rect.two_contact_region("rect-1", 4, 25.0)


def test_cli_reports_one_line_and_exit_2(capsys):
    assert main(["analyze", "figure", "9.9", "--out", "/tmp/unused"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("peghole: error: unknown figure")
    assert (
        main(["analyze", "jamming", "--geometry", "dual", "--depth", "20", "--wrench", "1,-2,3"])
        == 2
    )
    assert "F_z must be > 0" in capsys.readouterr().err
    assert (
        main(["analyze", "jamming", "--geometry", "rect", "--preset", "dual-1", "--depth", "20"])
        == 2
    )
