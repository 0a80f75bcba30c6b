"""Benchmarks: CSV format, roofline arithmetic, the NumPy impedance port, the MuJoCo
C control step, the PyBullet baseline env (skipped without pybullet), result readers."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import mujoco
import numpy as np
import pytest
from mujoco import rollout
from scipy import stats

from benchmarks import common
from benchmarks.baselines import pybullet_peghole, time_to_success
from benchmarks.evals import paired_reduction, rl_vs_rlcs
from benchmarks.evals.cross_engine import compare, paired_difference
from benchmarks.perf import (
    contact_caps,
    engines,
    plot,
    roofline,
    task_cost,
    throughput,
    warm_start,
)
from benchmarks.studies import capsule_fidelity
from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.reward import REWARD_WEIGHTS
from peghole_mjx.envs.rollout import scripted_policy
from peghole_mjx.geometry.mjcf import CONTACT_CAPS
from peghole_mjx.geometry.parts import DUAL_DEFAULT_REPRESENTATION, RECT_DEFAULT_REPRESENTATION

ROOT = Path(__file__).resolve().parents[1]

EXPECTED_COLUMNS = [
    "engine",
    "device",
    "scene",
    "worlds",
    "physics_steps_per_s",
    "env_steps_per_s",
    "compile_s",
    "peak_mem_mb",
    "versions",
    "date",
]


def _row(**kw):
    row = {
        "engine": "mujoco-c",
        "device": "cpu (2 cores, x86_64)",
        "scene": "rect",
        "worlds": 1,
        "physics_steps_per_s": 1000.0,
        "env_steps_per_s": 100.0,
        "compile_s": "",
        "peak_mem_mb": 300.0,
        "versions": common.versions_str(),
        "date": "2026-11-22T00:00:00Z",
    }
    row.update(kw)
    return row


# ----------------------------------------------------------------------------- CSV
def test_csv_writer_has_exactly_the_issue_columns(tmp_path):
    path = common.write_csv(tmp_path / "t.csv", [_row(), _row(engine="pybullet")])
    with path.open() as f:
        header = next(csv.reader(f))
    assert header == EXPECTED_COLUMNS
    rows = common.read_csv(path)
    assert [r["engine"] for r in rows] == ["mujoco-c", "pybullet"]
    assert rows[0]["compile_s"] is None and rows[0]["worlds"] == 1
    with pytest.raises(ValueError, match="misses"):
        common.write_csv(tmp_path / "bad.csv", [{"engine": "x"}])
    with pytest.raises(ValueError):
        common.write_csv(tmp_path / "bad.csv", [_row(extra=1)])
    assert "," not in common.versions_str()  # one CSV field


def test_rows_writer_keeps_the_columns_and_refuses_a_stray_key(tmp_path):
    """``write_rows``: the first row's keys (or ``fields``) in order, one line per row; a row
    with another key is refused and the file already there is left as it was."""
    path = common.write_rows(tmp_path / "r.csv", iter([{"b": 1, "a": None}, {"b": 2, "a": 0.5}]))
    assert path.read_text() == "b,a\n1,\n2,0.5\n"
    common.write_rows(path, [{"a": 1}], fields=["a", "b"])
    assert path.read_text() == "a,b\n1,\n"
    with pytest.raises(ValueError, match="c"):
        common.write_rows(path, [{"a": 1}, {"a": 2, "c": 3}])
    assert path.read_text() == "a,b\n1,\n"


def test_max_rss_sees_this_process_allocating():
    """A fresh process (no earlier peak to hide under) that touches 200 MiB reports it."""
    code = (
        "import numpy as np; from benchmarks import common as b;"
        "before = b.max_rss_mb(); block = np.ones(200 * 2**20 // 8);"
        "print(before, b.max_rss_mb())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    before, after = float(out[0]), float(out[1])
    assert after >= before + 180, (before, after)


def test_committed_throughput_csvs_are_well_formed():
    csvs = sorted(common.PERF_RESULTS.glob("throughput_*.csv"))
    for path in csvs:
        with path.open() as f:
            assert next(csv.reader(f)) == EXPECTED_COLUMNS, path
        for r in common.read_csv(path):
            # rows of a retired engine stay as measured (common.RETIRED_ENGINES)
            engine_ok = r["engine"] in common.ENGINES or r["engine"] in common.RETIRED_ENGINES
            assert engine_ok and r["scene"] in ("rect", "dual")
            assert r["physics_steps_per_s"] == pytest.approx(
                10 * r["env_steps_per_s"], rel=1e-3, abs=1.0
            )


def test_quick_plan_covers_the_acceptance_engines():
    args = type(
        "A",
        (),
        {
            "quick": True,
            "engines": list(common.ENGINES),
            "scenes": ["rect", "dual"],
            "worlds": None,
            "chunk": None,
            "min_time": 1.0,
        },
    )()
    jobs = throughput.plan(args, gpu=None)
    engines = {j["engine"] for j in jobs}
    assert {"mjx-jax", "mujoco-1t", "mujoco-c-rollout"} <= engines
    assert not set(common.RETIRED_ENGINES) & engines
    assert "mjx-warp" not in engines  # no GPU: skipped with a message
    assert not any(j["engine"] == "pybullet" and j["scene"] == "dual" for j in jobs)
    assert not any(j["engine"] == "mjx-jax" and j["scene"] == "dual" for j in jobs)
    assert common.device_label(None) == common.cpu_label()
    assert common.device_label("NVIDIA H100 80GB HBM3") == "gpu-h100"
    assert common.device_label("NVIDIA H200") == "gpu-h200"


# ----------------------------------------------------------------------------- roofline
def test_roofline_arithmetic():
    est = roofline.roofline_estimate(10_000, 3.35e12, n_substeps=10)
    assert est["bytes_per_physics_step"] == 20_000
    assert est["max_physics_steps_per_s"] == pytest.approx(1.675e8)
    assert est["max_env_steps_per_s"] == pytest.approx(1.675e7)
    assert "2 x 10000 B" in est["arithmetic"]
    frac = roofline.roofline_fraction(1.675e7, 10_000, 3.35e12)
    assert frac == pytest.approx(0.1)
    assert roofline.GPU_BANDWIDTH["H200 (HBM3e)"] / roofline.GPU_BANDWIDTH[
        "H100 SXM (HBM3)"
    ] == pytest.approx(4.8 / 3.35)


def test_committed_roofline_matches_the_arithmetic():
    path = common.PERF_RESULTS / "roofline.json"
    if not path.exists():
        pytest.skip("no roofline.json committed")
    r = json.loads(path.read_text())
    for e in r["scenes"].values():
        for gpu, est in e["roofline"].items():
            bw = roofline.GPU_BANDWIDTH[gpu]
            assert est["max_physics_steps_per_s"] == pytest.approx(
                bw / (2 * e["mjx_data_bytes_per_world"])
            )


def test_tree_bytes_counts_leaves():
    tree = {"a": np.zeros((3, 4), np.float32), "b": [np.zeros(5, np.int32)]}
    assert roofline.tree_bytes(tree) == 3 * 4 * 4 + 5 * 4


# ----------------------------------------------------------------------------- MuJoCo C rows
def test_rollout_row_replays_the_envs_own_closed_loop_torques():
    """The mujoco-c-rollout row's torques are recorded on the env's mujoco engine
    (``MujocoEngine.ctrl_log``): replayed open loop by ``mujoco.rollout`` from the recorded
    starts (state, warm start, per-world hole pose and friction in the model copies), they
    give the env's own states after the same steps, bit for bit."""
    rec = engines.record_starts("rect", 2, 30)
    env = rec["env"]
    assert rec["control"].shape == (2, 30, env.mj_model.nu)
    assert env.engine.ctrl_log is None  # the record is switched off again
    fric = [float(m.pair_friction[0, 0]) for m in rec["models"]]
    assert fric[0] != fric[1]  # each start's own friction draw
    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(jax.vmap(env.step, in_axes=(0, None)))
    s = reset(jax.random.split(jax.random.PRNGKey(1), 2))
    for _ in range(3):
        s = step(s, scripted_policy(env)(None, None))
    states, _ = rollout.rollout(
        rec["models"],
        mujoco.MjData(rec["models"][0]),
        rec["state"],
        rec["control"],
        initial_warmstart=rec["warmstart"],
    )
    nq, nv = env.mj_model.nq, env.mj_model.nv
    for w in range(2):
        closed = np.asarray(s.data.state[w]).view(np.float64)
        np.testing.assert_array_equal(states[w, -1, : 1 + nq + nv], closed[: 1 + nq + nv])


