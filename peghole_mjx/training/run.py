"""Training runs on disk: the one driver of ``peghole train`` (:class:`Run`) and its single-seed
run (:class:`TrainingRun`); the multi-seed run (``--seeds N``) is
:class:`peghole_mjx.training.seeds.SeedsRun`, the same driver with another learner and layout.

Layout of a single-seed ``--out DIR``::

    run.json              env, hyperparameters, network, device, versions, start date
    metrics.csv           one row per evaluation (env steps, wall clock, eval and training stats)
    tb/                   TensorBoard event files (same scalars)
    run.lock              held by the process writing the run (peghole_mjx/files/lock.py)
    checkpoints/step_N/   policy.json + params.npz at every evaluation; the two newest also
                          hold state/ (orbax, by tree path) + state.json (the whole carry,
                          for --resume);
                          manifest.json: every file's size and SHA-256 (training/checkpoints.py)
    final_policy/         the policy at the end (what `peghole evaluate DIR` loads)
    curves.png            Figs 4.5-4.7 style learning curves
    rollout.gif           one episode of the final policy (mujoco.Renderer, headless)
    summary.json          final evaluation, wall clock, time to 95 % success

What every run shares is :class:`Run`'s: the start (a folder that holds a run is refused, one
that a failed start left is taken over), the resume, the calls of the learner with a checkpoint
and log rows at each boundary, and one writer each of the checkpoints
(:func:`peghole_mjx.training.checkpoints.save` / ``load``), the CSV log
(:class:`peghole_mjx.training.logs.CsvLog`) and ``run.json``
(:func:`peghole_mjx.training.config.write_run_record`). The two runs differ in their learner
(single seed: :class:`~peghole_mjx.training.sac.SACTrainer`, ``pmap``-ed over every device and
process, with evaluations during training; several seeds:
:func:`~peghole_mjx.training.functional.make_train` ``vmap``-ed over the seeds' keys) and in
their layout (``metrics.csv`` and one policy per checkpoint, or ``history.csv`` and ``seed_K/``).
Decided 2026-12-02: the single-seed run is not the one-seed case of the multi-seed run, as that
would change its layout (``metrics.csv`` with evaluation rows, ``checkpoints/step_N/policy.json``,
which ``peghole evaluate`` and the published runs rely on) and drop ``--distributed``.

Resume (``--resume DIR``) restores the newest checkpoint whose state verifies (a corrupt
newer one is set aside with a warning): actor, critics, target critics, temperature, optimiser
states, normaliser, replay buffer, every world's state, the PRNG key, the env-step counter, the
wall clock so far and the evaluation schedule. Rows of the log written after that checkpoint
are dropped (their work is redone; none are kept when no checkpoint was written, and the
earlier history is then moved into ``history_N/``). Nothing of the run is rewritten before the
new configuration and the checkpoint have been validated and loaded; every file is written
atomically (``peghole_mjx.files.fileio``).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np
from tqdm import tqdm

from peghole_mjx import envs
from peghole_mjx.core import memory
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import check, dumps
from peghole_mjx.envs import rollout as rollouts
from peghole_mjx.envs.metrics import EVAL_STATS, TOTAL_KEYS, TRAIN_STATS, summarize_totals
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import RunLock
from peghole_mjx.files.provenance import commit, provenance
from peghole_mjx.policies import make_policy_fn, save_policy
from peghole_mjx.sim.engines import engine_label, task_overrides
from peghole_mjx.training import checkpoints
from peghole_mjx.training.config import RUN_RECORD, TrainConfig, read_run_record, write_run_record
from peghole_mjx.training.logs import CsvLog
from peghole_mjx.training.plots import plot_curves
from peghole_mjx.training.sac import SACTrainer
from peghole_mjx.training.video import render_policy_gif

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
#: evaluation seeds: ``cfg.seed + EVAL_SEED_OFFSET + k`` for the k-th evaluation of a run
EVAL_SEED_OFFSET = 10_000


class Run:
    """The driver every training run shares (see the module): ``run()`` starts or resumes it,
    then calls the learner until its last env step, writing the log rows and a checkpoint at
    each boundary. A subclass gives the learner, the layout and the outputs (the hooks below)."""

    #: the run's CSV log in its folder, its columns and the columns each row must have
    LOG_NAME = "metrics.csv"
    LOG_COLUMNS: tuple[str, ...] = METRIC_COLUMNS
    LOG_KEYS: tuple[str, ...] = ("step",)
    #: the keys of ``state.json`` a checkpoint of this run must hold (its schedule)
    SCHEDULE_KEYS: tuple[str, ...] = ()
    #: the run's lock when the caller took it (else :meth:`run` takes it)
    lock: RunLock | None = None
    #: run.json as it will be once the resumed config and checkpoint are validated
    _pending_meta: dict[str, Any] | None = None
    progress = True
    #: the final carry, for callers that continue in-process
    carry: Any = None
    cfg: TrainConfig
    out: Path
    ckpt_dir: Path

    @classmethod
    def log_at(cls, out: str | Path) -> CsvLog:
        """The CSV log (``metrics.csv`` or ``history.csv``) of this kind of run in ``out``."""
        return CsvLog(Path(out) / cls.LOG_NAME, cls.LOG_COLUMNS, cls.LOG_KEYS)

    @property
    def log(self) -> CsvLog:
        """The run's CSV log."""
        return self.log_at(self.out)

    def checkpoint_files(self) -> tuple[str, ...]:
        """What a checkpoint of this run holds, verified before a resume."""
        return (*checkpoints.POLICY_FILES, *checkpoints.STATE_FILES)

    # ------------------------------------------------------------------ hooks
    def _template(self) -> Any:
        """A carry of this run's structure, shapes and dtypes (what a checkpoint restores)."""
        raise NotImplementedError

    def _on_device(self, template: Any, host: Any) -> Any:
        """The restored host arrays ``host`` placed as the learner wants them."""
        raise NotImplementedError

    def _write_policies(self, folder: Path, host: Any, step: int) -> None:
        """Write the policy files of a checkpoint into ``folder`` (a temporary folder)."""
        raise NotImplementedError

    def _record(self) -> dict[str, Any]:
        """``run.json`` of a new run."""
        raise NotImplementedError

    def _schedule(self) -> dict[str, Any]:
        """What a checkpoint records besides the env step (the evaluation schedule)."""
        return {}

    def _init_carry(self) -> Any:
        raise NotImplementedError

    def _start(self, carry: Any, step: int, sched: dict[str, Any] | None, tb) -> tuple[Any, int]:
        """Before the first call: the clocks and schedule (``sched``: a checkpoint's, None for
        a new run) and whatever a run does first; returns ``(carry, step)``."""
        return carry, step

    @property
    def total_steps(self) -> int:
        raise NotImplementedError

    @property
    def steps_per_call(self) -> int:
        raise NotImplementedError

    def _desc(self) -> str:
        return f"SAC {self.cfg.env}"

    def _advance(self, carry: Any, step: int, bar) -> Any:
        """One call of the learner from env step ``step``."""
        raise NotImplementedError

    def _at_boundary(self, step: int) -> bool:
        """A checkpoint (and log rows) is due after the call that reached ``step``."""
        raise NotImplementedError

    def _boundary_rows(self, carry: Any, step: int, bar) -> tuple[list[dict], str | None]:
        """The log rows of a boundary and, to end the run there, the reason (printed)."""
        raise NotImplementedError

    def _finish(self, carry: Any, step: int) -> dict[str, Any]:
        raise NotImplementedError

    def _open_tensorboard(self):
        return None

    # ------------------------------------------------------------------ state I/O
    def save_checkpoint(self, carry: Any, step: int, sched: dict[str, Any]) -> Path:
        """Write ``checkpoints/step_N`` completely (:func:`checkpoints.save`: fsynced, sealed,
        renamed): the run's policies, its state and ``sched``; the two newest checkpoints keep
        their state."""
        host = jax.device_get(carry)
        return checkpoints.save(
            self.ckpt_dir, step, host, sched, lambda f: self._write_policies(f, host, step)
        )

    def _save(self, carry: Any, step: int) -> Path:
        """The checkpoint of a boundary (:meth:`save_checkpoint` with the run's schedule)."""
        return self.save_checkpoint(carry, step, self._schedule())

    def load_checkpoint(self, path: Path) -> tuple[Any, dict[str, Any]]:
        """``(carry, sched)`` of checkpoint ``path``, restored by tree path into this run's
        carry (a carry of another structure is refused: ``checkpoints.restore_state``)."""
        template = self._template()
        host, sched = checkpoints.load(path, template, self.SCHEDULE_KEYS)
        return self._on_device(template, host), sched

    # ------------------------------------------------------------------ start and resume
    def _prepare(self, resume: bool) -> tuple[tuple[Path, Any] | None, list[dict[str, str]]]:
        """``(found, rows)``: the checkpoint to resume from (``(path, (carry, sched))``, None:
        from the start) and the log rows up to it. A new run refuses a folder that holds a run
        (but for a failed start, replaced); a resume verifies each checkpoint by this run's
        layout (:meth:`checkpoint_files`), falls back past corrupt ones and, finding none, sets
        the history aside (``history_N/``) before starting over. Only then are the run's records
        rewritten: run.json (with a validated change) and the log, cut to the checkpoint's
        step (the header alone when starting over)."""
        self.out.mkdir(parents=True, exist_ok=True)
        if not resume and (self.out / RUN_RECORD).exists():
            if not failed_start(self.out):
                raise UserInputError(
                    f"{self.out} already holds a training run: use --resume {self.out} or a "
                    "new --out"
                )
            clear_failed_start(self.out)
        # the log read once, schema-checked before any work (file and line)
        logged = self.log.read() if resume else []
        found = None
        if resume:
            found = checkpoints.newest_valid(
                self.ckpt_dir, self.load_checkpoint, self.checkpoint_files()
            )
            if found is None:
                starting_over(self.out, self.ckpt_dir)
        # validated: from here on the run's records are rewritten
        if self._pending_meta is not None:
            write_run_record(self.out, self._pending_meta)
            self._pending_meta = None
        if not (self.out / RUN_RECORD).exists():
            write_run_record(self.out, self._record())
        rows = [r for r in logged if int(r["step"]) <= found[1][1]["step"]] if found else []
        self.log.rewrite(rows)
        return found, rows

    # ------------------------------------------------------------------ main loop
    def run(self, resume: bool = False) -> dict[str, Any]:
        """Train (``resume``: from the newest valid checkpoint) holding the run's lock."""
        lock = self.lock
        if lock is None or not lock.held:
            lock = RunLock(self.out).acquire()
        try:
            return self._drive(resume)
        finally:
            if lock is not self.lock:
                lock.release()

    def _drive(self, resume: bool) -> dict[str, Any]:
        found, _ = self._prepare(resume)
        tb = self._open_tensorboard()
        if found is not None:
            path, (carry, sched) = found
            step = sched["step"]
            print(f"resumed from {path} at {step} env steps", file=sys.stderr)
        else:
            carry, step, sched = self._init_carry(), 0, None
        carry, step = self._start(carry, step, sched, tb)
        total, per_call = self.total_steps, self.steps_per_call
        bar = tqdm(
            total=total,
            initial=min(step, total),
            unit="step",
            unit_scale=True,
            desc=self._desc(),
            file=sys.stderr,
            disable=not self.progress,
            dynamic_ncols=True,
        )
        while step < total:
            carry = self._advance(carry, step, bar)
            step += per_call
            bar.update(per_call)
            if self._at_boundary(step):
                rows, stop = self._boundary_rows(carry, step, bar)
                with naming(self.log.path):
                    self.log.append(rows, tb)
                with naming(self.ckpt_dir / checkpoints.checkpoint_name(step)):
                    self._save(carry, step)
                if stop:
                    print(f"{stop}: stopping at {step} env steps", file=sys.stderr)
                    break
        bar.close()
        if tb is not None:
            tb.close()
        self.carry = carry
        return self._finish(carry, step)


