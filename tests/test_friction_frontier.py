"""The friction-model map: its worlds, pairing and admissibility rule (friction_frontier)."""

import mujoco
import numpy as np
import pytest

from benchmarks.studies import friction_frontier as ff
from benchmarks.studies import pull_speed as ps
from benchmarks.studies.c_replica import pull_c
from peghole_mjx.experiments import contact_check as cc


def test_the_worlds_are_the_tilted_experiments_first_paired_draws():
    """Every world commands the thesis's tilt; per K_theta and repeat, the tip and top worlds
    share their error draws (paired), and they are the first draws of pull_speed's 16."""
    ws = ff.worlds(3)
    assert len(ws) == len(ff.K_ROT) * len(ff.LCS) * 3
    assert all(w["theta0"] == pytest.approx(np.deg2rad(-0.9)) for _, _, _, w, _ in ws)
    by = {(k, at, r): w for k, at, r, w, _ in ws}
    for k in ff.K_ROT:
        top = ps.worlds_at(ps.cell(k, 0.0, "dual_tilt"), ps.REPEATS, "top")
        for r in range(3):
            assert by[k, "tip", r]["delta0"] == by[k, "top", r]["delta0"]
            assert by[k, "top", r]["delta0"] == pytest.approx(float(top["delta0"][r]))
            assert by[k, "top", r]["L_C"] > by[k, "tip", r]["L_C"]


def _rows(variant: str, repeats: int, tip: float, top: float, **over) -> list[dict]:
    rows = []
    for k in ff.K_ROT:
        for v in ff.SPEEDS_MM_S:
            for at, p in (("tip", tip), ("top", top)):
                for r in range(repeats):
                    rows.append(
                        {
                            "variant": variant,
                            "k_rot_Nm_rad": k,
                            "speed_mm_s": v,
                            "at": at,
                            "repeat": r,
                            "peak_fz_late_N": p * (1 + 0.01 * r),
                            "oracle_peak_fz_late_N": p,
                            "mu_eff": over.get("mu_eff", {}).get(v, 0.26),
                            "both_walls_frac_in_two_point": over.get("both", {}).get(v, 0.99),
                            "penetration_um": 5.0,
                            "wall_s": 1.0,
                        }
                    )
    return rows


def test_the_summary_pairs_tip_and_top_by_repeat():
    cells = ff.summary(_rows("Coulomb rows", 4, 1.0, 2.0), 4)
    assert len(cells) == len(ff.K_ROT) * len(ff.SPEEDS_MM_S)
    for c in cells:
        red = c["reduction_tip_vs_top_pct"]
        assert red["value"] == pytest.approx(50.0)
        assert red["oracle"] == pytest.approx(50.0)
        assert c["oracle_within_15pct_frac"] == 1.0
    # a world missing: the (variant, K_theta, speed) is left out, not summarised on fewer
    rows = _rows("Coulomb rows", 4, 1.0, 2.0)[1:]
    assert len(ff.summary(rows, 4)) == len(ff.K_ROT) * len(ff.SPEEDS_MM_S) - 1


def test_the_rule_names_each_violated_condition():
    """A variant meeting every bound is admissible; one whose slow pull loses friction, or whose
    fast pull bounces, is not, and the reason names the bound and the cell."""
    ok = ff.summary(_rows("relaxed 0.3 s", 2, 1.0, 2.0), 2)
    slow = ff.summary(_rows("relaxed 1 s (the experiment's)", 2, 1.0, 2.0,
                            mu_eff={0.5: 0.10}), 2)  # fmt: skip
    fast = ff.summary(_rows("Coulomb rows", 2, 1.0, 2.0, both={20.0: 0.3}), 2)
    adm = ff.admissible(ok + slow + fast, 0.266)
    assert adm["relaxed 0.3 s"] == {"admissible": True, "fails": []}
    assert not adm["relaxed 1 s (the experiment's)"]["admissible"]
    assert all(
        "mu_eff" in f and "0.5 mm/s" in f for f in adm["relaxed 1 s (the experiment's)"]["fails"]
    )
    assert not adm["Coulomb rows"]["admissible"]
    assert all("both walls" in f and "20 mm/s" in f for f in adm["Coulomb rows"]["fails"])
    assert "relaxed 0.1 s" not in adm  # no cells: not judged


def test_the_replica_refuses_an_unknown_option():
    with pytest.raises(ValueError, match="unknown mjOption field 'no_such_field'"):
        pull_c("rect-2", cc.STANDARD_MU, cc.STANDARD_CASE, 0.02, opt={"no_such_field": 1})


def test_every_variant_sets_real_options():
    """The variants' options exist on MuJoCo's mjOption (a typo would fail the map late)."""
    opt = mujoco.MjModel.from_xml_string("<mujoco/>").opt
    for tcf, extra, engines in ff.VARIANTS.values():
        assert tcf is None or tcf > 0
        assert all(hasattr(opt, k) for k in extra)
        assert engines.startswith("C")
