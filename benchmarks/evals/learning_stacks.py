"""The learning benchmark's other two stacks (``--stack seed`` and ``--stack sb3``): one
Stable-Baselines3 SAC run per task x seed, resumable, with the same evaluation schedule and the
same final evaluation as ours (:mod:`benchmarks.evals.learning` holds the statistics).

* ``seed``: the thesis's pipeline rebuilt (:mod:`benchmarks.baselines.seed_stack`): the
  PyBullet env of RectExtract or RectExtractHard (its default config: eq 4.4, the compliance
  strategy off; ``--set env.KEY=VALUE`` changes, checked by the sim) and SB3 SAC with
  :data:`~benchmarks.baselines.seed_stack.SAC_SETTINGS` (SB3's defaults for the rest).
* ``sb3``: SB3 SAC with its defaults (``MlpPolicy``) on our Gymnasium adapter
  (:class:`peghole_mjx.gym.PegHoleGymEnv`, time-outs as truncations), the env of our
  ``--profile``'s training config (its env overrides and training's env defaults, ``--set
  env.KEY=VALUE`` on top), engine ``mujoco`` (``--engine auto``) or the one named; the
  discount is the env's reward discount
  (:func:`peghole_mjx.training.config.reward_discount`).

Budget: ``--num-timesteps`` or the ``--profile``'s ``num_timesteps`` of the task (env steps).
Every ``--eval-every`` env steps (and at step 0) training stops for ``--eval-episodes``
deterministic episodes, fresh ones each time (evaluation ``k`` of seed ``s`` draws the
episodes of seed ``(k + 1) * 1_000_000 + s``); the training clock counts ``model.learn`` only
(env steps and updates, the adapter's compile in; evaluations and checkpoints out). After
each evaluation the model (``model.save``) and the filled part of its replay buffer
(``checkpoints/``), then ``state.json`` (steps, clock, the evaluations) are written, each
atomically; an interrupted run resumes from the last of them, a finished one is not trained
again. The final model (``final_model.zip``) and the scripted baseline then run the same
``--final-episodes`` fresh episodes (seed ``--final-seed``): on our env through
:func:`peghole_mjx.envs.rollout.rollout` (the SB3 actor's deterministic action, tanh of its
mean, run as a JAX function of its weights), on the PyBullet env one episode after another,
its baseline :func:`~benchmarks.baselines.pybullet_peghole.scripted_action` (the same straight
pull at 0.02 m/s). Per-episode mean and peak |F_z| are the env's (PyBullet: its F/T force
averaged over the substeps of each env step, as the MJX env's ``fz_N``).
"""

from __future__ import annotations

import functools
import importlib.metadata
import inspect
import json
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.baselines.pybullet_peghole import (
    PYBULLET_ENVS,
    check_config,
    env_config,
    make_gym_env,
    scripted_action,
)
from benchmarks.baselines.seed_stack import SAC_SETTINGS
from benchmarks.common import parse_overrides, versions_dict, write_rows
from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import dumps
from peghole_mjx.envs.config import apply_overrides
from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import run_provenance
from peghole_mjx.gym import PegHoleGymEnv
from peghole_mjx.sim.engines import engine_label, engine_overrides
from peghole_mjx.training.config import env_setting, load_train_config, reward_discount

#: the stacks of the learning benchmark; ``ours`` runs in :mod:`benchmarks.evals.learning`
STACKS = ("ours", "seed", "sb3")
#: what each stack is, as the result files name it
STACK_NAMES = {
    "ours": "peghole_mjx: Brax SAC (training's defaults) on the MJX envs",
    "seed": "seed stack: PyBullet env + Stable-Baselines3 SAC (the thesis's settings)",
    "sb3": "Stable-Baselines3 SAC (its defaults) on peghole_mjx's Gymnasium adapter",
}
#: the tasks each SB3 stack can run (None: every task with a training config)
STACK_TASKS = {"seed": PYBULLET_ENVS, "sb3": None}
#: evaluation k (0 at step 0) of seed s runs the episodes of seed (k + 1) * EVAL_SEED_STRIDE + s
EVAL_SEED_STRIDE = 1_000_000
#: SB3 SAC's settings recorded (and compared on resume); their defaults are read from SB3
SAC_KEYS = (
    "learning_rate",
    "buffer_size",
    "learning_starts",
    "batch_size",
    "tau",
    "gamma",
    "train_freq",
    "gradient_steps",
    "ent_coef",
    "target_update_interval",
    "target_entropy",
    "use_sde",
)
METRICS_FIELDS = (
    "step",
    "train_wall_s",
    "sps",
    "eval_s",
    "eval/episodes",
    "eval/success_rate",
    "eval/mean_fz_N",
    "eval/peak_fz_N",
    "eval/mean_return",
)
STATE = "state.json"
FINAL_MODEL = "final_model.zip"


