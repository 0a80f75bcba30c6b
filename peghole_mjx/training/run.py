"""A training run on disk: config, progress, metrics, checkpoints, resume, final outputs.

Layout of ``--out DIR``::

    run.json              env, hyperparameters, network, device, versions, start date
    metrics.csv           one row per evaluation (env steps, wall clock, eval and training stats)
    tb/                   TensorBoard event files (same scalars)
    run.lock              held by the process writing the run (training/lock.py)
    checkpoints/step_N/   policy.json + params.npz at every evaluation; the two newest also
                          hold state/ (orbax, by tree path) + state.json (the whole carry,
                          for --resume);
                          manifest.json: every file's size and SHA-256 (training/checkpoints.py)
    final_policy/         the policy at the end (what `peghole evaluate DIR` loads)
    curves.png            Figs 4.5-4.7 style learning curves
    rollout.gif           one episode of the final policy (mujoco.Renderer, headless)
    summary.json          final evaluation, wall clock, time to 95 % success

Resume (``--resume DIR``) restores the newest checkpoint whose state verifies (a corrupt
newer one is set aside with a warning): actor, critics, target critics, temperature, optimiser
states, normaliser, replay buffer, every world's state, the PRNG key, the env-step counter, the
wall clock so far and the evaluation schedule. Rows of ``metrics.csv`` written after that
checkpoint are dropped (their work is redone; none are kept when no checkpoint was written).
Nothing of the run is rewritten before the new configuration and the checkpoint have been
validated and loaded; every file is written atomically (``peghole_mjx.fileio``).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np

from peghole_mjx import fileio, memory
from peghole_mjx.envs.metrics import EVAL_STATS, TOTAL_KEYS, TRAIN_STATS, summarize_totals
from peghole_mjx.errors import CorruptFileError, UserInputError
from peghole_mjx.policies import make_policy_fn, save_policy
from peghole_mjx.provenance import provenance
from peghole_mjx.training import checkpoints
from peghole_mjx.training.config import TrainConfig, read_run_record
from peghole_mjx.training.lock import RunLock
from peghole_mjx.training.plots import read_metrics
from peghole_mjx.training.sac import SACTrainer
from peghole_mjx.validation import dumps

METRIC_COLUMNS = (
    "step",
    "wall_s",
    "train_wall_s",
    "sps",
    *(f"eval/{k}" for k in EVAL_STATS),
    *(f"train/{k}" for k in TRAIN_STATS),
    "loss/critic",
    "loss/actor",
    "loss/alpha",
    "alpha",
)
#: eval success that defines "time to success" (issue targets: 95 %)
SUCCESS_THRESHOLD = 0.95


class TrainingRun:
    """Drive a :class:`SACTrainer` with evaluation, logging and checkpoints."""

    def __init__(
        self,
        cfg: TrainConfig,
        out: str | Path,
        progress: bool = True,
        render: bool = True,
        stop_at_success: float | None = None,
        budget_train_s: float | None = None,
    ):
        from peghole_mjx.envs import load

        self.cfg, self.out, self.progress, self.render = cfg, Path(out), progress, render
        #: end the run at the first evaluation whose success rate reaches this (benchmarks)
        self.stop_at_success = stop_at_success
        #: end the run, after a last evaluation, once the training clock (evaluations
        #: excluded) reaches this many seconds (benchmarks with a wall-clock budget)
        self.budget_train_s = budget_train_s
        self.carry = None
        self.env = load(cfg.env, config_overrides=cfg.env_overrides or None)
        self.trainer = SACTrainer(self.env, cfg)
        # before anything is allocated, compiled or written
        need_disk = check_resources(self.env, cfg, self.trainer.obs_size, self.trainer.act_size)
        fileio.check_room(self.out, need_disk, "--out")
        self.policy_fn = make_policy_fn(self.trainer.network, deterministic=True)
        self.ckpt_dir = self.out / "checkpoints"
        #: the run's lock when the caller took it (else :meth:`run` takes it)
        self.lock: RunLock | None = None
        #: run.json as it will be once the resumed config and checkpoint are validated
        self._pending_meta: dict[str, Any] | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def resume(
        cls,
        out: str | Path,
        progress: bool = True,
        render: bool = True,
        num_timesteps: int | None = None,
    ) -> TrainingRun:
        """The run in ``out`` with its own config; ``num_timesteps`` extends or ends it.

        Nothing is written here: the changed ``run.json`` is written by :meth:`run` once the
        new configuration and the checkpoint have been validated.
        """
        from peghole_mjx.validation import check

        out = Path(out)
        meta, _ = read_run_record(out)  # schema-checked, its config validated
        if (out / "metrics.csv").exists():  # checked before the env is built
            read_metrics(out, torn_tail=True)
        config = dict(meta["config"])
        if num_timesteps is not None:
            n = check("num_timesteps", num_timesteps, "--set num_timesteps")
            config["num_timesteps"] = n
            meta = {**meta, "config": config}
            meta["resumed_with"] = [*meta.get("resumed_with", []), {"num_timesteps": n}]
        run = cls(TrainConfig.from_dict(config), out, progress, render)
        if num_timesteps is not None:
            run._pending_meta = meta
        return run

    def latest_checkpoint(self) -> Path | None:
        """Newest checkpoint folder holding a saved state (not checked; see
        :meth:`find_resume_point`)."""
        full = [p for p in checkpoints.checkpoint_dirs(self.ckpt_dir) if checkpoints.has_state(p)]
        return full[-1] if full else None

    def find_resume_point(self):
        """``(path, carry, sched)`` of the newest checkpoint whose state verifies and loads,
        or None; corrupt newer ones are set aside with a warning (``checkpoints.newest_valid``)."""
        found = checkpoints.newest_valid(self.ckpt_dir, self.load_checkpoint)
        if found is None:
            return None
        path, (carry, sched) = found
        return path, carry, sched

    # ------------------------------------------------------------------ state I/O
    def save_checkpoint(self, carry, step: int, sched: dict[str, Any]) -> Path:
        """Write ``checkpoints/step_N`` completely (``checkpoints.write``: fsynced, sealed,
        renamed); the two newest checkpoints keep their state."""
        params = self.trainer.policy_params(carry)
        host = jax.device_get(carry)

        def write_files(folder: Path) -> None:
            save_policy(folder, params, self._policy_meta(step), atomic=False)
            saved = checkpoints.save_state(folder, host)
            text = dumps({"step": step, **sched, **saved}, indent=2) + "\n"
            fileio.write_text(folder / "state.json", text)

        return checkpoints.write(self.ckpt_dir, step, write_files)

    def load_checkpoint(self, path: Path):
        """``(carry, sched)`` of checkpoint ``path``, restored by tree path into this run's
        carry (a carry of another structure is refused: ``checkpoints.restore_state``)."""
        template = self.trainer.init_carry(self.cfg.seed)
        sched = json.loads((path / "state.json").read_text())
        if not isinstance(sched, dict) or not isinstance(sched.get("step"), int):
            raise CorruptFileError(f"{path}/state.json holds no step")
        if not {"wall_s", "n_eval"} <= set(sched):
            raise CorruptFileError(f"{path}/state.json lacks the evaluation schedule")
        empty = sched.pop("empty_leaves", {})
        host = checkpoints.restore_state(path, template, empty)
        carry = jax.tree.map(
            lambda t, x: jax.device_put(x.astype(t.dtype), t.sharding), template, host
        )
        return carry, sched

    def _policy_meta(self, step: int) -> dict[str, Any]:
        return policy_meta(self.cfg, self.trainer.network, step)

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, carry, episodes: int, seed: int) -> dict[str, float]:
        from peghole_mjx.envs.rollout import rollout

        params = self.trainer.policy_params(carry)
        res = rollout(
            self.env,
            self.policy_fn,
            episodes,
            seed=seed,
            progress=False,
            params=params,
            gamma=self.cfg.discounting,
            refuse_all_nan=False,  # a training run records it (nan_worlds), goes on
        )
        return res.summary().as_dict()

    # ------------------------------------------------------------------ logging
    def _read_rows(self, upto_step: int | None = None) -> list[dict[str, str]]:
        if not (self.out / "metrics.csv").exists():
            return []
        # schema-checked; a row cut short by a kill during its write is dropped
        rows = read_metrics(self.out, torn_tail=True)
        if upto_step is not None:
            rows = [r for r in rows if int(r["step"]) <= upto_step]
        return rows

    def _write_rows(self, rows: list[dict[str, Any]]) -> None:
        """Replace metrics.csv atomically with ``rows``."""
        with fileio.atomic_open(self.out / "metrics.csv", "w") as f:
            w = csv.DictWriter(f, fieldnames=METRIC_COLUMNS)
            w.writeheader()
            for r in rows:
                w.writerow({k: r.get(k, "") for k in METRIC_COLUMNS})

    def _append_row(self, row: dict[str, Any], tb) -> None:
        path = self.out / "metrics.csv"
        new = not path.exists()
        with path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=METRIC_COLUMNS)
            if new:
                w.writeheader()
            w.writerow({k: _fmt(row.get(k, "")) for k in METRIC_COLUMNS})
            f.flush()
            os.fsync(f.fileno())
        if tb is not None:
            for k, v in row.items():
                if k != "step" and isinstance(v, int | float) and math.isfinite(v):
                    tb.add_scalar(k, v, row["step"])
            tb.flush()

    # ------------------------------------------------------------------ main loop
    def run(self, resume: bool = False) -> dict[str, Any]:
        """Train (``resume``: from the newest valid checkpoint) holding the run's lock."""
        lock = self.lock
        if lock is None or not lock.held:
            lock = RunLock(self.out).acquire()
        try:
            return self._run(resume)
        finally:
            if lock is not self.lock:
                lock.release()

    def prepare(self, resume: bool):
        """Check the run folder, find the checkpoint to resume from (None: from the start),
        and only then rewrite the run's records: run.json (with a validated change) and
        metrics.csv, truncated to the checkpoint's step (emptied when starting over)."""
        self.out.mkdir(parents=True, exist_ok=True)
        if not resume and (self.out / "run.json").exists():
            if not failed_start(self.out):
                raise UserInputError(
                    f"{self.out} already holds a training run: use --resume {self.out} or a "
                    "new --out"
                )
            clear_failed_start(self.out)
        # metrics.csv read once, schema-checked before any work (file and line)
        logged = self._read_rows() if resume else []
        found = self.find_resume_point() if resume else None
        rows = [r for r in logged if int(r["step"]) <= found[2]["step"]] if found else []
        if resume and found is None:
            starting_over(self.out, self.ckpt_dir)
        # validated: from here on the run's records are rewritten
        if self._pending_meta is not None:
            fileio.write_text(self.out / "run.json", dumps(self._pending_meta, indent=2) + "\n")
            self._pending_meta = None
        if not (self.out / "run.json").exists():
            meta = {"config": self.cfg.as_dict(), "network": self.trainer.network, **provenance()}
            fileio.write_text(self.out / "run.json", dumps(meta, indent=2) + "\n")
        if resume:  # rows after the checkpoint (all rows when starting over) are redone
            self._write_rows(rows)
        return found

    def _run(self, resume: bool) -> dict[str, Any]:
        cfg, trainer = self.cfg, self.trainer
        found = self.prepare(resume)
        tb = _tensorboard(self.out / "tb")
        t_start = time.perf_counter()
        if found is not None:
            ckpt, carry, sched = found
            step, wall0, n_eval = sched["step"], sched["wall_s"], sched["n_eval"]
            eval_s = sched.get("eval_s", 0.0)
            print(f"resumed from {ckpt} at {step} env steps", file=sys.stderr)
        else:
            carry = trainer.init_carry(cfg.seed)
            step, wall0, n_eval = 0, 0.0, 0
            eval_s = 0.0  # wall clock spent in evaluations (excluded from train_wall_s)

        def wall() -> float:
            return wall0 + time.perf_counter() - t_start

        def timed_eval(seed: int) -> dict[str, float]:
            nonlocal eval_s
            t0 = time.perf_counter()
            ev = self.evaluate(carry, cfg.num_eval_envs, seed=seed)
            eval_s += time.perf_counter() - t0
            return ev

        def clocks() -> dict[str, float]:
            return {"wall_s": wall(), "train_wall_s": wall() - eval_s}

        per_call = cfg.num_envs * cfg.steps_per_call
        totals = {k: 0.0 for k in TOTAL_KEYS}
        losses: dict[str, float] = {}
        if step == 0:  # the untrained policy, then the replay prefill
            ev = timed_eval(cfg.seed + 10_000)
            self._append_row({"step": 0, **clocks(), **_prefix("eval/", ev)}, tb)
            n_eval = 1
            while step < cfg.min_replay_size:
                carry, tot = trainer.prefill(carry)
                step += per_call
                _accumulate(totals, tot)
        from tqdm import tqdm

        bar = tqdm(
            total=cfg.num_timesteps,
            initial=min(step, cfg.num_timesteps),
            unit="step",
            unit_scale=True,
            desc=f"SAC {cfg.env}",
            file=sys.stderr,
            disable=not self.progress,
            dynamic_ncols=True,
        )
        last = self._read_rows()
        post = {}
        if last:
            post = {
                "success": last[-1]["eval/success_rate"],
                "return": last[-1]["eval/mean_return"],
            }
        t_sps, s_sps = time.perf_counter(), step
        while step < cfg.num_timesteps:
            carry, tot, m = trainer.train_call(carry)
            step += per_call
            _accumulate(totals, tot)
            losses = {k: float(np.mean(v)) for k, v in jax.device_get(m).items()}
            bar.update(per_call)
            sps = (step - s_sps) / max(time.perf_counter() - t_sps, 1e-9)
            bar.set_postfix(sps=f"{sps:.0f}", **post, refresh=False)
            over_budget = (
                self.budget_train_s is not None and clocks()["train_wall_s"] >= self.budget_train_s
            )
            if step >= n_eval * cfg.eval_every or step >= cfg.num_timesteps or over_budget:
                ev = timed_eval(cfg.seed + 10_000 + n_eval)
                n_eval = max(n_eval + 1, step // cfg.eval_every + 1)
                row = {
                    "step": step,
                    **clocks(),
                    "sps": sps,
                    **_prefix("eval/", ev),
                    **_train_stats(totals),
                    **losses,
                }
                self._append_row(row, tb)
                self.save_checkpoint(
                    carry, step, {"wall_s": wall(), "eval_s": eval_s, "n_eval": n_eval}
                )
                post = {
                    "success": f"{ev['success_rate']:.2f}",
                    "return": f"{ev['mean_return']:.1f}",
                }
                bar.set_postfix(sps=f"{sps:.0f}", **post)
                totals = {k: 0.0 for k in TOTAL_KEYS}
                t_sps, s_sps = time.perf_counter(), step
                if self.stop_at_success is not None and ev["success_rate"] >= self.stop_at_success:
                    print(
                        f"eval success {ev['success_rate']:.2f} >= {self.stop_at_success}: "
                        f"stopping at {step} env steps",
                        file=sys.stderr,
                    )
                    break
                if over_budget:
                    print(
                        f"training clock reached the {self.budget_train_s:g} s budget: "
                        f"stopping at {step} env steps",
                        file=sys.stderr,
                    )
                    break
        bar.close()
        if tb is not None:
            tb.close()
        self.carry = carry  # the final carry, for callers that continue in-process
        return self.finish(carry, step, wall())

    # ------------------------------------------------------------------ outputs
    def finish(self, carry, step: int, wall_s: float) -> dict[str, Any]:
        save_policy(
            self.out / "final_policy", self.trainer.policy_params(carry), self._policy_meta(step)
        )  # both files or neither (a temporary folder renamed)
        rows = self._read_rows()
        first95 = next(
            (r for r in rows if _f(r["eval/success_rate"]) >= SUCCESS_THRESHOLD),
            None,
        )
        t95 = float(first95["wall_s"]) if first95 else None
        t95_train = _f(first95.get("train_wall_s")) if first95 else None
        last = rows[-1] if rows else {}
        summary = {
            "env": self.cfg.env,
            "compliance_strategy": bool(self.env.config.compliance_strategy),
            "profile": self.cfg.profile,
            "env_steps": step,
            "wall_s": round(wall_s, 1),
            "time_to_95pct_success_s": t95,
            # the same without the evaluations' wall clock (compilation and prefill included)
            "time_to_95pct_success_train_s": t95_train,
            "step_at_95pct_success": int(first95["step"]) if first95 else None,
            "untrained_eval_return": _f(rows[0]["eval/mean_return"]) if rows else None,
            "final_eval": {k[5:]: _f(v) for k, v in last.items() if k.startswith("eval/")},
            **provenance(),
        }
        # strict JSON: a statistic without a value (no successful episode) is null, not NaN
        fileio.write_text(self.out / "summary.json", dumps(summary, indent=2) + "\n")
        try:
            from peghole_mjx.training.plots import plot_curves

            plot_curves([self.out], self.out / "curves.png")
        except Exception as exc:  # a plot must never lose a finished run
            print(f"warning: learning curves not plotted: {exc}", file=sys.stderr)
        if self.render:
            try:
                from peghole_mjx.training.video import render_policy_gif

                render_policy_gif(self.out / "final_policy", self.out / "rollout.gif")
            except Exception as exc:
                print(f"warning: rollout GIF not rendered: {exc}", file=sys.stderr)
        return summary


# ---------------------------------------------------------------------- resources
def replay_row_bytes(obs_size: int, act_size: int) -> int:
    """Bytes of one replay row: observation, action, reward, discount, next observation and
    the truncation flag, float32 (Brax's ``Transition``, flattened)."""
    return 4 * (2 * obs_size + act_size + 3)


def check_resources(env, cfg: TrainConfig, obs_size: int, act_size: int, seeds: int = 1) -> int:
    """Refuse, before anything is allocated or compiled, a run whose replay buffer, batch and
    worlds do not fit the available memory (``peghole_mjx.memory.check_fits``, host and
    device); return an estimate of the bytes its outputs take on disk (the two newest states
    and the one being written, a policy per evaluation, logs and pictures).

    The replay buffer is counted twice (a training call's input and output carries), worlds
    four times (state, next state, fresh resets, work space)."""

    row = replay_row_bytes(obs_size, act_size)
    replay = seeds * cfg.max_replay_size * row
    batch = seeds * cfg.batch_size * cfg.grad_updates_per_step * row * 2
    runs = f"{seeds} seeds x " if seeds > 1 else ""
    memory.check_fits(
        2 * replay + batch,
        f"the replay buffer ({runs}max_replay_size={cfg.max_replay_size} rows of {row} B, "
        "held twice during a training call)",
        "lower --set max_replay_size",
    )
    world = memory.world_bytes(env)  # traced, not compiled
    worlds = seeds * (cfg.num_envs + cfg.num_eval_envs) * world * memory.WORLD_COPIES
    memory.check_fits(
        2 * replay + batch + worlds,
        f"training ({runs}replay buffer {memory.fmt_bytes(2 * replay)}, batch "
        f"{memory.fmt_bytes(batch)}, {cfg.num_envs} + {cfg.num_eval_envs} eval worlds of "
        f"{world} B: {memory.fmt_bytes(worlds)})",
        "lower --set num_envs, num_eval_envs, batch_size or max_replay_size",
    )
    sizes = [obs_size, *cfg.hidden_layer_sizes, 2 * act_size]
    policy = 4 * sum(a * b + b for a, b in itertools.pairwise(sizes)) + 8 * obs_size + 65536
    evals = cfg.num_timesteps // cfg.eval_every + 2
    state = replay + seeds * cfg.num_envs * world + 8 * policy
    return 3 * state + seeds * evals * policy + (32 << 20)


# ---------------------------------------------------------------------- run folders
#: what a run writes besides run.json (``history_N/`` holds these of an abandoned history)
RUN_OUTPUTS = (
    "metrics.csv",
    "history.csv",
    "checkpoints",
    "tb",
    "final_policy",
    "summary.json",
    "seeds.json",
    "curves.png",
    "rollout.gif",
)


def _data_rows(path: Path) -> bool:
    """``path`` (a CSV log) holds anything beyond its header line."""
    if not path.exists():
        return False
    lines = [line for line in path.read_bytes().split(b"\n") if line.strip()]
    return len(lines) > 1


def failed_start(out: Path) -> bool:
    """``out`` holds a readable run.json and nothing of a run's progress: no evaluation row,
    no checkpoint (of any kind), no final output. Such a folder is what a run that failed
    before its first evaluation leaves (e.g. out of memory while compiling); a new run may
    take it over (:func:`clear_failed_start`, under the run's lock)."""
    try:
        read_run_record(out, full=False)
    except UserInputError:
        return False
    ckpt = out / "checkpoints"
    if ckpt.is_dir() and any(ckpt.iterdir()):
        return False
    if _data_rows(out / "metrics.csv") or _data_rows(out / "history.csv"):
        return False
    finals = ("final_policy", "summary.json", "seeds.json")
    return not any((out / f).exists() for f in finals) and not any(out.glob("seed_*"))


def clear_failed_start(out: Path) -> None:
    """Remove what a failed start left in ``out`` (:func:`failed_start`), with a warning."""
    import shutil

    print(
        f"warning: {out} holds a run that stopped before its first evaluation (no metrics, "
        "no checkpoint): the new run replaces it",
        file=sys.stderr,
    )
    for name in ("metrics.csv", "history.csv", "tb", "checkpoints"):
        p = out / name
        if p.is_dir():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)
    (out / "run.json").unlink()
    fileio.fsync_dir(out)


