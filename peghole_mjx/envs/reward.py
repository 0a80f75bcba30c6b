"""The extraction reward, eq (4.4) with the Table 4.1 weights, as named terms."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from ml_collections import config_dict

#: Table 4.1 reward weights (one source of truth; configs copy them into reward_config)
REWARD_WEIGHTS = {"w_d": 1.0, "w_f": 1.0, "w_stf": 0.1, "r_success": 1.0, "r_failure": -1.0}


def reward_terms(
    dz_mm, fxy_N, k_xy_N_m, success, failure, rc: config_dict.ConfigDict, k_rot_Nm_rad=0.0, fz_N=0.0
) -> dict[str, jax.Array]:
    """The named reward terms of eq (4.4) (Table 4.1 weights in ``rc``, the ``reward_config``).

    ``dz_mm``: change of tip depth this step (negative when the peg comes out);
    ``fxy_N``: lateral contact force; ``k_xy_N_m``: lateral stiffness (both axes equal, so
    ``||k_xy|| = sqrt(2) k``); ``success``/``failure``: 0 or 1. Two terms are not in
    eq (4.4) and are zero at their default weights: ``rot_stiffness``
    ``-w_stf_rot K_theta / 300 N m/rad`` and ``extraction_force`` ``-w_fz |f_z| / fz_scale_N``.
    The names are :data:`peghole_mjx.envs.metrics.REWARD_TERMS`.
    """
    return {
        "progress": -rc.w_d * dz_mm,
        "force": -rc.w_f * fxy_N / rc.force_scale_N,
        "stiffness": -rc.w_stf * jnp.sqrt(2.0) * jnp.abs(k_xy_N_m) / rc.stiffness_scale_N_m,
        "rot_stiffness": -rc.w_stf_rot * jnp.abs(k_rot_Nm_rad) / rc.rot_stiffness_scale_Nm_rad,
        "extraction_force": -rc.w_fz * jnp.abs(fz_N) / rc.fz_scale_N,
        "end": rc.r_success * success + rc.r_failure * failure,
    }
