"""RectExtract: pull the rectangular peg out of its hole (thesis Ch 3-4, preset rect-2)."""

from __future__ import annotations

from ml_collections import config_dict

from peghole_mjx.envs.base import PegHoleEnv, base_config


def default_config() -> config_dict.ConfigDict:
    """Rect-2 (60 x 40 mm peg in a 60.1 x 40.1 mm hole, 150 mm long, mu 0.266)."""
    config = base_config("rect-2")
    config.episode_length = 750  # 15 s at 50 Hz: twice the thesis's 7.6 s mean time
    return config


class RectExtract(PegHoleEnv):
    """The thesis's RL task (Ch 4): the rectangular peg-hole. Tables: see PegHoleEnv."""

    def __init__(
        self, config: config_dict.ConfigDict | None = None, config_overrides: dict | None = None
    ):
        super().__init__(config or default_config(), config_overrides)
