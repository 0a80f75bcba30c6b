"""Imports of optional dependencies, with a one-line message naming the extra to install.

The CAD pipeline (``peghole models decompose``, :mod:`peghole_mjx.geometry.decompose`) needs
the ``cad`` extra (coacd, trimesh, manifold3d for trimesh's booleans, rtree for its proximity
queries); the Gymnasium adapter (:mod:`peghole_mjx.gym`) needs the ``gym`` extra; MuJoCo
Playground's training wrapper (:mod:`peghole_mjx.envs.playground`) the ``playground`` extra.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from peghole_mjx.core.errors import MissingExtraError

#: the extra of pyproject.toml that installs each optional module
EXTRAS = {
    "coacd": "cad",
    "trimesh": "cad",
    "manifold3d": "cad",
    "rtree": "cad",
    "gymnasium": "gym",
    "mujoco_playground": "playground",
}


def optional_import(name: str, purpose: str) -> ModuleType:
    """Import module ``name``; if it is missing, raise :class:`MissingExtraError` saying that
    ``purpose`` needs it and which ``pip install`` command installs it."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        top = name.split(".")[0]
        extra = EXTRAS.get(top)
        how = f'pip install -e ".[{extra}]"' if extra else f"pip install {top}"
        raise MissingExtraError(f"{purpose} needs {top}, which is not installed: {how}") from exc