def sb3():
    """``(torch, SAC)``: the ``bench`` extra, or one line saying how to install it."""
    try:
        import torch
        from stable_baselines3 import SAC
    except ImportError as exc:
        raise UserInputError(
            f"--stack seed and sb3 need Stable-Baselines3 and torch ({exc}): pip install "
            "torch==2.13.0 (CPU wheel) then pip install -e '.[bench]'"
        ) from None
    return torch, SAC


def stack_versions(stack: str) -> dict[str, str]:
    """The versions of what a stack adds to ours (SB3, torch, Gymnasium; PyBullet)."""
    if stack == "ours":
        return {}
    out = versions_dict(("sb3", "torch", *(("pybullet",) if stack == "seed" else ())))
    out.pop("python", None)
    try:
        out["gymnasium"] = importlib.metadata.version("gymnasium")
    except importlib.metadata.PackageNotFoundError:
        pass
    return out


def provenance(stack: str, command: list[str]) -> dict[str, Any]:
    """:func:`run_provenance` with the stack's own libraries among the versions."""
    prov = run_provenance(command)
    prov["versions"] = {**prov["versions"], **stack_versions(stack)}
    return prov


def sb3_defaults() -> dict[str, Any]:
    """SB3 SAC's own defaults of :data:`SAC_KEYS` (read from its signature)."""
    _, SAC = sb3()
    params = inspect.signature(SAC.__init__).parameters
    return {k: params[k].default for k in SAC_KEYS}


# ---------------------------------------------------------------------- configs
def check_args(args) -> None:
    """Refuse (one line, before any work) what ``--stack`` seed or sb3 cannot run."""
    stack = args.stack
    if stack == "ours":
        return
    allowed = STACK_TASKS[stack]
    if allowed is not None:
        bad = [t for t in args.tasks if t not in allowed]
        if bad:
            raise UserInputError(
                f"--stack {stack} runs {' and '.join(allowed)} only (the PyBullet seed stack "
                f"rebuilds those), not {', '.join(bad)}"
            )
    other = sorted(k for k in parse_overrides(args.sets) if not k.startswith("env."))
    if other:
        raise UserInputError(
            f"--set {', '.join(other)}: --stack {stack} takes env config changes only "
            "(env.KEY=VALUE); its SAC settings are fixed (module text)"
        )
    if stack == "seed" and args.engine != "auto":
        raise UserInputError(
            f"--engine {args.engine}: --stack seed runs the PyBullet env (no engine choice)"
        )
    sb3()  # the extra is there, before any run
    for task in args.tasks:  # each task's config (the env changes checked), before any run
        stack_config(stack, task, args.seeds[0], args)


