"""Several seeds of one SAC config trained in one compiled call: ``peghole train --seeds N``.

The thin driver around :func:`peghole_mjx.training.functional.make_train`:
``jax.vmap`` over the seeds' keys (seed ``cfg.seed + k``), run in chunks of ``eval_every``
env steps with a checkpoint after each chunk. Layout of ``--out DIR``::

    run.json            config, seeds, network, device, versions, start date
    history.csv         one row per seed and chunk: env steps and the finished training
                        episodes' statistics (success, F_z, |F_xy|, return, ...) and losses
    checkpoints/step_N/ the stacked carry of all seeds (orbax, by tree path; atomic write,
                        SHA-256 manifest, fallback to the previous one: training/checkpoints.py)
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

import csv
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx import fileio
from peghole_mjx.envs.metrics import EVAL_STATS, TOTAL_KEYS, TRAIN_STATS, summarize_totals
from peghole_mjx.errors import CorruptFileError, UserInputError
from peghole_mjx.provenance import provenance
from peghole_mjx.training import checkpoints
from peghole_mjx.training.config import TrainConfig, read_run_record
from peghole_mjx.training.functional import make_train
from peghole_mjx.validation import dumps

#: the losses logged per chunk (means over its calls)
LOSSES = ("loss/critic", "loss/actor", "loss/alpha", "alpha")
HISTORY_COLUMNS = ("seed", "step", *(f"train/{k}" for k in TRAIN_STATS), *LOSSES)
#: evaluation seed offset (as TrainingRun's evaluations: cfg.seed + 10 000 + k)
EVAL_SEED_OFFSET = 10_000


def t_interval(values: list[float], level: float = 0.95) -> list[float] | None:
    """The ``level`` Student-t interval of the mean of ``values`` (None for fewer than 2)."""
    from scipy import stats

    v = np.asarray([x for x in values if math.isfinite(x)], float)
    if len(v) < 2:
        return None
    half = stats.t.ppf(0.5 + level / 2, len(v) - 1) * v.std(ddof=1) / math.sqrt(len(v))
    return [float(v.mean() - half), float(v.mean() + half)]


class SeedsRun:
    """``seeds`` SAC runs of ``cfg`` (seeds ``cfg.seed`` ... ``cfg.seed + seeds - 1``)."""

    def __init__(self, cfg: TrainConfig, seeds: int, out: str | Path, progress: bool = True):
        from peghole_mjx.envs import load

        if not isinstance(seeds, int) or seeds < 1:
            raise UserInputError(f"--seeds must be a whole number >= 1, got {seeds!r}")
        self.cfg, self.seeds, self.out, self.progress = cfg, seeds, Path(out), progress
        self.env = load(cfg.env, config_overrides=cfg.env_overrides or None)
        self.train = make_train(self.env, cfg)
        # before anything is allocated, compiled or written
        from peghole_mjx.training.run import check_resources

        trainer = self.train.trainer
        need_disk = check_resources(self.env, cfg, trainer.obs_size, trainer.act_size, seeds)
        fileio.check_room(self.out, need_disk, "--out")
        self.keys = jnp.stack([jax.random.PRNGKey(cfg.seed + k) for k in range(seeds)])
        self.chunk_calls = max(1, cfg.eval_every // self.train.steps_per_call)
        self.ckpt_dir = self.out / "checkpoints"
        self._init = jax.jit(jax.vmap(self.train.init))
        self._call = jax.jit(jax.vmap(self.train.call, in_axes=(0, None)))

    @classmethod
    def resume(cls, out: str | Path, progress: bool = True) -> SeedsRun:
        meta, cfg = read_run_record(out)  # schema-checked, its config validated
        if "seeds" not in meta:
            raise CorruptFileError(f"{Path(out) / 'run.json'}: not a multi-seed run (no seeds)")
        if (Path(out) / "history.csv").exists():  # checked before the env is built
            from peghole_mjx.training.plots import read_rows

            read_rows(Path(out) / "history.csv", ("seed", "step"), torn_tail=True)
        return cls(cfg, meta["seeds"], out, progress)

    def checkpoint_files(self) -> tuple[str, ...]:
        """What a checkpoint of this run holds, verified before a resume: every seed's
        policy folder (``seed_K/``) and the stacked state."""
        return (*(f"seed_{k}" for k in range(self.seeds)), *checkpoints.STATE_FILES)

    # ------------------------------------------------------------------ state I/O
    def _template(self):
        shapes = jax.eval_shape(self._init, self.keys)
        return jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), shapes)

    def _load(self, path: Path):
        sched = json.loads((path / "state.json").read_text())
        if not isinstance(sched, dict) or not isinstance(sched.get("step"), int):
            raise CorruptFileError(f"{path}/state.json holds no step")
        host = checkpoints.restore_state(path, self._template(), sched.pop("empty_leaves", {}))
        return jax.tree.map(jnp.asarray, host), sched["step"]

    def _save(self, carry, step: int) -> None:
        host = jax.device_get(carry)

        def write_files(folder: Path) -> None:
            for k in range(self.seeds):
                self._save_policy(folder / f"seed_{k}", host, k, step, atomic=False)
            saved = checkpoints.save_state(folder, host)
            fileio.write_text(folder / "state.json", dumps({"step": step, **saved}) + "\n")

        checkpoints.write(self.ckpt_dir, step, write_files)

    def _save_policy(self, path: Path, carry, k: int, step: int, atomic: bool = True) -> None:
        from peghole_mjx.policies import save_policy
        from peghole_mjx.training.run import policy_meta

        params = _seed_slice(self.train.policy_params(carry), k)
        cfg = dataclasses.replace(self.cfg, seed=self.cfg.seed + k)
        save_policy(path, params, policy_meta(cfg, self.train.network, step), atomic=atomic)

    # ------------------------------------------------------------------ history
    def _rows(self, upto: int | None = None) -> list[dict[str, str]]:
        from peghole_mjx.training.plots import read_rows

        path = self.out / "history.csv"
        if not path.exists():
            return []
        rows = read_rows(path, ("seed", "step"), torn_tail=True)  # schema-checked
        return [r for r in rows if upto is None or int(r["step"]) <= upto]

    def _write_rows(self, rows: list[dict[str, Any]]) -> None:
        with fileio.atomic_open(self.out / "history.csv", "w") as fh:
            w = csv.DictWriter(fh, fieldnames=HISTORY_COLUMNS, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)

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
            row.update({f"train/{s}": _fmt(stats[s]) for s in TRAIN_STATS if s in stats})
            row.update({m: _fmt(float(np.mean([c[m][k] for c in learning]))) for m in LOSSES})
            rows.append(row)
        return rows

    # ------------------------------------------------------------------ main loop
    def run(self, resume: bool = False) -> dict[str, Any]:
        from tqdm import tqdm

        from peghole_mjx.training.lock import RunLock

        self.out.mkdir(parents=True, exist_ok=True)
        with RunLock(self.out):
            found, rows = self.prepare(resume)
            flags = np.asarray(self.train.learn_flags())
            per_call = self.train.steps_per_call
            bar = tqdm(
                total=len(flags) * per_call,
                unit="step",
                unit_scale=True,
                desc=f"SAC {self.cfg.env} x {self.seeds} seeds",
                file=sys.stderr,
                disable=not self.progress,
                dynamic_ncols=True,
            )
            if found is not None:
                path, (carry, step) = found
                print(f"resumed from {path} at {step} env steps", file=sys.stderr)
            else:
                carry, step = self._init(self.keys), 0
            bar.update(step)
            chunk: list[tuple[bool, dict]] = []
            for i in range(step // per_call, len(flags)):
                carry, hist = self._call(carry, jnp.asarray(flags[i]))
                step += per_call
                chunk.append((bool(flags[i]), hist))
                bar.update(per_call)
                learned = i + 1 - self.train.prefill_calls
                if learned > 0 and (learned % self.chunk_calls == 0 or i + 1 == len(flags)):
                    rows += self._chunk_rows(chunk, step)
                    chunk = []
                    self._write_rows(rows)
                    self._save(carry, step)
            bar.close()
            return self.finish(carry, step)

    def prepare(self, resume: bool):
        """``(found, rows)``: the checkpoint to resume from (``(path, (carry, step))``, None:
        from the start) and the rows of history.csv up to it, written back. Holding the lock:
        a new run refuses a folder that holds a run (but for a failed start, replaced); a
        resume verifies each checkpoint by this run's layout (``seed_K/`` policies and the
        state), falls back past corrupt ones and, finding none, sets the history aside
        (``history_N/``) before starting over."""
        from peghole_mjx.training.run import clear_failed_start, failed_start, starting_over

        found = None
        if resume:
            self._rows()  # history.csv schema-checked before any work (file and line)
            found = checkpoints.newest_valid(self.ckpt_dir, self._load, self.checkpoint_files())
            if found is None:
                starting_over(self.out, self.ckpt_dir)
        elif (self.out / "run.json").exists():
            if not failed_start(self.out):
                raise UserInputError(
                    f"{self.out} already holds a training run: use --resume or a new --out"
                )
            clear_failed_start(self.out)
        if not (self.out / "run.json").exists():
            meta = {
                "config": self.cfg.as_dict(),
                "seeds": self.seeds,
                "network": self.train.network,
                **provenance(),
            }
            fileio.write_text(self.out / "run.json", dumps(meta, indent=2) + "\n")
        rows = self._rows(upto=found[1][1]) if found is not None else []
        self._write_rows(rows)
        return found, rows

    def finish(self, carry, step: int) -> dict[str, Any]:
        """Each seed's final policy, evaluated on the same episodes; seeds.json; curves."""
        from peghole_mjx.envs.rollout import rollout
        from peghole_mjx.policies import make_policy_fn

        policy_fn = make_policy_fn(self.train.network, deterministic=True)
        host = jax.device_get(carry)
        per_seed = []
        for k in range(self.seeds):
            self._save_policy(self.out / f"seed_{k}" / "final_policy", host, k, step)
            params = _seed_slice(self.train.policy_params(host), k)
            res = rollout(
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
        summary = {
            "env": self.cfg.env,
            "compliance_strategy": bool(self.cfg.compliance_strategy),
            "profile": self.cfg.profile,
            "seeds": [self.cfg.seed + k for k in range(self.seeds)],
            "env_steps": step,
            "eval_episodes_per_seed": self.cfg.num_eval_envs,
            "eval_seed": self.cfg.seed + EVAL_SEED_OFFSET,
            "final_eval": per_seed,
            "final_eval_over_seeds": across,
            **provenance(),
        }
        # strict JSON: a statistic without a value (no successful episode) is null, not NaN
        fileio.write_text(self.out / "seeds.json", dumps(summary, indent=2) + "\n")
        try:
            from peghole_mjx.training.plots import plot_seed_bands

            plot_seed_bands([self.out], self.out / "curves.png")
        except Exception as exc:  # a plot must never lose a finished run
            print(f"warning: curves not plotted: {exc}", file=sys.stderr)
        return summary


def _seed_slice(tree, k: int):
    """Seed ``k``'s part of a tree stacked over seeds."""
    return jax.tree.map(lambda x: np.asarray(x[k]), tree)


def _fmt(v):
    return f"{v:.6g}" if isinstance(v, float) else v