def test_contact_count_replay_is_the_envs_step():
    """``contact_caps.count_c`` counts after every physics step by replaying each env step of
    the mujoco engine (it raises if the replay leaves the env's trajectory) and finds the
    peg in contact."""
    env = envs.load(
        "RectExtract", config_overrides={"engine": "mujoco", "contact_cap": 0, "mujoco_threads": 1}
    )
    out = contact_caps.count_c(env, "random", 2, 3)
    assert out["max_active"] > 0 and out["env_steps_per_world"] == 3
    assert env.engine.ctrl_log is None
    with pytest.raises(ValueError, match="mujoco engine"):
        contact_caps.count_c(
            envs.load("RectExtract", config_overrides={"engine": "mjx"}), "scripted", 1, 1
        )


def test_the_retired_engine_is_refused_in_one_line(capsys, tmp_path):
    with pytest.raises(SystemExit):
        throughput.main(["--engines", "mujoco-c", "--out", str(tmp_path / "x.csv")])
    assert "mujoco-c was retired on 2026-12-02" in capsys.readouterr().err


# ----------------------------------------------------------------------------- PyBullet
@pytest.fixture(scope="module")
def pb_env():
    pytest.importorskip("pybullet")
    pytest.importorskip("gymnasium")
    env = pybullet_peghole.make_gym_env(seed=0)
    yield env
    env.close()