class TrainingRun(Run):
    """One seed: a :class:`SACTrainer` with evaluations, ``metrics.csv``, TensorBoard logs and
    a checkpoint at every evaluation (the module's layout)."""

    SCHEDULE_KEYS = ("wall_s", "n_eval")

    def __init__(
        self,
        cfg: TrainConfig,
        out: str | Path,
        progress: bool = True,
        render: bool = True,
        stop_at_success: float | None = None,
        budget_train_s: float | None = None,
    ):
        self.cfg, self.out, self.progress, self.render = cfg, Path(out), progress, render
        #: end the run at the first evaluation whose success rate reaches this (benchmarks)
        self.stop_at_success = stop_at_success
        #: end the run, after a last evaluation, once the training clock (evaluations
        #: excluded) reaches this many seconds (benchmarks with a wall-clock budget)
        self.budget_train_s = budget_train_s
        self.env = envs.load(cfg.env, config_overrides=cfg.env_overrides or None)
        self.trainer = SACTrainer(self.env, cfg)
        # before anything is allocated, compiled or written
        need_disk = check_resources(self.env, cfg, self.trainer.obs_size, self.trainer.act_size)
        fileio.check_room(self.out, need_disk, "--out")
        self.policy_fn = make_policy_fn(self.trainer.network, deterministic=True)
        self.ckpt_dir = self.out / "checkpoints"

    # ------------------------------------------------------------------ construction
    @classmethod
    def resume(
        cls,
        out: str | Path,
        progress: bool = True,
        render: bool = True,
        num_timesteps: int | None = None,
    ) -> TrainingRun:
        """The run in ``out`` with its own config; ``num_timesteps`` extends it (a smaller one
        than the run's is refused: decided 2026-12-04).

        Nothing is written here: the changed ``run.json`` is written by :meth:`run` once the
        new configuration and the checkpoint have been validated.
        """
        out = Path(out)
        meta, _ = read_run_record(out)  # schema-checked, its config validated
        cls.log_at(out).read()  # checked before the env is built
        config = dict(meta["config"])
        if num_timesteps is not None:
            n = check("num_timesteps", num_timesteps, "--set num_timesteps")
            recorded = config.get("num_timesteps")
            config["num_timesteps"] = n
            meta = {**meta, "config": config}
            meta["resumed_with"] = [*meta.get("resumed_with", []), {"num_timesteps": n}]
        cfg = TrainConfig.from_dict(config)  # validated before anything is built
        if num_timesteps is not None and isinstance(recorded, int) and n < recorded:
            raise UserInputError(
                f"--set num_timesteps={n} is below the run's num_timesteps={recorded}: "
                "--resume only extends a run (run.json and metrics.csv stay as they are); to "
                "end it sooner, stop it (Ctrl-C) and use its newest checkpoint"
            )
        run = cls(cfg, out, progress, render)
        if num_timesteps is not None:
            run._pending_meta = meta
        return run

    def prepare(self, resume: bool):
        """``(path, carry, sched)`` of the checkpoint to resume from, or None (from the start),
        once the run folder is checked and its records rewritten (:meth:`Run._prepare`)."""
        found, _ = self._prepare(resume)
        if found is None:
            return None
        path, (carry, sched) = found
        return path, carry, sched

    # ------------------------------------------------------------------ state I/O
    def _template(self):
        return self.trainer.init_carry(self.cfg.seed)

    def _on_device(self, template, host):
        return jax.tree.map(
            lambda t, x: jax.device_put(x.astype(t.dtype), t.sharding), template, host
        )

    def _write_policies(self, folder: Path, host, step: int) -> None:
        params = self.trainer.policy_params(host)
        save_policy(folder, params, self._policy_meta(step), atomic=False)

    def _record(self) -> dict[str, Any]:
        return {
            "config": self.cfg.as_dict(),
            "engine": engine_label(self.env.config),  # the engine this run steps with
            "network": self.trainer.network,
            **provenance(),
            "commit": commit(),
        }

    def _policy_meta(self, step: int) -> dict[str, Any]:
        return policy_meta(self.cfg, self.trainer.network, step, engine_label(self.env.config))

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, carry, episodes: int, seed: int) -> dict[str, float]:
        params = self.trainer.policy_params(carry)
        res = rollouts.rollout(
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

    def _read_rows(self, upto_step: int | None = None) -> list[dict[str, str]]:
        """The rows of ``metrics.csv`` (up to ``upto_step``), schema-checked; a row cut short
        by a kill during its write is dropped."""
        return self.log.read(upto_step)

    # ------------------------------------------------------------------ the driver's hooks
    @property
    def total_steps(self) -> int:
        return self.cfg.num_timesteps

    @property
    def steps_per_call(self) -> int:
        return self.cfg.num_envs * self.cfg.steps_per_call

    def _init_carry(self):
        return self.trainer.init_carry(self.cfg.seed)

    def _wall(self) -> float:
        return self._wall0 + time.perf_counter() - self._t_start

    def _clocks(self) -> dict[str, float]:
        return {"wall_s": self._wall(), "train_wall_s": self._wall() - self._eval_s}

    def _timed_eval(self, carry, seed: int) -> dict[str, float]:
        t0 = time.perf_counter()
        ev = self.evaluate(carry, self.cfg.num_eval_envs, seed=seed)
        self._eval_s += time.perf_counter() - t0
        return ev

    def _schedule(self) -> dict[str, Any]:
        return {"wall_s": self._wall(), "eval_s": self._eval_s, "n_eval": self._n_eval}

    def _open_tensorboard(self):
        return _tensorboard(self.out / "tb")

    def _start(self, carry, step, sched, tb):
        """The clocks and evaluation schedule (a checkpoint's, or zero); a new run evaluates
        the untrained policy, then fills the replay buffer (prefill calls)."""
        cfg = self.cfg
        self._t_start = time.perf_counter()
        sched = sched or {}
        self._wall0 = sched.get("wall_s", 0.0)
        self._n_eval = sched.get("n_eval", 0)
        self._eval_s = sched.get("eval_s", 0.0)  # evaluations' wall clock (not train_wall_s)
        self._totals = {k: 0.0 for k in TOTAL_KEYS}
        self._losses: dict[str, float] = {}
        if step == 0:  # the untrained policy, then the replay prefill
            ev = self._timed_eval(carry, cfg.seed + EVAL_SEED_OFFSET)
            self.log.append([{"step": 0, **self._clocks(), **_prefix("eval/", ev)}], tb)
            self._n_eval = 1
            while step < cfg.min_replay_size:
                carry, tot = self.trainer.prefill(carry)
                step += self.steps_per_call
                _accumulate(self._totals, tot)
        last = self._read_rows()
        self._post = {}
        if last:
            self._post = {
                "success": last[-1]["eval/success_rate"],
                "return": last[-1]["eval/mean_return"],
            }
        self._t_sps, self._s_sps, self._sps = time.perf_counter(), step, 0.0
        return carry, step

    def _advance(self, carry, step: int, bar):
        carry, tot, m = self.trainer.train_call(carry)
        _accumulate(self._totals, tot)
        self._losses = {k: float(np.mean(v)) for k, v in jax.device_get(m).items()}
        done = step + self.steps_per_call - self._s_sps
        self._sps = done / max(time.perf_counter() - self._t_sps, 1e-9)
        bar.set_postfix(sps=f"{self._sps:.0f}", **self._post, refresh=False)
        return carry

    def _at_boundary(self, step: int) -> bool:
        """An evaluation is due (by the schedule, at the end, or past the training budget)."""
        cfg, budget = self.cfg, self.budget_train_s
        self._over_budget = budget is not None and self._clocks()["train_wall_s"] >= budget
        due = step >= self._n_eval * cfg.eval_every or step >= cfg.num_timesteps
        return due or self._over_budget

    def _boundary_rows(self, carry, step: int, bar):
        cfg = self.cfg
        ev = self._timed_eval(carry, cfg.seed + EVAL_SEED_OFFSET + self._n_eval)
        self._n_eval = max(self._n_eval + 1, step // cfg.eval_every + 1)
        row = {
            "step": step,
            **self._clocks(),
            "sps": self._sps,
            **_prefix("eval/", ev),
            **_train_stats(self._totals),
            **self._losses,
        }
        self._post = {"success": f"{ev['success_rate']:.2f}", "return": f"{ev['mean_return']:.1f}"}
        bar.set_postfix(sps=f"{self._sps:.0f}", **self._post)
        self._totals = {k: 0.0 for k in TOTAL_KEYS}
        self._t_sps, self._s_sps = time.perf_counter(), step
        stop = None
        if self.stop_at_success is not None and ev["success_rate"] >= self.stop_at_success:
            stop = f"eval success {ev['success_rate']:.2f} >= {self.stop_at_success}"
        elif self._over_budget:
            stop = f"training clock reached the {self.budget_train_s:g} s budget"
        return [row], stop

    def _finish(self, carry, step: int) -> dict[str, Any]:
        return self.finish(carry, step, self._wall())

    # ------------------------------------------------------------------ outputs
    def finish(self, carry, step: int, wall_s: float) -> dict[str, Any]:
        """The final policy, ``summary.json``, the learning curves and the rollout GIF."""
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
            plot_curves([self.out], self.out / "curves.png")
        except Exception as exc:  # a plot must never lose a finished run
            print(f"warning: learning curves not plotted: {exc}", file=sys.stderr)
        if self.render:
            try:
                render_policy_gif(self.out / "final_policy", self.out / "rollout.gif")
            except Exception as exc:
                print(f"warning: rollout GIF not rendered: {exc}", file=sys.stderr)
        return summary


@contextlib.contextmanager
def naming(path: str | Path):
    """Give an ``OSError`` raised without a file name (a write or fsync on a full disk:
    ``[Errno 28] No space left on device``) the name of ``path``, the file or folder being
    written, so that the one line the CLI prints says which (``PATH: No space left on
    device``)."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None or exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


# ---------------------------------------------------------------------- resources
def replay_row_bytes(obs_size: int, act_size: int) -> int:
    """Bytes of one replay row: observation, action, reward, discount, next observation and
    the truncation flag, float32 (Brax's ``Transition``, flattened)."""
    return 4 * (2 * obs_size + act_size + 3)


def check_resources(env, cfg: TrainConfig, obs_size: int, act_size: int, seeds: int = 1) -> int:
    """Refuse, before anything is allocated or compiled, a run whose replay buffer, batch and
    worlds do not fit the available memory (``peghole_mjx.core.memory.check_fits``, host and
    device); return an estimate of the bytes its outputs take on disk (the two newest states
    and the one being written, a policy per evaluation, logs and pictures).

    The replay buffer is counted twice (a training call's input and output carries), worlds
    four times (state, next state, fresh resets, work space)."""

    row = replay_row_bytes(obs_size, act_size)
    replay = seeds * cfg.max_replay_size * row
    batch = seeds * cfg.batch_size * cfg.grad_updates_per_step * row * 2
    runs = f"{seeds} seeds x " if seeds > 1 else ""
    fewer = "fewer --seeds or " if seeds > 1 else ""  # each seed has its own buffer and worlds
    memory.check_fits(
        2 * replay + batch,
        f"the replay buffer ({runs}max_replay_size={cfg.max_replay_size} rows of {row} B, "
        "held twice during a training call)",
        f"give {fewer}a lower --set max_replay_size",
    )
    world = memory.world_bytes(env)  # traced, not compiled
    worlds = seeds * (cfg.num_envs + cfg.num_eval_envs) * world * memory.WORLD_COPIES
    memory.check_fits(
        2 * replay + batch + worlds,
        f"training ({runs}replay buffer {memory.fmt_bytes(2 * replay)}, batch "
        f"{memory.fmt_bytes(batch)}, {cfg.num_envs} + {cfg.num_eval_envs} eval worlds of "
        f"{world} B: {memory.fmt_bytes(worlds)})",
        f"give {fewer}a lower --set num_envs, num_eval_envs, batch_size or max_replay_size",
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
def policy_meta(
    cfg: TrainConfig, network: dict[str, Any], step: int, engine: str | None = None
) -> dict[str, Any]:
    """``policy.json`` of a policy trained with ``cfg`` for ``step`` env steps on ``engine``
    (its ``engine_label``). The engine is provenance, not the task (2026-12-05): the
    ``env_overrides`` leave out the engine entries (:data:`~peghole_mjx.sim.engines.ENGINE_KEYS`)
    and ``engine`` records the one trained on; the policy runs on any engine."""
    return {
        "env": cfg.env,
        "env_overrides": task_overrides(cfg.env_overrides),
        **({"engine": engine} if engine else {}),
        "network": network,
        "train_config": cfg.as_dict(),
        "env_steps": step,
        "provenance": provenance(),
    }


def _tensorboard(path: Path):
    try:
        # function-local: tensorboardX imports torch and boto3 (3.7 s on the 2-core CPU,
        # 2026-12-02), and metrics.csv holds the same numbers when it is missing
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


def _f(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")
