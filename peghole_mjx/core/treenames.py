"""Leaves of a JAX pytree named by their tree paths, so saved arrays are matched by name.

``named_leaves(carry)`` gives ``{"ts/q_params/params/hidden_0/kernel": array, ...}``:
attribute names, dict keys and sequence indices joined by ``/``, in tree order. Checkpoint
states (``training/checkpoints.py``) and policy parameters (``policies``, format 2) are saved
under these names and restored by them, never by leaf position.
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np


def _key_name(k: Any) -> str:
    for attr in ("key", "name", "idx"):
        if hasattr(k, attr):
            return str(getattr(k, attr))
    return str(k)


def named_leaves(tree: Any) -> dict[str, np.ndarray]:
    """``{"a/b/0": array}``: every leaf of ``tree`` named by its tree path, as a numpy array,
    in tree order."""
    out: dict[str, np.ndarray] = {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(jax.device_get(tree))[0]:
        name = path_name(path)
        if name in out:
            raise ValueError(f"two leaves share the tree path {name!r}")
        out[name] = np.asarray(leaf)
    return out


def path_name(path: tuple) -> str:
    """The ``/``-joined name of a JAX key path."""
    return "/".join(_key_name(k) for k in path)


def differences(have: dict[str, Any], want: dict[str, Any]) -> list[str]:
    """What differs between two ``{name: (shape, dtype)}`` maps, for a one-line message: the
    first names missing from ``have``, those it has in excess, and those of another value."""

    def some(names) -> str:
        names = sorted(names)
        return ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")

    problems = []
    if missing := set(want) - set(have):
        problems.append(f"missing {some(missing)}")
    if extra := set(have) - set(want):
        problems.append(f"unexpected {some(extra)}")
    if other := sorted(k for k in set(want) & set(have) if have[k] != want[k]):
        k = other[0]
        problems.append(
            f"{len(other)} of another shape or dtype (e.g. {k}: saved {have[k][0]} "
            f"{have[k][1]}, expected {want[k][0]} {want[k][1]})"
        )
    return problems