def test_pybullet_env_spaces_and_start(pb_env):
    assert pb_env.observation_space.shape == (9,)
    assert pb_env.action_space.shape == (6,)
    assert np.all(pb_env.action_space.low == -1) and np.all(pb_env.action_space.high == 1)
    obs, _ = pb_env.reset(seed=1)
    assert obs.shape == (9,) and obs.dtype == np.float32
    # the peg starts in the hole: flange on the hole axis, inserted, sensor zeroed, upright
    assert np.all(np.abs(obs[:2]) < 0.01) and abs(obs[2]) < 1e-3
    np.testing.assert_allclose(obs[3:6], 0.0, atol=1e-6)
    assert np.all(np.abs(obs[6:]) < 0.05)
    assert pb_env.sim.info["depth_mm"] == pytest.approx(149.5, abs=0.01)


def test_pybullet_reward_wiring(pb_env):
    """Reward = the project's reward_terms with Table 4.1 weights; progress = -w_d dz."""
    sim = pb_env.sim
    assert sim.rc.w_d == REWARD_WEIGHTS["w_d"] and sim.rc.w_stf == REWARD_WEIGHTS["w_stf"]
    pb_env.reset(seed=2)
    a = np.zeros(6, np.float32)
    a[2] = 0.2  # 20 mm/s out
    depth = sim.info["depth_mm"]
    for _ in range(10):
        obs, r, term, trunc, info = pb_env.step(a)
        assert not (term or trunc)
        dz = info["depth_mm"] - depth
        depth = info["depth_mm"]
        assert info["reward/progress"] == pytest.approx(-REWARD_WEIGHTS["w_d"] * dz)
        assert info["reward/force"] == pytest.approx(-REWARD_WEIGHTS["w_f"] * info["fxy_N"] / 20)
        assert info["reward/stiffness"] == pytest.approx(
            -REWARD_WEIGHTS["w_stf"] * np.sqrt(2) * 300.0 / 1000.0
        )
        assert info["reward/end"] == 0.0
        assert r == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward/")))
    assert obs[5] > 0  # pulling against friction: +F_z, the MJX env's sign
    for _ in range(90):  # past the start transient (the z spring builds up the pull force)
        pb_env.step(a)
    d100 = sim.info["depth_mm"]
    for _ in range(50):
        pb_env.step(a)
    assert d100 - sim.info["depth_mm"] == pytest.approx(50 * 0.4, abs=2.0)  # 20 mm/s


def test_pybullet_pushing_the_peg_reads_as_minus_the_contact_force(pb_env):
    """The F/T sign convention of the MJX env: the reading is minus the load on the peg."""
    sim = pb_env.sim
    pb_env.reset(seed=3)
    p, kw = sim.p, {"physicsClientId": sim.cid}
    f = np.zeros(3)
    for _ in range(150):  # 0.3 s: the impedance settles against a steady 6 N lift
        tau = sim._torque(sim.info["cmd_tip"], sim.info["cmd_mat"], np.zeros(3), np.zeros(3))
        p.setJointMotorControlArray(
            sim.robot, list(range(7)), p.TORQUE_CONTROL, forces=tau.tolist(), **kw
        )
        p.applyExternalForce(sim.robot, 8, [0.0, 0.0, 6.0], sim.tip().tolist(), p.WORLD_FRAME, **kw)
        p.stepSimulation(**kw)
        f = sim.contact_force()
    assert f[2] == pytest.approx(-6.0, abs=1.0)


# ----------------------------------------------------------------------------- readers
def test_time_to_success_reader(tmp_path):
    assert time_to_success.read_time_to_success(tmp_path / "missing.json") is None
    p = tmp_path / "r.json"
    p.write_text(
        json.dumps({"time_to_success_s": None, "budget_s": 600, "final_success_rate": 0.1})
    )
    r = time_to_success.read_time_to_success(p)
    assert r["reached"] is False and r["time_s"] == 600
    p.write_text(json.dumps({"time_to_95_s": 42.0, "budget_s": 600}))
    r = time_to_success.read_time_to_success(p)
    assert r["reached"] is True and r["time_s"] == 42.0


