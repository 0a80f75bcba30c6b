"""Gymnasium adapters of the extraction envs: NumPy in, NumPy out.

The physics engine is the env config's default, ``auto`` (MuJoCo C without a GPU; on a CUDA GPU
MJX-Warp with warp-lang, else MJX-JAX: :func:`peghole_mjx.sim.engines.default_engine`);
``config_overrides={"engine": ...}`` names another.

* :class:`PegHoleVectorEnv`: a ``gymnasium.vector.VectorEnv`` over N worlds of one env
  (``peghole_mjx.envs.load(name)``), stepped together by one jitted, vmapped call;
* :class:`PegHoleGymEnv`: one world as a ``gymnasium.Env`` (passes
  ``gymnasium.utils.env_checker.check_env``), for single-env libraries such as
  Stable-Baselines3.

Spaces. Actions: ``Box(-1, 1, (env.action_size,), float32)``, decoded by the env (6-D: lateral
and axial motion and feed-forward force increments; more with the compliance strategy, see
:class:`peghole_mjx.envs.PegHoleEnv`). Observations: ``Box(-inf, inf, (env.observation_size,),
float32)`` (normalised forces and poses, unbounded in principle).

Episode ends. ``terminated``: success (tip above the mouth), a jam (lateral force at the limit
for ``jam_time_s``), a non-finite world, or (MuJoCo Warp) a contact buffer overflow.
``truncated``: the time limit ``episode_length`` reached without one of those. The rewards are
the native env's, eq (4.4) unchanged: the time-limit step's reward includes the failure term
``r_failure``, since the thesis counts a time-out as a failed extraction.

Worlds are sized before anything is allocated: ``num_envs`` worlds whose states do not fit
the available memory are refused in one line (:func:`peghole_mjx.core.memory.check_worlds`).

Actions are checked before they reach the env: real numbers (an integer or float dtype;
complex, boolean, text or object arrays are refused, not cast) of the action space's shape, or
:class:`~peghole_mjx.core.errors.UserInputError`. Values outside [-1, 1] are clipped by the env;
a NaN action ends its episode like a non-finite world (``info["nan"]``).

After an episode ends (single env): ``step`` raises :class:`~peghole_mjx.core.errors.UserInputError`
until ``reset`` is called; the ended world is never simulated further, and its terminal
reward is paid once.

Autoreset (vector env): ``AutoresetMode.NEXT_STEP``, Gymnasium's default. After a world's
episode ends, the next ``step`` ignores that world's action and returns the first observation
of a new episode for it, with reward 0 and ``terminated = truncated = False``. Every new
episode is fully re-randomised (a fresh reset, never a cached first state).

Randomness. ``reset(seed=s)`` seeds the adapter's NumPy generator (``self.np_random``), and
every JAX reset key is drawn from it: the same seed and actions give the same trajectory.

Compilation. Each adapter jits the env's ``reset`` and ``step`` once (vmapped over the worlds
for the vector env); later calls reuse the compiled functions.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx import envs
from peghole_mjx.core import memory
from peghole_mjx.core._optional import optional_import
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import check
from peghole_mjx.sim.engines import batch_reset, select_worlds

gymnasium = optional_import("gymnasium", "the Gymnasium adapter (peghole_mjx.gym)")
from gymnasium import spaces  # noqa: E402
from gymnasium.vector import AutoresetMode, VectorEnv  # noqa: E402
from gymnasium.vector.utils import batch_space  # noqa: E402

#: ``metrics`` of the native env's State that the adapters return in ``info`` (per world)
INFO_KEYS = (
    "success",
    "jammed",
    "nan",
    "extraction_time_s",
    "depth_mm",
    "fz_N",
    "fxy_N",
    "mean_fz_N",
    "peak_fz_N",
)


def _spaces(env: envs.PegHoleEnv) -> tuple[spaces.Box, spaces.Box]:
    obs = spaces.Box(-np.inf, np.inf, (env.observation_size,), np.float32)
    act = spaces.Box(-1.0, 1.0, (env.action_size,), np.float32)
    return obs, act


def _end_flags(env: envs.PegHoleEnv, state: envs.State) -> tuple[jax.Array, jax.Array]:
    """(terminated, truncated) of a State (unbatched): see the module docstring."""
    m = state.metrics
    done = state.done > 0
    ended_early = (m["success"] + m["jammed"] + m["nan"] + m["overflow"]) > 0
    timeout = state.info["step"] >= env.config.episode_length
    truncated = done & timeout & ~ended_early
    return done & ~truncated, truncated


def _checked_action(action, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``action`` as float32 after checking its dtype and shape (see the module docstring)."""
    try:
        a = np.asarray(action)
    except ValueError as exc:  # ragged nested sequences
        raise UserInputError(f"{what} must be an array of shape {shape}: {exc}") from None
    if a.dtype.kind not in "fiu":
        raise UserInputError(
            f"{what} must hold real numbers (float32 in [-1, 1]), got dtype {a.dtype}"
        )
    if a.shape != shape:
        raise UserInputError(f"{what} must have shape {shape}, got {a.shape}")
    return a.astype(np.float32)


