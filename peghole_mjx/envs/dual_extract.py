"""DualExtract: pull the dual peg out of its two holes (thesis Ch 2, preset dual-2).

The RL study the thesis could not run: PyBullet collided the non-convex dual peg as its convex
hull. Here the parts are convex pieces in the collision representation of ``config.representation``
(:mod:`peghole_mjx.geometry.parts`): by default ``capsule`` (capsule pegs in box-walled holes, the
GPU-scale scene), or ``mesh`` (two 16-gon prisms and a bridge in convex wedges, exact; the
published dual policy was trained there and pins it).
"""

from __future__ import annotations

from ml_collections import config_dict

from peghole_mjx.envs.config import base_config
from peghole_mjx.envs.extraction import PegHoleEnv
from peghole_mjx.geometry.specs import get_preset


def default_config(preset: str = "dual-2") -> config_dict.ConfigDict:
    """Dual-2 (two r = 6.0 mm pegs in R = 6.1 mm holes, 40 mm apart, 50 mm long, mu 0.01)."""
    config = base_config(preset)
    config.episode_length = 400  # 8 s at 50 Hz for a 50 mm pull
    return config


#: DualExtractHard's commanded tilt error about x and y, deg (uniform in +-this)
HARD_ANGULAR_ERROR_DEG = 1.75
#: DualExtractHard's friction: the printed (PLA) peg of the rect chapter, mu 0.266; the dual
#: preset's mu 0.01 is erratum E5
HARD_FRICTION_PRESET = "rect-2"


def hard_config() -> config_dict.ConfigDict:
    """DualExtractHard: dual-3 (r = 6.05 mm pegs in R = 6.1 mm holes) with mu 0.266 (erratum E5:
    the friction of the rect chapter's printed peg) and the commanded tilt error up to 1.75 deg
    about each axis, where the scripted Ch 2-3 method wedges in a fraction of the episodes
    (docs/index.md, "Hard variants"; measured with ``benchmarks/evals/hard_variants.py``)."""
    config = default_config("dual-3")
    r = config.randomization
    # the env scales the preset's mu per episode by friction_scale: rescale the range to mu 0.266
    ratio = get_preset(HARD_FRICTION_PRESET).friction / get_preset(config.preset).friction
    r.friction_scale = tuple(ratio * s for s in r.friction_scale)
    r.angular_error_deg = HARD_ANGULAR_ERROR_DEG
    return config


class DualExtract(PegHoleEnv):
    """The dual peg-hole extraction task. Tables: see PegHoleEnv."""

    def __init__(
        self, config: config_dict.ConfigDict | None = None, config_overrides: dict | None = None
    ):
        super().__init__(config or default_config(), config_overrides)
