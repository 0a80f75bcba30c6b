"""Training hyperparameters: :class:`TrainConfig` owns every default (the values shared by all
envs and profiles; :data:`TRAINING_ENV_DEFAULTS` the env config entries training sets, the
compliance strategy); one JSON file per env in ``train/configs/``
(kept apart from the env configs in :mod:`peghole_mjx.envs`) holds three profiles of the
sizes that differ (steps, worlds, batch, replay) and any env-specific change.

Keys, and the choices made where Brax's defaults differ from the thesis (stack_notes.md):

* ``num_timesteps``: env steps in the whole run; ``num_envs``: worlds stepped in parallel
  (divisible by the device count); ``num_eval_envs``: episodes per evaluation, each run to
  its end; ``eval_every``: env steps between evaluations (a checkpoint is written at each).
* ``batch_size``: transitions per gradient step; ``grad_updates_per_step``: gradient steps per
  batched env step (update-to-data ratio = this / num_envs).
* ``max_replay_size``: replay rows. The thesis used 100 000 with one env; we scale it with the
  worlds. Always set: Brax's default (num_timesteps rows) can exhaust GPU memory.
  ``min_replay_size``: rows collected by the initial policy before learning.
* ``learning_rate``: Adam, actor and critics: 3e-4 (SB3's default, which the thesis used;
  Brax's default is 1e-4).
* ``discounting``: gamma. Under the outcome reward (training's default) its own discount,
  ``env.reward_config.discount`` = 0.9995 (:func:`load_train_config` takes it from there; any
  other value is refused: the reward's ordering of outcomes holds at that discount,
  :mod:`peghole_mjx.envs.reward`); under the thesis's reward 0.99 as in the thesis. Brax's
  default 0.9 would shorten the horizon to about 10 steps (0.2 s), far shorter than an
  extraction.
* ``lr_schedule``: ``constant`` (the default) or ``linear``: the actor's and critics' learning
  rates fall linearly from ``learning_rate`` to zero over the run's gradient updates
  (``num_timesteps / num_envs * grad_updates_per_step``; a run extended on resume follows the
  longer line from where it stands). The temperature's rate stays 3e-4.
* ``entropy_backup``: true (Brax's SAC, Haarnoja et al. 2018): the critics' target carries the
  next state's entropy bonus ``-alpha log pi``; false: the target is the task reward alone
  (the entropy still shapes the actor and the temperature), as jaxrl's ``backup_entropy``.
  Why it matters here: under the ``outcome`` reward a step costs 0.05-0.1 while ``alpha H``
  at the target entropy is ``-alpha dim(A) / 2`` per step, as large at alpha 0.02 and 10-30x
  larger at the 0.2-0.6 the learned temperature reached on DualExtractHard
  (docs/research/learner_settings.md), so a backed-up entropy adds a time cost that outweighs
  the reward's force cost and changes the ranking of outcomes the reward was built for.
* ``q_target_clip``: false (Brax's target); true: the critics' target is clipped to the
  ``outcome`` reward's bounds on a discounted return, ``[-(2 P + w_progress), w_progress]``
  (:func:`peghole_mjx.envs.reward.return_bounds`, :mod:`peghole_mjx.training.losses`), refused
  under the thesis's reward. Why: at one update per env step the critics' estimates on the Hard
  tasks grew to 40-450 where no return exceeds 30 (docs/research/learner_settings.md).
* ``tau``: target-critic Polyak rate 0.005; ``reward_scaling``: 1 (the eq 4.4 terms are
  already of order one).
* ``alpha``: entropy temperature, ``"auto"`` (learned with Brax's target entropy -dim(A)/2)
  or a fixed number; ``alpha=0.2`` reproduces the thesis's fixed value. ``alpha_init``: the
  starting value when learned, 0.2 (Brax starts at 1, which swamps the per-step rewards).
* ``hidden_layer_sizes``: MLP widths of actor and critics, (256, 256) as SB3's MlpPolicy;
  ``normalize_observations``: running mean/std normaliser, on.
* ``critic``: the critics' network, ``mlp`` (Brax's, the default), ``layernorm`` or ``simba``
  (:mod:`peghole_mjx.training.critics`; the actor and the losses are the same for all).
* ``actor_delay_updates``: gradient updates in which only the critics learn (the actor and
  the temperature held), 0: a critic burn-in, as residual RL uses (Silver et al. 2018) so
  that a residual policy (env ``action.residual``), which starts as the scripted pull, is
  not moved by an untrained critic. The ``cpu`` and ``full`` profiles of the four base tasks
  and MeshExtract set 5000 (the residual protocol's setting); ``quick`` keeps 0.
* ``steps_per_call``: batched env steps per jitted call (progress-bar granularity), 25;
  ``seed``: 0; ``env_overrides``: flat env-config overrides (e.g. ``episode_length``).
* The compliance strategy is an env config entry (``compliance_strategy``,
  :mod:`peghole_mjx.envs.config`), set like any other through ``env_overrides``; training
  turns it on unless told otherwise (:data:`TRAINING_ENV_DEFAULTS`: RL + CS, thesis Sec 4.2:
  the action also sets k_xy and K_theta, docs/guide/training.md), while the env config's own default
  (off) applies to envs built outside training. ``peghole train --compliance-strategy on|off``
  and :func:`load_train_config`'s ``compliance_strategy`` are shorthands for
  ``env.compliance_strategy``. A ``run.json`` or ``policy.json`` that carries a
  ``compliance_strategy`` training key (an older record) is read as the env override
  (:func:`legacy_config`, the one place; the decision and its date:
  docs/research/train_profiles.md).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import optax

from peghole_mjx import envs
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import MAX_HIDDEN_LAYERS, RANGES, check, dumps, load_json_object
from peghole_mjx.files import fileio
from peghole_mjx.training.critics import CRITICS

_PKG_CONFIGS = Path(__file__).resolve().parents[1] / "_train_configs"
_REPO_CONFIGS = Path(__file__).resolve().parents[2] / "train" / "configs"
CONFIG_DIR = _PKG_CONFIGS if _PKG_CONFIGS.is_dir() else _REPO_CONFIGS
PROFILES = ("full", "cpu", "quick")
#: the learning-rate schedules of the actor and critics (``TrainConfig.lr_schedule``)
LR_SCHEDULES = ("constant", "linear")
#: env config entries that training sets unless a run says otherwise (the env config's own
#: defaults apply to envs built outside training): the compliance strategy on, RL + CS, and
#: the thesis's reward, eq (4.4), the one that learns within the ``cpu`` budgets; the
#: ``outcome`` reward (envs/reward.py, ``--set env.reward_config.kind=outcome``) ranks
#: outcomes as a user does but did not learn RectExtract (docs/research/learning.md)
#: the env entries training sets unless told otherwise: RL + compliance strategy (thesis Sec
#: 4.2), the outcome reward (its optimum a clean extraction; envs/reward.py) and residual
#: actions (the scripted pull plus the policy's correction). Decided 2026-12-06 from the
#: residual learning benchmark (benchmarks/results/evals/learning_residual_cpu-2core,
#: docs/research/residual.md: final policies of RectExtract and DualExtract 5 of 5 seeds at
#: 1.00 success, no collapse; the thesis's reward and plain actions collapsed or missed the line
#: on the same tasks), the setting the four published policies were trained with. The
#: thesis's eq (4.4) stays for the studies of its claims (C4, R3), which set
#: ``env.reward_config.kind=thesis`` and ``env.action.residual=false`` themselves.
TRAINING_ENV_DEFAULTS: dict[str, Any] = {
    "compliance_strategy": True,
    "reward_config.kind": "outcome",
    "action.residual": True,
}


@dataclass
class TrainConfig:
    """Every hyperparameter of a SAC run (see the module table)."""

    env: str
    num_timesteps: int
    num_envs: int
    num_eval_envs: int
    eval_every: int
    batch_size: int
    grad_updates_per_step: int
    max_replay_size: int
    min_replay_size: int
    learning_rate: float = 3e-4
    lr_schedule: str = "constant"
    entropy_backup: bool = True
    q_target_clip: bool = False
    discounting: float = 0.99
    tau: float = 0.005
    reward_scaling: float = 1.0
    alpha: str | float = "auto"
    alpha_init: float = 0.2
    hidden_layer_sizes: list[int] = field(default_factory=lambda: [256, 256])
    normalize_observations: bool = True
    critic: str = "mlp"
    actor_delay_updates: int = 0
    steps_per_call: int = 25
    seed: int = 0
    env_overrides: dict[str, Any] = field(default_factory=dict)
    profile: str = "full"

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """The validated config of a mapping (``run.json``'s ``config``, ``policy.json``'s
        ``train_config``; older records' :data:`LEGACY_KEYS` read as what they became)."""
        names = {f.name for f in fields(cls)} | set(LEGACY_KEYS)
        if not isinstance(d, dict):
            raise UserInputError(f"training config must be a mapping, got {type(d).__name__}")
        unknown = sorted(str(k) for k in set(d) - names)
        if unknown:
            known = sorted(names - set(LEGACY_KEYS))
            raise UserInputError(f"unknown training config keys {unknown}; known: {known}")
        required = {
            f.name for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING
        }
        missing = sorted(required - set(d))
        if missing:
            raise UserInputError(f"training config lacks the keys {missing}")
        cfg = cls(**legacy_config(d))
        cfg.validate()
        return cfg

    def validate(self) -> None:
        """Type, finiteness and range of every field (``peghole_mjx.core.validation.RANGES``), then
        the relations between them. Whole-number floats (``1e6``) become integers."""

        def need(cond: bool, what: str) -> None:
            if not cond:
                raise UserInputError(f"training config: {what}")

        for f in fields(self):
            if f.name in RANGES and f.name != "alpha":
                setattr(self, f.name, check(f.name, getattr(self, f.name), _label(f.name)))
        need(
            self.alpha == "auto"
            or (not isinstance(self.alpha, str) and RANGES["alpha"].problem(self.alpha) is None),
            f"alpha must be 'auto' or a positive finite number, got {self.alpha!r}",
        )
        if self.alpha != "auto":
            self.alpha = float(self.alpha)
        sizes = self.hidden_layer_sizes
        need(
            isinstance(sizes, list | tuple) and 1 <= len(sizes) <= MAX_HIDDEN_LAYERS,
            f"hidden_layer_sizes must be a list of 1 to {MAX_HIDDEN_LAYERS} layer widths, "
            f"got {sizes!r}",
        )
        self.hidden_layer_sizes = [
            check("hidden_layer_sizes", w, _label("hidden_layer_sizes"), kind="hidden_layer_size")
            for w in sizes
        ]
        need(
            isinstance(self.normalize_observations, bool),
            f"normalize_observations must be true or false, got {self.normalize_observations!r}",
        )
        need(
            self.lr_schedule in LR_SCHEDULES,
            f"lr_schedule must be one of {list(LR_SCHEDULES)}, got {self.lr_schedule!r}",
        )
        for flag in ("entropy_backup", "q_target_clip"):
            value = getattr(self, flag)
            need(isinstance(value, bool), f"{flag} must be true or false, got {value!r}")
        need(
            self.critic in CRITICS,
            f"critic must be one of {list(CRITICS)}, got {self.critic!r}",
        )
        need(isinstance(self.env, str), f"env must be a name, got {self.env!r}")
        need(self.profile in PROFILES, f"profile must be one of {list(PROFILES)}")
        need(
            isinstance(self.env_overrides, dict),
            f"env_overrides must be a mapping, got {self.env_overrides!r}",
        )
        chunk = self.num_envs * self.steps_per_call
        need(
            self.eval_every >= chunk,
            f"eval_every ({self.eval_every}) must be >= num_envs x steps_per_call ({chunk})",
        )
        need(
            self.min_replay_size < self.num_timesteps,
            f"min_replay_size ({self.min_replay_size}) must be < num_timesteps "
            f"({self.num_timesteps}): no training would happen",
        )
        need(
            self.max_replay_size >= self.min_replay_size,
            "max_replay_size must be >= min_replay_size",
        )
        need(
            self.batch_size <= self.max_replay_size,
            f"batch_size ({self.batch_size}) must be <= max_replay_size ({self.max_replay_size})",
        )


def learning_rate(cfg: TrainConfig) -> float | Callable[[Any], Any]:
    """The actor's and critics' learning rate: ``cfg.learning_rate`` (``lr_schedule``
    ``constant``), or an optax schedule falling linearly to zero at the run's last gradient
    update (``linear``)."""
    if cfg.lr_schedule == "constant":
        return cfg.learning_rate
    updates = max(1, cfg.num_timesteps // cfg.num_envs * cfg.grad_updates_per_step)
    return optax.linear_schedule(cfg.learning_rate, 0.0, updates)


def _label(name: str) -> str:
    return f"training config: {name}"


#: training config keys of older records, each read as what it became: ``compliance_strategy``
#: (a field in records written before 2026-12-02) is the env config entry of the same name
LEGACY_KEYS = ("compliance_strategy",)


def legacy_config(config: dict[str, Any]) -> dict[str, Any]:
    """``config`` (a training config as ``run.json`` or ``policy.json`` records it) with the
    :data:`LEGACY_KEYS` moved where they live now: ``compliance_strategy`` into
    ``env_overrides``. A record that sets it both ways differently is refused in one line.
    The one place that reads them; a copy, ``config`` is left as it is."""
    if "compliance_strategy" not in config:
        return config
    config = dict(config)
    cs = config.pop("compliance_strategy")
    if not isinstance(cs, bool):
        raise UserInputError(
            f"training config: compliance_strategy must be true or false, got {cs!r}"
        )
    over = config.get("env_overrides", {})
    if isinstance(over, dict):
        in_env = over.get("compliance_strategy", cs)
        if in_env != cs:
            raise UserInputError(
                f"compliance_strategy is {cs} but env_overrides sets {in_env!r}: set one of them"
            )
        config["env_overrides"] = {**over, "compliance_strategy": cs}
    return config


def env_setting(env: str, env_overrides: dict[str, Any], key: str) -> Any:
    """The env config entry ``key`` (dotted) of env ``env`` built with ``env_overrides``: the
    override, else the env config's default."""
    if key in env_overrides:
        return env_overrides[key]
    node = envs.get_default_config(env)
    for part in key.split("."):
        node = node[part]
    return node


#: config keys that ``--set`` cannot change: each is chosen another way (the env and the
#: profile pick the JSON file and its sizes; env config entries are set one by one)
CHOSEN_BY_FLAG = {
    "env": "the env is chosen with --env NAME (its config file gives the other defaults)",
    "profile": "the profile is chosen with --profile full|cpu|quick (or --quick)",
    "env_overrides": "set env config entries one by one with --set env.KEY=VALUE",
}


def load_train_config(
    env: str,
    profile: str = "full",
    overrides: dict[str, Any] | None = None,
    compliance_strategy: bool | None = None,
) -> TrainConfig:
    """The hyperparameters of ``env`` for ``profile``: :class:`TrainConfig`'s defaults, the
    env's JSON file (``common``, if any, then the profile), then flat ``overrides``
    (``env.KEY`` for the env config, on :data:`TRAINING_ENV_DEFAULTS` and the file's env
    overrides). ``compliance_strategy`` (not None) is a shorthand for
    ``env.compliance_strategy``; the two set differently are refused."""
    if profile not in PROFILES:
        raise UserInputError(f"unknown profile {profile!r}; choose one of {list(PROFILES)}")
    path = CONFIG_DIR / f"{env}.json"
    if not path.exists():
        known = sorted(p.stem for p in CONFIG_DIR.glob("*.json"))
        raise UserInputError(f"no training config for env {env!r} in {CONFIG_DIR}; have {known}")
    raw = json.loads(path.read_text())
    d = dict(raw.get("common", {}))
    prof = dict(raw["profiles"][profile])
    env_over = {
        **TRAINING_ENV_DEFAULTS,
        **d.pop("env_overrides", {}),
        **prof.pop("env_overrides", {}),
    }
    d.update(prof)
    given: dict[str, Any] = {}
    for key, value in (overrides or {}).items():
        if key in CHOSEN_BY_FLAG:  # would be silently replaced below: refused instead
            raise UserInputError(f"--set {key}={value}: {CHOSEN_BY_FLAG[key]}")
        if key.startswith("env."):
            given[key[4:]] = value
        else:
            d[key] = value
    if compliance_strategy is not None:
        cs = given.setdefault("compliance_strategy", bool(compliance_strategy))
        if cs != bool(compliance_strategy):
            raise UserInputError(
                f"compliance_strategy={compliance_strategy} and env.compliance_strategy={cs} "
                "disagree: set one of them"
            )
    d.update(env=env, env_overrides={**env_over, **given}, profile=profile)
    # the outcome reward's own discount (one source: its env config entry)
    d.setdefault("discounting", reward_discount(env, d["env_overrides"]))
    kind = env_setting(env, d["env_overrides"], "reward_config.kind")
    gamma = env_setting(env, d["env_overrides"], "reward_config.discount")
    check_discount(kind, gamma, d["discounting"])
    if isinstance(d.get("hidden_layer_sizes"), tuple):
        d["hidden_layer_sizes"] = list(d["hidden_layer_sizes"])
    return TrainConfig.from_dict(d)


def check_discount(kind: str, reward_gamma: float, discounting: Any) -> None:
    """Refuse a learner discount other than the outcome reward's own (its shaping and its
    ordering of outcomes hold at that discount only: :mod:`peghole_mjx.envs.reward`)."""
    if kind != "outcome":
        return
    if not isinstance(discounting, int | float) or abs(discounting - reward_gamma) > 1e-12:
        raise UserInputError(
            f"training config discounting={discounting!r} differs from the outcome reward's "
            f"discount {reward_gamma:g} (env.reward_config.discount): set that one instead"
        )


def reward_discount(env: str, env_overrides: dict[str, Any]) -> float:
    """The learner's discount for ``env`` with ``env_overrides``: the outcome reward's own
    (``reward_config.discount``: its shaping and ordering hold there), else the
    :class:`TrainConfig` default (0.99, the thesis's)."""
    if env_setting(env, env_overrides, "reward_config.kind") == "outcome":
        return float(env_setting(env, env_overrides, "reward_config.discount"))
    return float(default("discounting"))


def default(name: str) -> Any:
    """The default of :class:`TrainConfig` field ``name`` (what the CLI shows and uses)."""
    f = {f.name: f for f in fields(TrainConfig)}[name]
    return f.default_factory() if f.default is MISSING else f.default


#: the largest number of seeds a ``--seeds`` run records (``run.json`` key ``seeds``)
MAX_SEEDS = 4096
#: a training run's record in its folder
RUN_RECORD = "run.json"


def write_run_record(out: str | Path, meta: dict[str, Any]) -> Path:
    """Write ``run.json`` of the run in ``out`` (strict JSON, atomically): the one writer of
    run records (:func:`read_run_record` reads them back)."""
    return fileio.write_text(Path(out) / RUN_RECORD, dumps(meta, indent=2) + "\n")


def read_run_record(out: str | Path, what: str = "--resume", full: bool = True):
    """``(meta, cfg)``: a training run's ``run.json``, schema-checked, and its config.

    Strict JSON (no bare NaN, nesting at most ``validation.MAX_JSON_DEPTH``), an object with a
    ``config`` object; ``seeds`` (multi-seed runs) a whole number >= 1; ``resumed_with`` a
    list of objects. ``full``: the config is a complete :class:`TrainConfig` (``cfg``); else
    only ``env`` (a name) and ``env_overrides`` (a mapping) are checked and ``cfg`` is None
    (for reading older or partial records, e.g. to label curves). A missing file is a
    :class:`UserInputError`, a damaged one a :class:`CorruptFileError`, in one line naming it.
    """
    path = Path(out) / RUN_RECORD
    if not path.is_file():
        raise UserInputError(f"{what}: {path} not found (not a training run directory)")

    def bad(why: str) -> CorruptFileError:
        return CorruptFileError(f"{path} is not a readable run record ({why})")

    meta = load_json_object(path, bad)
    config = meta.get("config")
    if not isinstance(config, dict):
        raise bad(f"'config' must be an object, got {type(config).__name__}")
    seeds = meta.get("seeds", 1)
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= MAX_SEEDS:
        raise bad(f"'seeds' must be a whole number in [1, {MAX_SEEDS}], got {seeds!r}")
    resumed = meta.get("resumed_with", [])
    if not isinstance(resumed, list) or not all(isinstance(r, dict) for r in resumed):
        raise bad(f"'resumed_with' must be a list of objects, got {resumed!r:.60}")
    if not full:
        try:
            meta = {**meta, "config": legacy_config(config)}
        except UserInputError as exc:
            raise bad(str(exc)) from None
        config = meta["config"]
        if not isinstance(config.get("env"), str):
            raise bad(f"config.env must be an env name, got {config.get('env')!r:.60}")
        if not isinstance(config.get("env_overrides", {}), dict):
            raise bad("config.env_overrides must be an object")
        return meta, None
    try:
        cfg = TrainConfig.from_dict(config)
    except UserInputError as exc:
        raise bad(str(exc)) from None
    except TypeError as exc:  # a field of the wrong kind that validate() cannot name
        raise bad(f"training config: {exc}") from None
    return meta, cfg