def stack_config(stack: str, task: str, seed: int, args) -> dict[str, Any]:
    """The run's declared config (compared on resume): budget, evaluation schedule, env
    overrides, SAC settings, updates per env step."""
    over = {k[4:]: v for k, v in parse_overrides(args.sets).items() if k.startswith("env.")}
    budget = args.num_timesteps
    if budget is None:
        budget = load_train_config(task, args.profile).num_timesteps
    if stack == "seed":
        check_config(apply_overrides(env_config(task), over))  # one line if not honoured
        sac = {**sb3_defaults(), **SAC_SETTINGS}
        engine, kind = "pybullet", "thesis"
    else:
        # one world stepped at a time: MuJoCo C, unless another engine is named
        choice = "mujoco" if args.engine == "auto" else args.engine
        train = load_train_config(
            task,
            args.profile,
            {
                **{f"env.{k}": v for k, v in engine_overrides(choice).items()},
                **{f"env.{k}": v for k, v in over.items()},
            },
        )
        over = train.env_overrides
        gamma = reward_discount(task, over)
        sac = {**sb3_defaults(), "policy": "MlpPolicy", "gamma": gamma}
        engine = engine_label(over)
        kind = env_setting(task, over, "reward_config.kind")
    return {
        "stack": stack,
        "env": task,
        "seed": seed,
        "num_timesteps": int(budget),
        "eval_every": args.eval_every,
        "num_eval_envs": args.eval_episodes,
        "profile": args.profile,
        "env_overrides": over,
        "engine": engine,
        "reward_kind": kind,
        "sac": sac,
        "updates_per_env_step": sac["gradient_steps"] / sac["train_freq"],
        "torch_threads": 1,
    }


def full_env_config(cfg: dict[str, Any]) -> dict[str, Any]:
    """The env config the run trains in (recorded in ``run.json``, not compared)."""
    if cfg["stack"] == "seed":
        return apply_overrides(env_config(cfg["env"]), cfg["env_overrides"]).to_dict()
    return json.loads(built_env(cfg["env"], dumps(cfg["env_overrides"])).config.to_json())


@functools.lru_cache(maxsize=8)
def built_env(task: str, overrides_json: str):
    """Our env of ``task`` with the overrides (JSON), built once per process: the runs of a
    task share it, and with it the compiled rollouts of their evaluations."""
    return envs.load(task, config_overrides=json.loads(overrides_json))


# ---------------------------------------------------------------------- policies
def actor_params(model) -> list[tuple[jax.Array, jax.Array]]:
    """The (weight, bias) pairs of an SB3 SAC actor's MLP and its mean layer, for
    :func:`actor_action`; refuses an actor that is not Flatten -> (Linear, ReLU)* -> Linear."""
    torch, _ = sb3()
    actor = model.actor
    hidden = list(actor.latent_pi)
    ok = type(actor.features_extractor).__name__ == "FlattenExtractor" and all(
        isinstance(m, torch.nn.Linear if i % 2 == 0 else torch.nn.ReLU)
        for i, m in enumerate(hidden)
    )
    if not ok or len(hidden) % 2:
        raise UserInputError(f"the SB3 actor is not an MLP of Linear and ReLU layers: {actor}")
    layers = [*hidden[::2], actor.mu]
    return [
        (
            jnp.asarray(m.weight.detach().cpu().numpy().T),
            jnp.asarray(m.bias.detach().cpu().numpy()),
        )
        for m in layers
    ]


def actor_action(params, obs, rng):
    """The SB3 SAC actor's deterministic action, tanh of its mean (what ``predict(obs,
    deterministic=True)`` returns on a [-1, 1] action space), as a JAX function."""
    del rng
    x = obs
    for w, b in params[:-1]:
        x = jax.nn.relu(x @ w + b)
    w, b = params[-1]
    return jnp.tanh(x @ w + b)


def summary_of(episodes: dict[str, np.ndarray]) -> dict[str, Any]:
    """``episodes``, ``success_rate``, ``mean_fz_N``, ``peak_fz_N``, ``mean_return`` of
    per-episode arrays (the means over episodes, as ``RolloutSummary``)."""
    return {
        "episodes": len(episodes["success"]),
        "success_rate": float(np.mean(np.asarray(episodes["success"]) > 0)),
        "mean_fz_N": float(np.mean(episodes["mean_fz_N"])),
        "peak_fz_N": float(np.mean(episodes["peak_fz_N"])),
        "mean_return": float(np.mean(episodes["return"])),
    }


