"""DualExtract: pull the dual peg out of its two holes (thesis Ch 2, preset dual-2).

The RL study the thesis could not run: PyBullet collided the non-convex dual peg as its convex
hull. Here the parts are convex pieces in the collision representation of ``config.representation``
(:mod:`peghole_mjx.geometry.parts`): by default ``capsule`` (capsule pegs in box-walled holes, the
GPU-scale scene), or ``mesh`` (two 16-gon prisms and a bridge in convex wedges, exact; the
published dual policy was trained there and pins it).
"""

from __future__ import annotations

from ml_collections import config_dict

from peghole_mjx.envs.base import PegHoleEnv, base_config


def default_config() -> config_dict.ConfigDict:
    """Dual-2 (two r = 6.0 mm pegs in R = 6.1 mm holes, 40 mm apart, 50 mm long, mu 0.01)."""
    config = base_config("dual-2")
    config.episode_length = 400  # 8 s at 50 Hz for a 50 mm pull
    return config


class DualExtract(PegHoleEnv):
    """The dual peg-hole extraction task. Tables: see PegHoleEnv."""

    def __init__(
        self, config: config_dict.ConfigDict | None = None, config_overrides: dict | None = None
    ):
        super().__init__(config or default_config(), config_overrides)