def _np_info(state: envs.State) -> dict[str, np.ndarray]:
    return {k: np.array(state.metrics[k], dtype=np.float32) for k in INFO_KEYS}


class PegHoleVectorEnv(VectorEnv):
    """N MJX worlds of one peg extraction env as a Gymnasium vector env (NumPy arrays).

    ``name``: a registered env (``peghole_mjx.envs.ALL_ENVS``); ``config_overrides``: flat
    overrides of its config (e.g. ``{"episode_length": 100, "representation": "box"}``).
    Autoreset, spaces and episode ends: see the module docstring.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}  # noqa: RUF012

    def __init__(
        self, name: str = "RectExtract", num_envs: int = 1, config_overrides: dict | None = None
    ):
        num_envs = check("num_envs", num_envs)  # an integer >= 1 (true, 2.7 refused)
        self.env = envs.load(name, config_overrides=config_overrides)
        # before anything is allocated or compiled: the worlds must fit in memory
        memory.check_worlds(
            self.env, num_envs, f"PegHoleVectorEnv(num_envs={num_envs})", "use fewer worlds"
        )
        self.num_envs = num_envs
        self.single_observation_space, self.single_action_space = _spaces(self.env)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        env = self.env

        def step(state, action):
            new = jax.vmap(env.step)(state, action)
            terminated, truncated = jax.vmap(lambda s: _end_flags(env, s))(new)
            return new, terminated, truncated

        self._reset_fn = jax.jit(functools.partial(batch_reset, env))
        self._step_fn = jax.jit(step)
        self._select_fn = jax.jit(select_worlds)
        self._state: envs.State | None = None
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    def _keys(self) -> jax.Array:
        seed = int(self.np_random.integers(2**31))
        return jax.random.split(jax.random.PRNGKey(seed), self.num_envs)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode in every world; ``seed`` reseeds the adapter's generator."""
        super().reset(seed=seed, options=options)
        self._state = self._reset_fn(self._keys())
        self._autoreset[:] = False
        return np.array(self._state.obs, dtype=np.float32), {}

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """One env step of every world (NEXT_STEP autoreset: see the module docstring)."""
        if self._state is None:
            raise UserInputError("call reset() before step()")
        a = _checked_action(actions, self.action_space.shape, "actions")
        state, terminated, truncated = self._step_fn(self._state, jnp.asarray(a))
        reward = state.reward
        if self._autoreset.any():
            mask = jnp.asarray(self._autoreset)
            state = self._select_fn(mask, self._reset_fn(self._keys()), state)
            reward = jnp.where(mask, 0.0, reward)
            terminated = terminated & ~mask
            truncated = truncated & ~mask
        self._state = state
        terminated = np.array(terminated, dtype=bool)
        truncated = np.array(truncated, dtype=bool)
        self._autoreset = terminated | truncated
        obs = np.array(state.obs, dtype=np.float32)
        return obs, np.array(reward, dtype=np.float64), terminated, truncated, _np_info(state)


class PegHoleGymEnv(gymnasium.Env):
    """One MJX world of a peg extraction env as a ``gymnasium.Env`` (NumPy arrays).

    ``name`` and ``config_overrides`` as for :class:`PegHoleVectorEnv`. Spaces and episode
    ends: see the module docstring; no autoreset (call ``reset`` after an episode ends).
    """

    metadata = {"render_modes": []}  # noqa: RUF012

    def __init__(self, name: str = "RectExtract", config_overrides: dict | None = None):
        self.env = envs.load(name, config_overrides=config_overrides)
        self.observation_space, self.action_space = _spaces(self.env)
        env = self.env

        def step(state, action):
            new = env.step(state, action)
            return new, *_end_flags(env, new)

        self._reset_fn = jax.jit(env.reset)
        self._step_fn = jax.jit(step)
        self._state: envs.State | None = None
        self._ended: str | None = None  # "terminated" / "truncated" once the episode ended

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new, randomised episode; ``seed`` reseeds ``self.np_random``."""
        super().reset(seed=seed, options=options)
        key = jax.random.PRNGKey(int(self.np_random.integers(2**31)))
        self._state = self._reset_fn(key)
        self._ended = None
        return np.array(self._state.obs, dtype=np.float32), {}

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict[str, float]]:
        """One env step (``ctrl_dt``: ``n_substeps`` physics steps under the impedance law).

        Raises :class:`UserInputError` after the episode ended (call ``reset``)."""
        if self._state is None:
            raise UserInputError("call reset() before step()")
        if self._ended is not None:
            raise UserInputError(
                f"the episode has ended ({self._ended}): call reset() before step()"
            )
        a = _checked_action(action, self.action_space.shape, "action")
        self._state, terminated, truncated = self._step_fn(self._state, jnp.asarray(a))
        terminated, truncated = bool(terminated), bool(truncated)
        if terminated or truncated:
            self._ended = "terminated" if terminated else "truncated"
        info = {k: float(v) for k, v in _np_info(self._state).items()}
        obs = np.array(self._state.obs, dtype=np.float32)
        return obs, float(self._state.reward), terminated, truncated, info


__all__ = ["INFO_KEYS", "PegHoleGymEnv", "PegHoleVectorEnv"]
