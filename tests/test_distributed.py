"""``--distributed``: two CPU processes on one machine (gloo collectives) train one learner.

Each process steps its own 4 of the 8 worlds; after the replay prefill and one training call
both must hold bit-identical learners (actor, critics, targets, temperature, optimiser states
and the observation normaliser, whose statistics count both processes' observations), while
their worlds differ. The env runs on the ``mujoco`` engine (the learner's collectives are the
same on either engine; an MJX train call compiles for minutes in each process).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np

_WORKER = """
import sys
from pathlib import Path
from peghole_mjx.training.distributed import initialize

pid, n = initialize()
assert n == 2, n
import jax
import numpy as np
from peghole_mjx.envs import load
from peghole_mjx.training.config import load_train_config
from peghole_mjx.training.sac import SACTrainer
from peghole_mjx.core.treenames import named_leaves

tiny = {"num_envs": 8, "steps_per_call": 10, "eval_every": 400, "num_eval_envs": 8,
        "batch_size": 128, "grad_updates_per_step": 8, "min_replay_size": 80,
        "max_replay_size": 20000, "env.episode_length": 25,
        "env.engine": "mujoco", "env.mujoco_threads": 1}
cfg = load_train_config("RectExtract", "quick", tiny, compliance_strategy=True)
tr = SACTrainer(load(cfg.env, config_overrides=cfg.env_overrides), cfg)
carry = tr.init_carry(cfg.seed)
carry, _ = tr.prefill(carry)
carry, _, _ = tr.train_call(carry)
out = Path(sys.argv[1])
ts = named_leaves(jax.tree.map(lambda x: x[0], carry.ts))
arrays = {"ts/" + k: v for k, v in ts.items()}
np.savez(out / f"{pid}.npz", obs=np.asarray(carry.env_state.obs), **arrays)
print("done", pid, flush=True)
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_cpu_processes_train_one_learner(tmp_path):
    root = str(Path(__file__).resolve().parents[1])
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]),
        "JAX_PLATFORMS": "cpu",
        "JAX_COORDINATOR_ADDRESS": f"127.0.0.1:{_free_port()}",
        "JAX_NUM_PROCESSES": "2",
    }
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _WORKER, str(tmp_path)],
            env={**env, "JAX_PROCESS_ID": str(i)},
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(2)
    ]
    outs = []
    try:
        for p in procs:
            outs.append(p.communicate(timeout=1800)[0])
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    report = "\n".join(
        f"--- process {i} (exit {p.returncode}):\n{t[-2500:]}"
        for i, (p, t) in enumerate(zip(procs, outs, strict=True))
    )
    assert all(
        p.returncode == 0 and f"done {i}" in t
        for i, (p, t) in enumerate(zip(procs, outs, strict=True))
    ), report
    a, b = np.load(tmp_path / "0.npz"), np.load(tmp_path / "1.npz")
    names = [k for k in a.files if k.startswith("ts/")]
    assert sorted(names) == sorted(k for k in b.files if k.startswith("ts/"))
    assert any("normalizer" in k for k in names) and any("q_params" in k for k in names)
    for k in names:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert int(a["ts/gradient_steps"]) > 0  # one training call happened
    # the normaliser counted both processes' worlds: 8 observations per env step, 20 steps
    if "ts/normalizer/count/lo" in a.files:  # Brax's 64-bit counter as two 32-bit halves
        count = int(a["ts/normalizer/count/hi"]) * 2**32 + int(a["ts/normalizer/count/lo"])
    else:
        count = float(a["ts/normalizer/count"])
    assert count == 8 * 20
    assert not np.array_equal(a["obs"], b["obs"])  # each process steps its own worlds


def test_distributed_without_a_coordinator_is_one_line(tmp_path):
    root = str(Path(__file__).resolve().parents[1])
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_COORDINATOR")}
    env.update(PYTHONPATH=root, JAX_PLATFORMS="cpu", JAX_NUM_PROCESSES="2", JAX_PROCESS_ID="0")
    cmd = [sys.executable, "-m", "peghole_mjx.cli.main", "train", "--distributed", "--env"]
    cmd += ["RectExtract", "--quick", "--out", str(tmp_path / "run")]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 2, res.stderr[-2000:]
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("peghole: error: --distributed:") and "JAX_COORDINATOR_ADDRESS" in last
    assert not (tmp_path / "run").exists()