def test_throughput_table_traces_to_the_csv(tmp_path):
    common.write_csv(
        tmp_path / "throughput_cpu-9core.csv",
        [
            _row(engine="mjx-jax", physics_steps_per_s=5000.0, env_steps_per_s=500.0),
            _row(engine="mujoco-c-rollout", physics_steps_per_s=2500.0, env_steps_per_s=250.0),
            _row(engine="pybullet", physics_steps_per_s=1000.0, env_steps_per_s=100.0),
            _row(engine="mujoco-c", physics_steps_per_s=900.0, env_steps_per_s=90.0),
        ],
    )
    table = throughput.throughput_table(tmp_path)
    assert "| mjx-jax | rect | 1 | 5000.0 | 500.0 |" in table
    # a retired engine's committed rows are rendered as measured, labelled, not rerunnable
    assert "| mujoco-c (retired 2026-12-02) | rect | 1 | 900.0 | 90.0 |" in table
    assert "retired code: no longer runs" in table
    assert "--engines pybullet --scenes rect --worlds 1" in table
    assert "mjx-jax / mujoco-c-rollout = 2" in table
    assert "mjx-jax / one PyBullet process = 5" in table
    (tmp_path / "throughput_cpu-9core_quick.csv").write_text("not read")
    assert throughput.throughput_csvs(tmp_path) == [tmp_path / "throughput_cpu-9core.csv"]


def test_plots_write_pngs(tmp_path):
    pytest.importorskip("matplotlib")
    csv_path = common.write_csv(
        tmp_path / "throughput_cpu-9core.csv",
        [_row(worlds=w, physics_steps_per_s=100.0 * w) for w in (1, 4, 16)],
    )
    outs = plot.plot_throughput(csv_path, tmp_path)
    assert [o.name for o in outs] == ["throughput_cpu-9core_rect.png"]
    out = time_to_success.plot_time_to_success(tmp_path, results=tmp_path)
    assert out.exists() and outs[0].stat().st_size > 1000


def _fake_run(path, cs: bool, train_fz: list[float]):
    """A run directory with the files rl_vs_rlcs.py reads (run.json, metrics.csv)."""
    path.mkdir()
    cfg = {"env": "RectExtract", "profile": "cpu", "seed": 0}
    cfg["env_overrides"] = {"compliance_strategy": cs}
    (path / "run.json").write_text(json.dumps({"config": cfg}))
    keys = ["success_rate", "mean_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N"]
    keys.append("mean_discounted_return")
    head = ["step", *[f"eval/{k}" for k in keys], "train/mean_fz_N"]
    rows = [",".join(head), ",".join(["0"] + ["1"] * len(keys) + [""])]
    for i, fz in enumerate(train_fz, start=1):
        rows.append(",".join([str(20000 * i)] + ["1"] * len(keys) + [str(fz)]))
    (path / "metrics.csv").write_text("\n".join(rows) + "\n")


def test_rl_vs_rlcs_verdict_and_bad_input(tmp_path):
    _fake_run(tmp_path / "cs", True, [4.0, 4.2, 3.8])
    _fake_run(tmp_path / "rl", False, [6.0, 9.0, 3.0])
    out = tmp_path / "out"
    out.mkdir()
    args = ["--cs", str(tmp_path / "cs"), "--no-cs", str(tmp_path / "rl"), "--results", str(out)]
    assert rl_vs_rlcs.main(args) == 0
    (res,) = [json.loads(p.read_text()) for p in out.glob("*.json")]
    assert res["rl_cs"]["train_mean_fz_N"] == pytest.approx(4.0)
    assert res["rl"]["train_mean_fz_N"] == pytest.approx(6.0)
    assert res["c4_1"]["lower"] and res["c4_1"]["steadier"]
    assert res["force_reduction_train_pct"] == pytest.approx(100 / 3)
    # the runs swapped: refused with the reason
    swapped = ["--cs", str(tmp_path / "rl"), "--no-cs", str(tmp_path / "cs"), "--results", str(out)]
    with pytest.raises(SystemExit, match="CS on"):
        rl_vs_rlcs.main(swapped)


def _fake_seeds_run(path, cs: bool, fz: dict[int, list[float]], fxy: dict[int, list[float]]):
    """A ``--seeds`` run directory (seeds.json, history.csv) as rl_vs_rlcs.py reads it."""
    path.mkdir()
    evals = [  # RL + CS extracts every episode; RL 0.5, 0.6, 0.7 (seeds 0, 1, 2)
        {"seed": s, "success_rate": 1.0 if cs else 0.5 + 0.1 * s, "mean_fz_N": 1.0}
        | {"mean_fxy_N": 1.0, "episodes": 8}
        for s in fz
    ]
    summary = {"env": "RectExtractHard", "compliance_strategy": cs, "profile": "cpu"}
    summary.update(seeds=list(fz), env_steps=300, eval_episodes_per_seed=8, final_eval=evals)
    (path / "seeds.json").write_text(json.dumps(summary))
    cfg = {"env": "RectExtractHard", "env_overrides": {"compliance_strategy": cs}}
    (path / "run.json").write_text(json.dumps({"config": cfg, "seeds": len(fz)}))
    rows = ["seed,step,train/mean_fz_N,train/mean_fxy_N"]
    for s in fz:
        for i, (a, b) in enumerate(zip(fz[s], fxy[s], strict=True)):
            rows.append(f"{s},{100 * (i + 1)},{a},{b}")
    (path / "history.csv").write_text("\n".join(rows) + "\n")