def pybullet_episodes(env, act, episodes: int, seed: int) -> dict[str, np.ndarray]:
    """``episodes`` episodes of the PyBullet gym env, one after another, starting from its
    generator seeded with ``seed`` (two policies run with one seed meet the same starts):
    success, the mean and peak |F_z| of each (F/T force averaged over an env step's substeps,
    hole frame) and its return."""
    rec: dict[str, list[float]] = {"success": [], "mean_fz_N": [], "peak_fz_N": [], "return": []}
    for i in range(episodes):
        obs, _ = env.reset(seed=seed if i == 0 else None)
        done, ret, fz, info = False, 0.0, [], {}
        while not done:
            obs, r, term, trunc, info = env.step(act(obs))
            ret += float(r)
            fz.append(abs(float(env.sim.info["wrench"][2])))
            done = term or trunc
        rec["success"].append(float(bool(info.get("is_success", False))))
        rec["mean_fz_N"].append(float(np.mean(fz)))
        rec["peak_fz_N"].append(float(np.max(fz)))
        rec["return"].append(ret)
    return {k: np.asarray(v) for k, v in rec.items()}


class Evaluator:
    """A stack's deterministic episodes of a model (and of the scripted baseline)."""

    def __init__(self, cfg: dict[str, Any]):
        self.cfg = cfg
        if cfg["stack"] == "seed":
            config = apply_overrides(env_config(cfg["env"]), cfg["env_overrides"])
            self.env = make_gym_env(cfg["env"], seed=0, config=config)
            self.baseline_action = scripted_action(config)
        else:
            self.env = built_env(cfg["env"], dumps(cfg["env_overrides"]))

    def policy(self, model, episodes: int, seed: int) -> dict[str, Any]:
        if self.cfg["stack"] == "seed":
            act = functools.partial(predict, model)
            return summary_of(pybullet_episodes(self.env, act, episodes, seed))
        return self._rollout(actor_action, episodes, seed, actor_params(model))

    def baseline(self, episodes: int, seed: int) -> dict[str, Any]:
        if self.cfg["stack"] == "seed":
            a = self.baseline_action
            return summary_of(pybullet_episodes(self.env, lambda obs: a, episodes, seed))
        return self._rollout(scripted_policy(self.env), episodes, seed, None)

    def _rollout(self, fn, episodes, seed, params) -> dict[str, Any]:
        res = rollout(
            self.env,
            fn,
            episodes,
            seed=seed,
            params=params,
            progress=False,
            gamma=self.cfg["sac"]["gamma"],
            refuse_all_nan=False,  # a NaN world is a failed episode, not an error
        )
        return summary_of(res.per_episode)

    def close(self) -> None:
        if self.cfg["stack"] == "seed":
            self.env.close()


def predict(model, obs):
    """The model's deterministic action for one observation."""
    return model.predict(obs, deterministic=True)[0]


# ---------------------------------------------------------------------- replay buffers
def buffer_arrays(buf) -> dict[str, np.ndarray]:
    """The filled rows of an SB3 replay buffer's arrays, with its ``pos`` and ``full``."""
    n = buf.buffer_size if buf.full else buf.pos
    out = {
        k: v[:n]
        for k, v in vars(buf).items()
        if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[0] == buf.buffer_size
    }
    return {**out, "pos": np.asarray(buf.pos), "full": np.asarray(buf.full)}


def save_buffer(buf, path: Path) -> None:
    """Write the filled part of ``buf`` (SB3's ``save_replay_buffer`` pickles all
    ``buffer_size`` rows: 1e6 by SB3's default, at every checkpoint), atomically."""
    arrays = buffer_arrays(buf)
    fileio.write_bytes_with(path, lambda f: np.savez(f, **arrays))


def load_buffer(buf, path: Path) -> None:
    """Fill ``buf`` (a new SB3 replay buffer of the same shapes) from :func:`save_buffer`."""
    with np.load(path, allow_pickle=False) as z:
        for k in z.files:
            if k in ("pos", "full"):
                continue
            a = z[k]
            getattr(buf, k)[: len(a)] = a
        buf.pos, buf.full = int(z["pos"]), bool(z["full"])


# ---------------------------------------------------------------------- runs
def make_model(cfg: dict[str, Any], env):
    """A new SB3 SAC of the run's settings on ``env`` (CPU, seeded)."""
    _, SAC = sb3()
    sac = dict(cfg["sac"])
    policy = sac.pop("policy")
    return SAC(policy, env, **sac, seed=cfg["seed"], device="cpu", verbose=0)


