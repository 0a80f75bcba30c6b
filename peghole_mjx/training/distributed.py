"""Several training processes (hosts) as one learner: ``peghole train --distributed``.

:func:`initialize` calls ``jax.distributed.initialize`` before anything else of JAX runs.
The coordinator is ``JAX_COORDINATOR_ADDRESS`` (``host:port``, read by JAX), the number of
processes ``JAX_NUM_PROCESSES`` and this one's index ``JAX_PROCESS_ID``; without them JAX's
own cluster detection (SLURM, Open MPI, Kubernetes, Cloud TPU) fills them in. On CPU the
cross-process collectives use gloo. The learner then ``pmap``s over every process's devices
(:mod:`peghole_mjx.training.sac`).
"""

from __future__ import annotations

import os

import jax

from peghole_mjx.core.errors import UserInputError


def initialize() -> tuple[int, int]:
    """Join the processes; returns ``(process_index, process_count)``."""
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    kwargs = {}
    for var, key in (("JAX_NUM_PROCESSES", "num_processes"), ("JAX_PROCESS_ID", "process_id")):
        if os.environ.get(var):
            try:
                kwargs[key] = int(os.environ[var])
            except ValueError:
                raise UserInputError(f"{var} must be an integer, got {os.environ[var]!r}") from None
    try:
        jax.distributed.initialize(**kwargs)
    except (ValueError, RuntimeError) as exc:
        msg = " ".join(str(exc).split())
        raise UserInputError(
            f"--distributed: {msg} (set JAX_COORDINATOR_ADDRESS=host:port, JAX_NUM_PROCESSES "
            "and JAX_PROCESS_ID, or run under a cluster launcher)"
        ) from None
    return jax.process_index(), jax.process_count()
