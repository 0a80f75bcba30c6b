"""Render one episode of a policy to a GIF with ``mujoco.Renderer``.

Headless by default: :mod:`peghole_mjx` selects ``MUJOCO_GL=egl`` when there is no display
(set ``MUJOCO_GL=osmesa`` where EGL is missing).
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np


def render_policy_gif(
    policy_path: str | Path,
    out: str | Path,
    seed: int = 0,
    width: int = 320,
    height: int = 240,
    every: int = 5,
    max_steps: int | None = None,
) -> Path:
    """Run the policy in one world (deterministic) and write every ``every``-th env step."""
    import mujoco
    from PIL import Image

    from peghole_mjx.policies import load_policy

    bundle = load_policy(policy_path)
    env = bundle.make_env()
    policy = bundle.policy_fn()
    step = jax.jit(env.step)
    act = jax.jit(policy)
    state = jax.jit(env.reset)(jax.random.PRNGKey(seed))
    m = env.mj_model
    d = mujoco.MjData(m)
    renderer = mujoco.Renderer(m, height, width)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = np.asarray(state.info["hole_pos"]) + np.array([0.0, 0.0, 0.08])
    cam.distance, cam.azimuth, cam.elevation = 0.9, 150.0, -15.0
    frames = []
    n = max_steps or env.config.episode_length
    key = jax.random.PRNGKey(seed + 1)
    for t in range(n):
        if t % every == 0:
            env.engine.to_mjdata(state.data, m, d)  # either engine's state, forward done
            renderer.update_scene(d, camera=cam)
            frames.append(Image.fromarray(renderer.render()))
        key, sub = jax.random.split(key)
        state = step(state, act(bundle.params, state.obs, sub))
        if float(state.done) > 0:
            break
    renderer.close()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    duration_ms = int(1000 * env.config.ctrl_dt * every)
    frames[0].save(out, save_all=True, append_images=frames[1:], duration=duration_ms, loop=0)
    return out