def train_env(cfg: dict[str, Any]):
    """The stack's training env (one world)."""
    if cfg["stack"] == "seed":
        config = apply_overrides(env_config(cfg["env"]), cfg["env_overrides"])
        return make_gym_env(cfg["env"], seed=cfg["seed"], config=config)
    return PegHoleGymEnv(cfg["env"], config_overrides=cfg["env_overrides"])


def eval_seed(seed: int, k: int) -> int:
    """The episode seed of evaluation ``k`` of a run of ``seed`` (module text)."""
    return (k + 1) * EVAL_SEED_STRIDE + seed


def read_state(run_dir: Path) -> dict[str, Any] | None:
    path = run_dir / STATE
    return json.loads(path.read_text()) if path.exists() else None


def write_checkpoint(model, run_dir: Path, state: dict[str, Any]) -> None:
    """Model and replay buffer of this step, then ``state.json`` naming them (each file
    atomic; the older checkpoint's files are removed after), then ``metrics.csv``."""
    ck = run_dir / "checkpoints"
    ck.mkdir(parents=True, exist_ok=True)
    step = state["env_steps"]
    model_file, buffer_file = ck / f"model_{step:09d}.zip", ck / f"buffer_{step:09d}.npz"
    fileio.write_bytes_with(model_file, model.save)
    save_buffer(model.replay_buffer, buffer_file)
    state["checkpoint"] = [model_file.name, buffer_file.name]
    fileio.write_text(run_dir / STATE, dumps(state, indent=2) + "\n")
    for f in ck.iterdir():
        if f.name not in state["checkpoint"]:
            f.unlink()
    write_rows(run_dir / "metrics.csv", state["evals"], METRICS_FIELDS)


def evaluate_into(model, evaluator: Evaluator, state: dict[str, Any], cfg, wall0: float):
    """Run evaluation ``len(state['evals'])`` of the model and append its row."""
    t = time.perf_counter()
    k = len(state["evals"])
    res = evaluator.policy(model, cfg["num_eval_envs"], eval_seed(cfg["seed"], k))
    clock = state["train_clock_s"]
    row = {
        "step": int(model.num_timesteps),
        "train_wall_s": round(clock, 3),
        "sps": round(model.num_timesteps / clock, 2) if clock > 0 else None,
        "eval_s": round(time.perf_counter() - t, 2),
        "eval/episodes": res["episodes"],
        "eval/success_rate": res["success_rate"],
        "eval/mean_fz_N": res["mean_fz_N"],
        "eval/peak_fz_N": res["peak_fz_N"],
        "eval/mean_return": res["mean_return"],
    }
    state["evals"].append(row)
    print(
        f"learning [{cfg['stack']} {cfg['env']} seed {cfg['seed']}]: step {row['step']}, "
        f"success {row['eval/success_rate']:.3f}, training clock {clock:.1f} s "
        f"(wall {time.perf_counter() - wall0:.0f} s)",
        file=sys.stderr,
        flush=True,
    )