def set_history_aside(out: Path) -> Path | None:
    """Move a run's outputs (:data:`RUN_OUTPUTS`, ``seed_K/``) into a new ``history_N/`` with a
    copy of run.json, so that a run starting over never truncates or overwrites them; the
    folder, or None when there was nothing to keep. Each move is a rename: a kill midway
    leaves every file in one of the two places."""
    import shutil

    items = [out / n for n in RUN_OUTPUTS if (out / n).exists()]
    items += sorted(p for p in out.glob("seed_*") if p.is_dir())
    if not items:
        return None
    taken = [int(p.name[8:]) for p in out.glob("history_*") if p.name[8:].isdigit()]
    dest = out / f"history_{max(taken, default=0) + 1}"
    dest.mkdir()
    if (out / "run.json").exists():
        shutil.copy2(out / "run.json", dest / "run.json")
    for p in items:
        os.replace(p, dest / p.name)
    fileio.fsync_dir(dest)
    fileio.fsync_dir(out)
    return dest


def starting_over(out: Path, ckpt_dir: Path) -> Path | None:
    """A resume that found no checkpoint to continue from: the earlier history is set aside
    (:func:`set_history_aside`) and the warning says where."""
    dest = set_history_aside(out)
    kept = ""
    if dest is not None:
        names = ", ".join(sorted(p.name for p in dest.iterdir() if p.name != "run.json"))
        kept = f"; the earlier history ({names}) is kept in {dest}, not overwritten"
    print(f"warning: no complete checkpoint in {ckpt_dir}: starting over{kept}", file=sys.stderr)
    return dest


