"""Render one episode of a policy to a GIF with ``mujoco.Renderer``.

Headless by default: :mod:`peghole_mjx` selects ``MUJOCO_GL=egl`` when there is no display
(set ``MUJOCO_GL=osmesa`` where EGL is missing).

Progress (stderr, :mod:`peghole_mjx.core.progress`): the compile of the episode's reset, step and
policy is one labelled phase, the episode one bar counting env steps with the frames drawn.
Decided 2026-12-02: the render (compile and frames) took 4.5 min on a 2-core CPU after the
training bar had reached 100 %, with nothing on screen.
"""

from __future__ import annotations

from pathlib import Path

import jax
import mujoco
import numpy as np
from PIL import Image

from peghole_mjx.core import progress as prog
from peghole_mjx.policies import load_policy


def render_policy_gif(
    policy_path: str | Path,
    out: str | Path,
    seed: int = 0,
    width: int = 320,
    height: int = 240,
    every: int = 5,
    max_steps: int | None = None,
    progress: bool = True,
) -> Path:
    """Run the policy in one world (deterministic) and write every ``every``-th env step;
    ``progress``: the compile and the episode's bar on stderr."""
    out = Path(out)
    bundle = load_policy(policy_path)
    env = bundle.make_env()
    policy = bundle.policy_fn()
    key = jax.random.PRNGKey(seed + 1)
    act, step = jax.jit(policy), jax.jit(env.step)
    with prog.compiling(f"the env step and policy for {out.name}", enabled=progress):
        state = jax.jit(env.reset)(jax.random.PRNGKey(seed))
        # one step whose result is dropped: compiles both (the episode below starts at state)
        jax.block_until_ready(step(state, act(bundle.params, state.obs, key)))
    m = env.mj_model
    d = mujoco.MjData(m)
    renderer = mujoco.Renderer(m, height, width)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = np.asarray(state.info["hole_pos"]) + np.array([0.0, 0.0, 0.08])
    cam.distance, cam.azimuth, cam.elevation = 0.9, 150.0, -15.0
    frames = []
    n = max_steps or env.config.episode_length
    bar = prog.bar(n, f"rendering {out.name}", unit="step", enabled=progress)
    try:
        for t in range(n):
            if t % every == 0:
                env.engine.to_mjdata(state.data, m, d)  # either engine's state, forward done
                renderer.update_scene(d, camera=cam)
                frames.append(Image.fromarray(renderer.render()))
                bar.set_postfix(frames=len(frames), refresh=False)
            key, sub = jax.random.split(key)
            state = step(state, act(bundle.params, state.obs, sub))
            bar.update()
            if float(state.done) > 0:
                break
    finally:
        bar.close()
        renderer.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    duration_ms = int(1000 * env.config.ctrl_dt * every)
    frames[0].save(out, save_all=True, append_images=frames[1:], duration=duration_ms, loop=0)
    return out