def test_rl_vs_rlcs_over_seeds_gives_verdicts_from_intervals(tmp_path):
    """Three seeds per arm: RL + CS clearly lower and steadier (C4.1 confirmed); |F_xy| falls
    in every RL + CS seed (C4.2 confirmed there) but not consistently in RL."""
    cs_fz = {0: [4.0, 4.1, 3.9], 1: [4.2, 4.0, 4.1], 2: [3.9, 4.0, 4.0]}
    rl_fz = {0: [6.0, 9.0, 3.0], 1: [7.0, 10.0, 2.0], 2: [5.0, 9.5, 3.5]}
    cs_fxy = {0: [3.0, 2.0, 1.0], 1: [3.1, 2.0, 1.2], 2: [2.9, 2.1, 1.1]}
    rl_fxy = {0: [1.0, 2.0, 3.0], 1: [3.0, 2.0, 1.0], 2: [2.0, 2.0, 2.0]}
    _fake_seeds_run(tmp_path / "cs", True, cs_fz, cs_fxy)
    _fake_seeds_run(tmp_path / "rl", False, rl_fz, rl_fxy)
    out = tmp_path / "out"
    args = ["--cs", str(tmp_path / "cs"), "--no-cs", str(tmp_path / "rl"), "--results", str(out)]
    assert rl_vs_rlcs.main([*args, "--tag", "t"]) == 0
    (res,) = [json.loads(p.read_text()) for p in out.glob("rl_vs_rlcs_rect_hard_t_*.json")]
    assert res["c4_1"]["verdict"] == "confirmed"
    assert res["c4_2"]["verdict"] == {"rl_cs": "confirmed", "rl": "not confirmed"}
    over = res["rl_cs"]["over_seeds"]["train_mean_fz_N"]
    assert over["mean"] == pytest.approx(np.mean([np.mean(v) for v in cs_fz.values()]))
    assert list(out.glob("*.png"))
    # the final policies' difference: RL minus RL + CS success, Welch over the seeds
    fin = res["final_eval_rl_minus_cs_ci95"]
    assert fin["success_rate"] == pytest.approx(
        rl_vs_rlcs.welch_interval([0.5, 0.6, 0.7], [1.0, 1.0, 1.0])
    )
    assert fin["success_rate"][1] < 0 and fin["mean_time_s"] is None  # no times recorded
    assert sorted(p.name.endswith("_final.png") for p in out.glob("*.png")) == [False, True]
    # Welch's interval against scipy's own (equal_var=False) t statistic
    a, b = [1.0, 2.0, 3.0, 4.0], [2.0, 2.5, 5.0]
    lo, hi = rl_vs_rlcs.welch_interval(a, b)
    t = stats.ttest_ind(a, b, equal_var=False)
    ci = t.confidence_interval(0.95)
    assert (lo, hi) == pytest.approx((ci.low, ci.high))


def test_committed_dual_paired_analysis_is_reproduced_from_its_episodes():
    """The per-episode CSV of the dual policy published until 2026-12-06 (its evaluation's
    episodes) reproduces its committed paired analysis (all episodes and jointly successful
    ones); the analysis is not shown beside the policy published since (another policy)."""
    res = common.EVALS_RESULTS / "dual_cpu-2core"
    got = paired_reduction.analyse(res / "episodes256.csv", chosen_on=0)
    committed = json.loads((res / "paired256.json").read_text())
    for k in ("episodes", "policy_mean_fz_N", "baseline_mean_fz_N", "reduction_pct"):
        assert got[k] == pytest.approx(committed[k], rel=1e-6)
    ev = json.loads((ROOT / "peghole_mjx/policies/dual_extract/evaluation.json").read_text())
    assert paired_reduction.paired_files("dual", ev) == []  # another policy's episodes
    for k in ("reduction_pct_not_chosen_on", "share_of_episodes_policy_lower"):
        assert got[k] == pytest.approx(committed[k])
    assert got["bootstrap"] == committed["bootstrap"]  # fixed resampling seed
    lo, hi = got["bootstrap"]["reduction_pct_95"]
    assert lo < got["reduction_pct"] < hi
    # the jointly successful episodes are those both sides extract, counted from the CSV
    with (res / "episodes256.csv").open() as f:
        rows = list(csv.DictReader(f))
    both = sum(float(r["policy_success"]) > 0 and float(r["baseline_success"]) > 0 for r in rows)
    successes = sum(float(r["policy_success"]) > 0 for r in rows)
    assert got["both_succeed"]["episodes"] == both <= successes
    assert got["both_succeed"] == committed["both_succeed"]