# ---------------------------------------------------------------------- helpers
def policy_meta(cfg: TrainConfig, network: dict[str, Any], step: int) -> dict[str, Any]:
    """``policy.json`` of a policy trained with ``cfg`` for ``step`` env steps."""
    return {
        "env": cfg.env,
        "env_overrides": cfg.env_overrides,
        "network": network,
        "train_config": cfg.as_dict(),
        "env_steps": step,
        "provenance": provenance(),
    }


def _tensorboard(path: Path):
    try:
        from tensorboardX import SummaryWriter
    except ImportError:  # optional: metrics.csv has the same numbers
        print("tensorboardX not installed: TensorBoard logs skipped", file=sys.stderr)
        return None
    return SummaryWriter(str(path))


def _accumulate(totals: dict[str, float], tot) -> None:
    for k, v in jax.device_get(tot).items():
        totals[k] += float(np.sum(v))


def _train_stats(t: dict[str, float]) -> dict[str, float]:
    """The training episodes' statistics of an evaluation period (``train/...``)."""
    return _prefix("train/", summarize_totals(t), TRAIN_STATS)


def _prefix(p: str, d: dict[str, Any], keys=EVAL_STATS) -> dict[str, Any]:
    """The logged statistics of ``d``, prefixed (``eval/...``)."""
    return {p + k: d[k] for k in keys if k in d}


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


def _f(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")
