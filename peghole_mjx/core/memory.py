"""Memory before allocation: what a run will hold, checked against what the machine has.

A replay buffer, a batch of worlds or an evaluation is sized before it is allocated, and a
run that would not fit is refused in one line naming both figures, instead of dying minutes
later with an out-of-memory traceback. Host memory is Linux's ``MemAvailable``; device memory
is the accelerator's free memory where JAX reports it (on a CPU the two are the same pool).
"""

from __future__ import annotations

import weakref

import jax
import mujoco
import numpy as np

from peghole_mjx.core.errors import UserInputError

#: share of the available memory a run may plan to use (the rest: XLA's work space, Python)
USABLE_FRACTION = 0.8


def host_available_bytes() -> int | None:
    """Linux's ``MemAvailable`` in bytes, or None where it cannot be read."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def device_available_bytes() -> int | None:
    """Free memory of JAX's first accelerator in bytes; None on a CPU or where not reported."""
    dev = jax.devices()[0]
    if dev.platform == "cpu":
        return None
    stats = dev.memory_stats() or {}
    limit, used = stats.get("bytes_limit"), stats.get("bytes_in_use", 0)
    return None if limit is None else int(limit - used)


def fmt_bytes(n: float) -> str:
    """``n`` bytes as MiB or GiB."""
    return f"{n / 2**20:.0f} MiB" if n < 2**30 else f"{n / 2**30:.1f} GiB"


def check_fits(need_bytes: int, what: str, hint: str = "") -> None:
    """Refuse (UserInputError) when ``need_bytes`` exceeds the usable share of the host's
    available memory or, on an accelerator, of its free memory. ``what`` names the
    allocation and ``hint`` the setting that sizes it."""
    pools = [("host", host_available_bytes())]
    try:
        pools.append(("device", device_available_bytes()))
    except (RuntimeError, NotImplementedError):  # a backend that cannot report: host only
        pass
    for pool, avail in pools:
        if avail is None:
            continue
        usable = int(avail * USABLE_FRACTION)
        if need_bytes > usable:
            tail = f"; {hint}" if hint else ""
            raise UserInputError(
                f"{what} needs about {fmt_bytes(need_bytes)}, more than the {pool} memory a run "
                f"may use ({fmt_bytes(usable)} = {USABLE_FRACTION:.0%} of "
                f"{fmt_bytes(avail)} available){tail}"
            )


_WORLD_BYTES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def world_bytes(env) -> int:
    """Bytes of one world's env state (``env.reset`` traced with ``jax.eval_shape``: shapes
    only, nothing compiled or allocated; a few seconds, remembered per env object)."""
    try:
        return _WORLD_BYTES[env]
    except (KeyError, TypeError):
        pass
    one = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
    n = sum(int(np.prod(x.shape)) * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(one))
    n += engine_host_bytes(env)
    try:
        _WORLD_BYTES[env] = n
    except TypeError:  # an env that cannot be weakly referenced: traced each time
        pass
    return n


def engine_host_bytes(env) -> int:
    """Bytes an engine holds per world outside the env state: the ``mujoco`` engine keeps a
    MuJoCo C ``MjData`` per world on the host (its main buffer, ``nbuffer``; about 19 kB for
    RectExtract), which the state traced by :func:`world_bytes` does not show. 0 for MJX."""
    engine = getattr(env, "engine", None)
    model = getattr(engine, "model", None)
    if not getattr(engine, "host_callbacks", False) or not isinstance(model, mujoco.MjModel):
        return 0
    return int(mujoco.MjData(model).nbuffer)


#: copies of a world's state a batched step holds at once (state, next state, resets, work)
WORLD_COPIES = 4


#: a bound on one world's state, 20x the largest of the built-in envs (DualExtract's mesh
#: scene, 49.8 kB): a batch that fits at this size needs no trace of the env's reset
WORLD_CEILING_BYTES = 1 << 20


def check_worlds(env, worlds: int, what: str, hint: str) -> None:
    """Refuse (UserInputError) ``worlds`` worlds of ``env`` run at once when their states
    (:data:`WORLD_COPIES` copies each) do not fit :func:`check_fits`. A batch that fits even at
    :data:`WORLD_CEILING_BYTES` a world is let through without tracing the env."""
    try:
        check_fits(WORLD_COPIES * worlds * WORLD_CEILING_BYTES, what, hint)
        return
    except UserInputError:
        pass  # might not fit: measure the world
    one = world_bytes(env)
    check_fits(WORLD_COPIES * worlds * one, f"{what} ({worlds} worlds of {one} B)", hint)