def test_paired_reduction_over_jointly_successful_episodes(tmp_path):
    """``both_succeed`` keeps only the episodes where policy and baseline both succeed."""
    cols = ["success", "extraction_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N"]
    head = ["episode", *(f"policy_{c}" for c in cols), *(f"baseline_{c}" for c in cols)]
    rows = [  # (policy success, policy F_z, baseline success, baseline F_z)
        (1, 1.0, 1, 2.0),
        (1, 3.0, 1, 4.0),
        (1, 1.0, 0, 50.0),  # baseline wedged: left out of both_succeed
        (0, 9.0, 1, 2.0),  # policy failed: left out
    ]
    lines = [",".join(head)]
    for i, (ps, pf, bs, bf) in enumerate(rows):
        lines.append(",".join(map(str, [i, ps, 1, pf, pf, 0, bs, 1, bf, bf, 0])))
    f = tmp_path / "episodes.csv"
    f.write_text("\n".join(lines) + "\n")
    got = paired_reduction.analyse(f)
    assert got["reduction_pct"] == pytest.approx(100 * (1 - 14 / 58))
    both = got["both_succeed"]
    assert both["episodes"] == 2
    assert both["reduction_pct"] == pytest.approx(100 * (1 - 4 / 6))
    lo, hi = both["bootstrap"]["reduction_pct_95"]
    assert lo <= both["reduction_pct"] <= hi


def test_committed_withdrawn_dual_analysis_is_reproduced_from_its_episodes():
    """The 0.5 N-bound evaluation (a bound set after training, withdrawn 2026-11-29) kept as
    history: its analysis follows from its episode file."""
    res = common.EVALS_RESULTS / "dual_ffdeploy_cpu-2core"
    got = paired_reduction.analyse(res / "episodes1024.csv", chosen_on=64)
    committed = json.loads((res / "paired1024.json").read_text())
    for k in ("reduction_pct", "reduction_pct_not_chosen_on", "policy_mean_fz_N"):
        assert got[k] == pytest.approx(committed[k])
    assert got["bootstrap"] == committed["bootstrap"]