def train(cfg: dict[str, Any], run_dir: Path, state: dict[str, Any] | None) -> None:
    """Train the run to its budget from ``state`` (None: a new run), evaluating and
    checkpointing at each evaluation boundary; the last model becomes ``final_model.zip``."""
    torch, SAC = sb3()
    torch.set_num_threads(cfg["torch_threads"])
    wall0 = time.perf_counter()
    env = train_env(cfg)
    evaluator = Evaluator(cfg)
    try:
        if state is None:
            model = make_model(cfg, env)
            state = {"env_steps": 0, "train_clock_s": 0.0, "evals": [], "finished": False}
            evaluate_into(model, evaluator, state, cfg, wall0)
            write_checkpoint(model, run_dir, state)
        else:
            model_file, buffer_file = (run_dir / "checkpoints" / n for n in state["checkpoint"])
            model = SAC.load(model_file, env=env, device="cpu")
            load_buffer(model.replay_buffer, buffer_file)
            # the episodes after a resume: seeded by the run's seed and step
            model.set_random_seed(cfg["seed"] + 7919 * model.num_timesteps)
        budget, every = cfg["num_timesteps"], cfg["eval_every"]
        while model.num_timesteps < budget:
            target = min(budget, (model.num_timesteps // every + 1) * every)
            t = time.perf_counter()
            model.learn(
                total_timesteps=target - model.num_timesteps,
                reset_num_timesteps=False,
                progress_bar=False,
            )
            state["train_clock_s"] += time.perf_counter() - t
            state["env_steps"] = int(model.num_timesteps)
            evaluate_into(model, evaluator, state, cfg, wall0)
            write_checkpoint(model, run_dir, state)
        fileio.write_bytes_with(run_dir / FINAL_MODEL, model.save)
        state["finished"] = True
        state["train_env_steps_per_s"] = (
            state["env_steps"] / state["train_clock_s"] if state["train_clock_s"] > 0 else None
        )
        fileio.write_text(run_dir / STATE, dumps(state, indent=2) + "\n")
        for f in (run_dir / "checkpoints").iterdir():  # the replay buffers are not needed now
            f.unlink()
    finally:
        env.close()
        evaluator.close()


def final_eval(cfg: dict[str, Any], run_dir: Path, episodes: int, seed: int) -> dict[str, Any]:
    """The final model and the scripted baseline on the same ``episodes`` fresh episodes."""
    torch, SAC = sb3()
    torch.set_num_threads(cfg["torch_threads"])
    model = SAC.load(run_dir / FINAL_MODEL, device="cpu")
    evaluator = Evaluator(cfg)
    try:
        pol = evaluator.policy(model, episodes, seed)
        base = evaluator.baseline(episodes, seed)
    finally:
        evaluator.close()
    return {
        "policy": pol,
        "baseline": base,
        "baseline_rule": (
            "the scripted straight pull at 0.02 m/s with the fixed stiffness, on the same "
            + (
                "episodes (PyBullet env, one after another, its generator seeded with seed)"
                if cfg["stack"] == "seed"
                else "episodes (peghole_mjx.envs.rollout.scripted_policy, rollout of seed)"
            )
        ),
        "episodes": episodes,
        "seed": seed,
        "env": cfg["env"],
        "engine": cfg["engine"],
        "policy_path": str(run_dir / FINAL_MODEL),
    }


def run_seed(stack: str, task: str, seed: int, args, out: Path):
    """Train (or resume, or skip when finished) one seed of ``stack`` and evaluate its final
    model: ``(config, run folder, final evaluation)``."""
    cfg = stack_config(stack, task, seed, args)
    run_dir = out / f"runs_{stack}" / task / f"seed_{seed}"
    record = run_dir / "run.json"
    if record.exists():
        recorded = json.loads(record.read_text())["config"]
        if recorded != json.loads(dumps(cfg)):
            raise UserInputError(
                f"{run_dir} holds a run of another config: rerun with the settings it was "
                "started with, or another --out"
            )
    else:
        run_dir.mkdir(parents=True, exist_ok=True)
        meta = {
            "stack": STACK_NAMES[stack],
            "config": cfg,
            "env_config": full_env_config(cfg),
            **provenance(stack, args.command),
        }
        fileio.write_text(record, dumps(meta, indent=2) + "\n")
    state = read_state(run_dir)
    if state is None or not state.get("finished"):
        train(cfg, run_dir, state)
    final_file = run_dir / f"final_eval_{args.final_episodes}_seed{args.final_seed}.json"
    if final_file.exists():
        final = json.loads(final_file.read_text())
    else:
        final = final_eval(cfg, run_dir, args.final_episodes, args.final_seed)
        fileio.write_text(final_file, dumps(final, indent=2) + "\n")
    return cfg, run_dir, final


__all__ = [
    "EVAL_SEED_STRIDE",
    "STACKS",
    "STACK_NAMES",
    "actor_action",
    "actor_params",
    "check_args",
    "load_buffer",
    "provenance",
    "run_seed",
    "save_buffer",
    "stack_config",
]
