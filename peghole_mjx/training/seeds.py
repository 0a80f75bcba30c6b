"""Several seeds of one SAC config trained in one compiled call: ``peghole train --seeds N``.

The training driver (:class:`peghole_mjx.training.run.Run`: start, resume, checkpoints, the
log, ``run.json``) around :func:`peghole_mjx.training.functional.make_train`: ``jax.vmap`` over
the seeds' keys (seed ``cfg.seed + k``), run in chunks of ``eval_every`` env steps with a
checkpoint after each chunk. Layout of ``--out DIR``::

    run.json            config, seeds, network, device, versions, start date
    history.csv         one row per seed and chunk: env steps and the finished training
                        episodes' statistics (success, F_z, |F_xy|, return, ...) and losses
    checkpoints/step_N/ every seed's policy (seed_K/) and the stacked carry of all seeds
                        (orbax, by tree path; atomic write, SHA-256 manifest, fallback to the
                        previous one: training/checkpoints.py)
    seed_K/final_policy/ seed K's final policy (``peghole evaluate DIR/seed_K/final_policy``)
    seeds.json          each seed's final evaluation (``num_eval_envs`` episodes, the same
                        episodes for every seed) and the mean over seeds with a 95 %
                        Student-t interval
    curves.png          the training episodes' F_z, |F_xy|, discounted return and success per
                        chunk: mean over seeds with the 95 % band (thesis Figs 4.5-4.7)

``--resume DIR`` continues from the newest valid checkpoint (rows of ``history.csv`` after it
are redone). The seeds' worlds, replay buffers and learners are independent: a seed's run is
bit-identical whatever the other seeds of the call (tested).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx import envs, policies
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import dumps
from peghole_mjx.envs import rollout as rollouts
from peghole_mjx.envs.metrics import EVAL_STATS, TOTAL_KEYS, TRAIN_STATS, summarize_totals
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import provenance
from peghole_mjx.sim.engines import engine_label
from peghole_mjx.training import checkpoints
from peghole_mjx.training.config import TrainConfig, env_setting, read_run_record
from peghole_mjx.training.functional import SEED_AXIS, make_train
from peghole_mjx.training.plots import plot_seed_bands, t_interval
from peghole_mjx.training.run import EVAL_SEED_OFFSET, Run, check_resources, policy_meta

#: the losses logged per chunk (means over its calls)
LOSSES = ("loss/critic", "loss/actor", "loss/alpha", "alpha")
HISTORY_COLUMNS = ("seed", "step", *(f"train/{k}" for k in TRAIN_STATS), *LOSSES)

__all__ = ["EVAL_SEED_OFFSET", "HISTORY_COLUMNS", "LOSSES", "SeedsRun", "t_interval"]


class SeedsRun(Run):
    """``seeds`` SAC runs of ``cfg`` (seeds ``cfg.seed`` ... ``cfg.seed + seeds - 1``)."""

    LOG_NAME = "history.csv"
    LOG_COLUMNS = HISTORY_COLUMNS
    LOG_KEYS = ("seed", "step")

    def __init__(self, cfg: TrainConfig, seeds: int, out: str | Path, progress: bool = True):
        if not isinstance(seeds, int) or seeds < 1:
            raise UserInputError(f"--seeds must be a whole number >= 1, got {seeds!r}")
        self.cfg, self.seeds, self.out, self.progress = cfg, seeds, Path(out), progress
        self.env = envs.load(cfg.env, config_overrides=cfg.env_overrides or None)
        self.train = make_train(self.env, cfg, seed_axis=SEED_AXIS)
        # before anything is allocated, compiled or written
        trainer = self.train.trainer
        need_disk = check_resources(self.env, cfg, trainer.obs_size, trainer.act_size, seeds)
        fileio.check_room(self.out, need_disk, "--out")
        self.keys = jnp.stack([jax.random.PRNGKey(cfg.seed + k) for k in range(seeds)])
        self.chunk_calls = max(1, cfg.eval_every // self.train.steps_per_call)
        self.ckpt_dir = self.out / "checkpoints"
        self._init = jax.jit(jax.vmap(self.train.init))
        self._call = jax.jit(jax.vmap(self.train.call, in_axes=(0, None), axis_name=SEED_AXIS))

    @classmethod
    def resume(cls, out: str | Path, progress: bool = True) -> SeedsRun:
        """The multi-seed run in ``out`` with its own config (nothing written here)."""
        meta, cfg = read_run_record(out)  # schema-checked, its config validated
        if "seeds" not in meta:
            raise CorruptFileError(f"{Path(out) / 'run.json'}: not a multi-seed run (no seeds)")
        cls.log_at(out).read()  # checked before the env is built
        return cls(cfg, meta["seeds"], out, progress)

    def checkpoint_files(self) -> tuple[str, ...]:
        """What a checkpoint of this run holds, verified before a resume: every seed's
        policy folder (``seed_K/``) and the stacked state."""
        return (*(f"seed_{k}" for k in range(self.seeds)), *checkpoints.STATE_FILES)

    def prepare(self, resume: bool):
        """``(found, rows)``: the checkpoint to resume from (``(path, (carry, step))``, None:
        from the start) and the rows of history.csv up to it, written back
        (:meth:`Run._prepare`)."""
        found, rows = self._prepare(resume)
        if found is not None:
            path, (carry, sched) = found
            found = path, (carry, sched["step"])
        return found, rows

    # ------------------------------------------------------------------ state I/O
    def _template(self):
        shapes = jax.eval_shape(self._init, self.keys)
        return jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), shapes)

    def _on_device(self, template, host):
        return jax.tree.map(jnp.asarray, host)

    def _write_policies(self, folder: Path, host, step: int) -> None:
        for k in range(self.seeds):
            self._save_policy(folder / f"seed_{k}", host, k, step, atomic=False)

    def _save_policy(self, path: Path, carry, k: int, step: int, atomic: bool = True) -> None:
        params = _seed_slice(self.train.policy_params(carry), k)
        cfg = dataclasses.replace(self.cfg, seed=self.cfg.seed + k)
        meta = policy_meta(cfg, self.train.network, step, engine_label(self.env.config))
        policies.save_policy(path, params, meta, atomic=atomic)

    def _record(self) -> dict[str, Any]:
        return {
            "config": self.cfg.as_dict(),
            "seeds": self.seeds,
            "engine": engine_label(self.env.config),  # the engine this run steps with
            "network": self.train.network,
            **provenance(),
        }

    # ------------------------------------------------------------------ history
    def _rows(self, upto: int | None = None) -> list[dict[str, str]]:
        """The rows of history.csv (up to env step ``upto``), schema-checked."""
        return self.log.read(upto)

    def _chunk_rows(self, calls: list[tuple[bool, dict]], step: int) -> list[dict[str, Any]]:
        """One row per seed: the training episodes that ended in ``calls`` (``(learn,
        history)`` pairs; the prefill calls are in the first chunk) and the learning calls'
        mean losses."""
        rows = []
        calls = jax.device_get(calls)  # one copy per chunk, not one per call
        learning = [h for learn, h in calls if learn]
        calls = [h for _, h in calls]
        for k in range(self.seeds):
            totals = {key: float(sum(np.sum(c[key][k]) for c in calls)) for key in TOTAL_KEYS}
            stats = summarize_totals(totals)
            row: dict[str, Any] = {"seed": self.cfg.seed + k, "step": step}
            row.update({f"train/{s}": stats[s] for s in TRAIN_STATS if s in stats})
            row.update({m: float(np.mean([c[m][k] for c in learning])) for m in LOSSES})
            rows.append(row)
        return rows

    # ------------------------------------------------------------------ the driver's hooks
    @property
    def total_steps(self) -> int:
        return len(self._flags) * self.steps_per_call

    @property
    def steps_per_call(self) -> int:
        return self.train.steps_per_call

    @property
    def _flags(self) -> np.ndarray:
        """``learn`` of every call of the run (the prefill calls, then the learning calls)."""
        return np.asarray(self.train.learn_flags())

    def _desc(self) -> str:
        return f"SAC {self.cfg.env} x {self.seeds} seeds"

    def _init_carry(self):
        return self._init(self.keys)

    def _start(self, carry, step, sched, tb):
        self._chunk: list[tuple[bool, dict]] = []
        self._learn = self._flags
        return carry, step

    def _advance(self, carry, step: int, bar):
        learn = self._learn[step // self.steps_per_call]
        carry, hist = self._call(carry, jnp.asarray(learn))
        self._chunk.append((bool(learn), hist))
        return carry

    def _at_boundary(self, step: int) -> bool:
        """After every ``chunk_calls`` learning calls, and after the last call."""
        calls = step // self.steps_per_call
        learned = calls - self.train.prefill_calls
        return learned > 0 and (learned % self.chunk_calls == 0 or calls == len(self._learn))

    def _boundary_rows(self, carry, step: int, bar):
        rows, self._chunk = self._chunk_rows(self._chunk, step), []
        return rows, None

    def _finish(self, carry, step: int) -> dict[str, Any]:
        return self.finish(carry, step)

    # ------------------------------------------------------------------ outputs
    def finish(self, carry, step: int) -> dict[str, Any]:
        """Each seed's final policy, evaluated on the same episodes; seeds.json; curves."""
        policy_fn = policies.make_policy_fn(self.train.network, deterministic=True)
        host = jax.device_get(carry)
        per_seed = []
        for k in range(self.seeds):
            self._save_policy(self.out / f"seed_{k}" / "final_policy", host, k, step)
            params = _seed_slice(self.train.policy_params(host), k)
            res = rollouts.rollout(
                self.env,
                policy_fn,
                self.cfg.num_eval_envs,
                seed=self.cfg.seed + EVAL_SEED_OFFSET,
                progress=False,
                params=params,
                gamma=self.cfg.discounting,
                refuse_all_nan=False,  # a training run records it (nan_worlds), goes on
            )
            per_seed.append({"seed": self.cfg.seed + k, **res.summary().as_dict()})
        across = {}
        for s in EVAL_STATS:
            vals = [float(r[s]) for r in per_seed if s in r]
            if vals and s != "episodes":
                finite = [v for v in vals if math.isfinite(v)]
                across[s] = {
                    "mean": float(np.mean(finite)) if finite else None,
                    "ci95_t": t_interval(vals),
                }
        cfg = self.cfg
        summary = {
            "env": cfg.env,
            "compliance_strategy": bool(
                env_setting(cfg.env, cfg.env_overrides, "compliance_strategy")
            ),
            "profile": cfg.profile,
            "seeds": [cfg.seed + k for k in range(self.seeds)],
            "env_steps": step,
            "eval_episodes_per_seed": cfg.num_eval_envs,
            "eval_seed": cfg.seed + EVAL_SEED_OFFSET,
            "final_eval": per_seed,
            "final_eval_over_seeds": across,
            **provenance(),
        }
        # strict JSON: a statistic without a value (no successful episode) is null, not NaN
        fileio.write_text(self.out / "seeds.json", dumps(summary, indent=2) + "\n")
        try:
            plot_seed_bands([self.out], self.out / "curves.png")
        except Exception as exc:  # a plot must never lose a finished run
            print(f"warning: curves not plotted: {exc}", file=sys.stderr)
        return summary


def _seed_slice(tree, k: int):
    """Seed ``k``'s part of a tree stacked over seeds."""
    return jax.tree.map(lambda x: np.asarray(x[k]), tree)