def test_gpu_suite_runs_its_tiny_configuration_on_the_cpu(tmp_path):
    """benchmarks/perf/gpu_suite.sh --tiny: the one-command GPU script, CPU smoke run (the
    one-thread rows of the env's mujoco engine run; mjx-warp skips cleanly without a GPU /
    warp; no training)."""
    env = {**os.environ, "OUT": str(tmp_path), "PYTHONPATH": str(ROOT), "PYTHON": sys.executable}
    res = subprocess.run(
        ["bash", str(ROOT / "benchmarks" / "perf" / "gpu_suite.sh"), "--tiny"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    log = (tmp_path / "gpu_suite.log").read_text()
    assert "[skip] mjx-warp" in log and "done in" in log
    rows = common.read_csv(tmp_path / "throughput_tiny.csv")
    assert sorted((r["engine"], r["scene"]) for r in rows) == [
        ("mujoco-1t", "dual"),
        ("mujoco-1t", "rect"),
    ]
    assert all(float(r["physics_steps_per_s"]) > 0 for r in rows)


def test_scene_variants_name_a_representation():
    assert common.SCENES["dual-mesh"] == "DualExtract"
    assert common.SCENE_OVERRIDES["dual-mesh"] == {"representation": "mesh"}
    assert throughput.skip_reason("mjx-jax", "dual-cylinder", None) is not None
    assert throughput.skip_reason("mjx-jax", "dual-mesh", None) is None


def test_jammed_dual_contact_forces_match_the_oracle(monkeypatch):
    """Two-point jam of the dual peg (benchmarks/capsule_fidelity.py jam, one depth, a faster
    pull): the capsule and mesh scenes' mouth and tip contact forces and extraction forces are
    within 10 % of the quasi-static oracle's (MuJoCo C, a few seconds). The mesh's F_z holds
    only with MuJoCo C's multi-point CCD off (on: +37 to +105 %)."""
    monkeypatch.setattr(capsule_fidelity, "JAM_DEPTHS_MM", (25.0,))
    out = capsule_fidelity.jam(speed_mm_s=10.0, h0_mm=30.0)
    rel = out["relative_difference"]["25"]
    assert set(out["oracle"]["25"]["contacts_N"]) == {"H2R-corner/P2", "P2L-tip/H2"}
    for rep in ("capsule", "mesh"):
        for name, v in rel[rep].items():
            assert abs(v) < 0.10, (rep, name, v)
    assert out["harness"]["friction_timeconst_s"] is None and not out["harness"]["multiccd"]


def _parts(folder, fz):
    """A ``--parts`` slice folder holding one slice with these per-episode mean F_z."""
    folder.mkdir(parents=True)
    fz = np.asarray(fz, np.float32)
    rec = {c: np.ones_like(fz) for c in paired_reduction.COLUMNS}
    rec["mean_fz_N"] = fz
    np.savez(folder / f"episodes_{0:07d}_{len(fz):07d}.npz", **rec)
    return folder


def test_export_pairs_a_policy_only_evaluation_with_an_earlier_baseline(tmp_path):
    """``--baseline-csv`` takes the baseline columns of an earlier export (its first n rows);
    a rerun baseline prefix must reproduce them, and a different one stops the export."""
    base_fz = [40.123457, 35.5, 37.25, 30.0]
    earlier = tmp_path / "earlier.csv"
    paired_reduction.export(
        _parts(tmp_path / "p0", [1, 2, 3, 4]), _parts(tmp_path / "b", base_fz), earlier
    )
    out = tmp_path / "new.csv"
    policy = _parts(tmp_path / "p1", [9.0, 8.0, 7.0])  # 3 episodes: the file's first 3 rows
    paired_reduction.export(policy, None, out, baseline_csv=earlier)
    direct = tmp_path / "direct.csv"
    paired_reduction.export(policy, _parts(tmp_path / "b3", base_fz[:3]), direct)
    assert out.read_text() == direct.read_text()
    # the first slice rerun agrees: accepted; a different baseline: refused, naming the episode
    paired_reduction.export(policy, _parts(tmp_path / "r1", base_fz[:2]), out, earlier)
    with pytest.raises(SystemExit, match="episode 1 mean_fz_N"):
        paired_reduction.export(policy, _parts(tmp_path / "r2", [40.123457, 35.6]), out, earlier)
    with pytest.raises(SystemExit, match="holds 4"):
        paired_reduction.export(_parts(tmp_path / "p5", [1] * 5), None, out, earlier)
    with pytest.raises(SystemExit, match="BASELINE_PARTS, --baseline-csv"):
        paired_reduction.export(policy, None, out)


def test_contact_caps_are_those_of_the_committed_measurement():
    """``CONTACT_CAPS`` holds the measured maxima of benchmarks/results/perf/contact_caps.json
    (one source of truth), every scene in it was measured in its default env and, where it
    has one, its hard variant, and every cap is above its measured maximum (or 0: none)."""
    committed = json.loads((common.PERF_RESULTS / "contact_caps.json").read_text())
    summary = committed["summary"]
    assert {tuple(k.split("/")) for k in summary} == set(CONTACT_CAPS)
    default_scene_envs = {
        ("rect", RECT_DEFAULT_REPRESENTATION): {"RectExtract", "RectExtractHard"},
        ("dual", DUAL_DEFAULT_REPRESENTATION): {"DualExtract", "DualExtractHard"},
    }
    for (scene, rep), entry in CONTACT_CAPS.items():
        got = summary[f"{scene}/{rep}"]
        assert got["measured_max"] == entry.measured_max and got["cap"] == entry.cap
        rows = [r for r in committed["rows"] if (r["scene"], r["representation"]) == (scene, rep)]
        assert max(r["max_active"] for r in rows) == entry.measured_max
        assert entry.cap == 0 or entry.cap > entry.measured_max
        if (scene, rep) in default_scene_envs:  # the default scene: its hard variant too
            assert set(got["envs"]) == default_scene_envs[(scene, rep)]


def test_cross_engine_comparison_is_paired_and_flags_disagreement():
    a = {
        "success": np.ones(40),
        "mean_fz_N": np.linspace(1, 2, 40),
        "peak_fz_N": np.linspace(2, 4, 40),
        "jammed": np.zeros(40),
        "overflow": np.zeros(40),
        "nan": np.zeros(40),
        "mean_fxy_N": np.zeros(40),
        "extraction_time_s": np.full(40, 7.0),
    }
    b = {**a, "mean_fz_N": a["mean_fz_N"] + 0.5}
    d = paired_difference(a["mean_fz_N"], b["mean_fz_N"])
    assert d["mean"] == pytest.approx(0.5) and d["ci95"][0] == pytest.approx(0.5)
    c = compare({"mjx": a, "mujoco": b})
    assert c["success_intervals_overlap"] and c["outcome_differs_share"] == 0.0
    worse = {**a, "success": np.r_[np.ones(10), np.zeros(30)]}
    c = compare({"mjx": a, "mujoco": worse})
    assert not c["success_intervals_overlap"] and c["outcome_differs_share"] == 0.75


def test_time_to_success_result_names_its_engine():
    result_path = time_to_success.result_path
    assert result_path("RectExtract", "cpu-2core").name == "train_rect_cpu-2core.json"
    got = result_path("RectExtractHard", "cpu-2core", "mujoco").name
    assert got == "train_RectExtractHard_mujoco_cpu-2core.json"


def test_warm_start_times_the_first_batch_marker_and_the_longest_silence():
    """The start-time benchmark's clock on a scripted child: output, 0.6 s of silence, then
    the first-batch marker; bad sizes are a usage error."""
    code = (
        "import sys, time; sys.stderr.write('compiling'); sys.stderr.flush(); time.sleep(0.6);"
        "sys.stderr.write('policy rollout: 1/2'); sys.stderr.flush(); time.sleep(0.1)"
    )
    row = warm_start.time_run([sys.executable, "-c", code], dict(os.environ))
    assert row["returncode"] == 0
    assert 0.6 <= row["first_batch_s"] < row["wall_s"]
    assert 0.55 <= row["longest_silence_s"] < row["wall_s"]
    silent = warm_start.time_run([sys.executable, "-c", "import time; time.sleep(0.3)"], {})
    assert silent["first_batch_s"] is None and silent["longest_silence_s"] >= 0.3
    with pytest.raises(SystemExit) as exc:
        warm_start.main(["--runs", "0"])
    assert exc.value.code == 2


def test_task_cost_refuses_a_folder_without_a_manifest_before_any_work(tmp_path):
    """A folder that is not a complete task (no manifest.json: one still being built) is one
    UserInputError line naming it, before any task is measured or the result written; the
    preset scenes shown beside the tasks are the committed cost file's default ones."""
    (tmp_path / "half").mkdir()
    out = tmp_path / "task_cost.json"
    with pytest.raises(UserInputError, match="half: no manifest.json") as exc:
        task_cost.main(["--tasks", str(tmp_path / "half"), "--out", str(out)])
    assert "\n" not in str(exc.value) and not out.exists()
    ref = task_cost.reference_rows(common.PERF_RESULTS / "cost_cpu-2core.json")
    assert [(r["env"], r["representation"]) for r in ref] == [
        ("RectExtract", RECT_DEFAULT_REPRESENTATION),
        ("DualExtract", DUAL_DEFAULT_REPRESENTATION),
    ]
    assert all(r["xla"]["env_step"]["bytes_per_world"] > 0 for r in ref)


def test_committed_task_cost_csv_is_its_json():
    """The task cost CSV holds exactly the committed JSON's rows (one per task, MB and MFLOP
    per world, device and date), as ``task_cost.main`` writes it after every run."""
    path = common.PERF_RESULTS / "task_cost_cpu-2core.json"
    doc = json.loads(path.read_text())
    rows = list(csv.DictReader(path.with_suffix(".csv").open()))
    assert [r["task"] for r in rows] == [r["task"] for r in doc["rows"]]
    for row, r in zip(rows, doc["rows"], strict=True):
        mb = r["xla"]["env_step"]["bytes_per_world"] / 1e6
        assert float(row["env_step_MB_per_world"]) == pytest.approx(mb, abs=1e-3)
        assert row["device"] == doc["device"] and row["date"] == doc["date"]


def test_committed_contact_caps_csv_is_its_json():
    """The contact-cap CSV holds the committed JSON's rows in order, with its device and date."""
    path = common.PERF_RESULTS / "contact_caps.json"
    doc = json.loads(path.read_text())
    rows = list(csv.DictReader(path.with_suffix(".csv").open()))
    assert [(r["scene"], r["policy"], int(r["max_active"])) for r in rows] == [
        (r["scene"], r["policy"], r["max_active"]) for r in doc["rows"]
    ]
    assert all(r["device"] == doc["device"] and r["date"] == doc["date"] for r in rows)


def test_a_benchmark_set_reads_its_value_as_the_cli_does():
    """One parser (core.validation.key_value) for ``peghole --set`` and every benchmark's:
    JSON first (``true``), then a Python literal (``False``, a tuple), else the text."""
    from benchmarks.common import parse_overrides
    from peghole_mjx.core.errors import UserInputError
    from peghole_mjx.core.validation import key_value

    items = [
        "env.action.residual=true",
        "a=False",
        "b=(0.8, 1.2)",
        "c=[1, 2]",
        "d=mujoco",
        "e=1e-4",
    ]
    parsed = parse_overrides(items)
    assert parsed == dict(key_value(i) for i in items)
    assert parsed == {
        "env.action.residual": True,
        "a": False,
        "b": (0.8, 1.2),
        "c": (1, 2),
        "d": "mujoco",
        "e": 1e-4,
    }
    with pytest.raises(UserInputError, match="expected KEY=VALUE"):
        parse_overrides(["no_equals_sign"])
