"""Where and how hard the peg touches the hole: one episode's contacts, env step by env step.

The thesis infers its contact states (Ch 2-3: one- and two-point contact, jamming) from the
F/T wrench and names watching the contact points directly as future work (Ch 5.3, a
transparent fixture). The simulator shows them. :func:`record_contacts` runs one world of an
env with a policy and, after every env step, writes the state into a MuJoCo ``MjData`` (the
engine's ``to_mjdata``, as the renderer does) and lists every active contact (distance
<= 0) between a peg geom and a hole geom:

* its point in the peg's frame, in mm: origin at the peg tip, axes of the peg body, whose z
  axis runs along the peg and out of its tip (a point on the peg's side has z < 0: its
  distance from the tip, negative);
* its normal, a unit vector in the peg's frame pointing from the wall into the peg;
* its normal force, N (``mujoco.mj_contactForce``: the contact frame's first component);
* the hole geom it touches (a wall of the hole: its name in the scene).

Sampled once per env step, at the end of the step's last physics substep, not per substep.

A step is in **two-point contact** (the thesis's state in which jamming happens, Ch 2-3: the
tilted peg pressed against opposite walls, one contact near its tip and one at the hole's
mouth) when two loaded contacts have opposite normals (``n1 . n2 < -0.9``) and lie at least
:data:`TWO_POINT_DZ_MM` apart along the peg (:func:`two_point_steps`). Contacts on opposite
walls at the same height (the peg squeezed, not tilted) are not counted.
:func:`plot_contacts` draws the points on the peg (two side views, coloured by force) and the
normal force on each hole geom over the episode. ``peghole envs contacts`` runs both.
"""

from __future__ import annotations

import copy
import functools
import weakref
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import mujoco
import numpy as np

from peghole_mjx.core import progress as prog
from peghole_mjx.envs import iiwa_constants as names
from peghole_mjx.envs.extraction import PegHoleEnv
from peghole_mjx.files import fileio
from peghole_mjx.geometry.specs import MM
from peghole_mjx.sim import free
from peghole_mjx.sim.engine_mujoco import STATE_SPEC
from peghole_mjx.sim.engines import batch_reset, select_worlds

#: the columns of :attr:`ContactTrace.rows` (one row per active peg-hole contact and env step)
COLUMNS = ("step", "time_s", "x_mm", "y_mm", "z_mm", "nx", "ny", "nz", "normal_N", "hole_geom")
#: two contacts this far apart along the peg (mm), with opposite normals: two-point contact
TWO_POINT_DZ_MM = 1.0


@dataclass
class ContactTrace:
    """One episode's peg-hole contacts (:data:`COLUMNS`) and how the episode ended."""

    rows: list[tuple]
    steps: int
    ctrl_dt: float
    success: bool

    def column(self, name: str) -> np.ndarray:
        i = COLUMNS.index(name)
        return np.array([r[i] for r in self.rows])

    def summary(self) -> dict[str, Any]:
        """Counts, the most contacts at one step, the largest normal force, per hole geom."""
        per_step = Counter(r[0] for r in self.rows)
        geoms = sorted({r[-1] for r in self.rows})
        return {
            "env_steps": self.steps,
            "success": self.success,
            "contact_rows": len(self.rows),
            "steps_in_contact": len(per_step),
            "most_contacts_at_one_step": max(per_step.values(), default=0),
            "max_normal_N": round(float(self.column("normal_N").max()), 3) if self.rows else 0.0,
            "two_point_steps": len(two_point_steps(self.rows)),
            "hole_geoms_touched": geoms,
        }

    def write_csv(self, path: Path) -> None:
        """:data:`COLUMNS`, one row per contact (written atomically)."""
        lines = [",".join(COLUMNS)]
        for r in self.rows:
            nums = ",".join(f"{v:.5f}" for v in r[1:-1])
            lines.append(f"{r[0]},{nums},{r[-1]}")
        fileio.write_text(path, "\n".join(lines) + "\n")


def _body_geoms(m: mujoco.MjModel, body: str) -> set[int]:
    """The geoms of ``body`` (the scenes hold the peg's and the hole's pieces on one body each,
    as :mod:`peghole_mjx.experiments.compliance` also reads them)."""
    return set(np.flatnonzero(m.geom_bodyid == m.body(body).id).tolist())


def contacts_now(m: mujoco.MjModel, d: mujoco.MjData, peg: set[int], hole: set[int]):
    """``[(x_mm, y_mm, z_mm, nx, ny, nz, normal_N, hole_geom_name)]`` of the active peg-hole
    contacts of ``d`` (forward done), in the peg tip's frame (module doc)."""
    peg_body = m.body(names.PEG_BODY).id
    R = d.xmat[peg_body].reshape(3, 3)
    tip = d.site_xpos[m.site(names.PEG_TIP_SITE).id]
    force = np.zeros(6)
    out = []
    for i in range(d.ncon):
        c = d.contact[i]
        if c.dist > 0.0:
            continue
        g1, g2 = int(c.geom1), int(c.geom2)
        # MuJoCo's contact normal points from geom1 to geom2: turned to point into the peg
        if g1 in peg and g2 in hole:
            other, sign = g2, -1.0
        elif g2 in peg and g1 in hole:
            other, sign = g1, 1.0
        else:
            continue
        mujoco.mj_contactForce(m, d, i, force)
        p = R.T @ (np.asarray(c.pos) - tip) / MM
        n = sign * (R.T @ np.asarray(c.frame[:3]))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, other) or f"geom{other}"
        out.append((*(float(v) for v in p), *(float(v) for v in n), float(force[0]), name))
    return out


def two_point_steps(rows: list[tuple], min_force_N: float = 1e-6) -> set[int]:
    """The steps of ``rows`` (:data:`COLUMNS`) in two-point contact (module doc): two contacts
    carrying force with opposite normals, at least :data:`TWO_POINT_DZ_MM` apart along z."""
    by_step: dict[int, list[tuple]] = {}
    for r in rows:
        if r[8] > min_force_N:
            by_step.setdefault(r[0], []).append(r)
    out = set()
    for step, cs in by_step.items():
        n = np.array([c[5:8] for c in cs])
        z = np.array([c[4] for c in cs])
        opposite = (n @ n.T) < -0.9
        apart = np.abs(z[:, None] - z[None, :]) >= TWO_POINT_DZ_MM
        if np.any(opposite & apart):
            out.add(step)
    return out


def record_contacts(
    env: PegHoleEnv,
    act: Callable[[jax.Array, jax.Array], jax.Array],
    seed: int = 0,
    max_steps: int | None = None,
    progress: bool = True,
) -> ContactTrace:
    """Run one world from the reset of ``seed`` with ``act(obs, rng) -> action`` until done
    (or ``max_steps``) and list its peg-hole contacts after every env step."""
    m = env.mj_model
    peg, hole = _body_geoms(m, names.PEG_BODY), _body_geoms(m, names.HOLE_BODY)
    d = mujoco.MjData(m)
    reset, step, act_j = jax.jit(env.reset), jax.jit(env.step), jax.jit(act)
    key = jax.random.PRNGKey(seed + 1)
    with prog.compiling(f"the {env.env_name} step for the contact record", enabled=progress):
        state = reset(jax.random.PRNGKey(seed))
        jax.block_until_ready(step(state, act_j(state.obs, key)))
    n = max_steps or env.config.episode_length
    rows: list[tuple] = []
    bar = prog.bar(n, "contact record", unit="step", enabled=progress)
    t = 0
    try:
        while t < n:
            key, sub = jax.random.split(key)
            state = step(state, act_j(state.obs, sub))
            t += 1
            env.engine.to_mjdata(state.data, m, d)
            for c in contacts_now(m, d, peg, hole):
                rows.append((t, t * env.config.ctrl_dt, *c))
            bar.update()
            if float(state.done) > 0:
                break
    finally:
        bar.close()
    return ContactTrace(
        rows=rows,
        steps=t,
        ctrl_dt=env.config.ctrl_dt,
        success=bool(float(state.metrics["success"]) > 0),
    )


def plot_contacts(trace: ContactTrace, path: Path, title: str = "") -> Path:
    """Three panels: the contact points on the peg (x-z and y-z side views, colour = normal
    force) and the summed normal force on each hole geom over the episode, the steps in
    two-point contact marked in red."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    if trace.rows:
        x, y, z = (trace.column(k) for k in ("x_mm", "y_mm", "z_mm"))
        f = trace.column("normal_N")
        for ax, h, lab in ((axes[0], x, "x"), (axes[1], y, "y")):
            sc = ax.scatter(h, z, c=f, s=10, cmap="viridis")
            ax.set_xlabel(f"{lab} on the peg (mm)")
            ax.set_ylabel("z from the tip (mm)")
            ax.set_aspect("equal", adjustable="datalim")
        fig.colorbar(sc, ax=axes[1], label="normal force (N)")
        steps, geoms = trace.column("step"), trace.column("hole_geom")
        t = np.arange(1, trace.steps + 1) * trace.ctrl_dt
        per = {}
        for g in set(geoms):
            per[g] = np.zeros(trace.steps)
            np.add.at(per[g], steps[geoms == g].astype(int) - 1, f[geoms == g])
        # the six geoms carrying the most force named, the rest in grey
        ranked = sorted(per, key=lambda g: -per[g].sum())
        for g in reversed(ranked):
            named = g in ranked[:6]
            axes[2].plot(t, per[g], lw=1, label=g if named else None, c=None if named else "0.8")
        two = sorted(two_point_steps(trace.rows))
        if two:
            axes[2].plot(
                t[np.asarray(two) - 1],
                np.zeros(len(two)),
                "|",
                c="red",
                ms=12,
                label="two-point contact",
            )
        axes[2].legend(fontsize=7)
    else:
        axes[1].text(0.5, 0.5, "no peg-hole contact", ha="center", transform=axes[1].transAxes)
    axes[0].set_title("contact points, side view x-z")
    axes[1].set_title("contact points, side view y-z")
    axes[2].set_title("normal force per hole geom")
    axes[2].set_xlabel("time (s)")
    axes[2].set_ylabel("N")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def restart_done(state: Any, start: Any) -> Any:
    """The batch ``state`` with its finished worlds put back to their start states ``start``."""
    return select_worlds(jnp.asarray(np.asarray(state.done) > 0), start, state)


class ContactReplay:
    """Counts the active contacts (distance <= 0) after every physics step of a ``mujoco``
    engine env's steps, by replaying them.

    Inside ``with ContactReplay(env) as replay:`` each env step runs in the env with the
    engine's torque record on (``engine.ctrl_log``); ``replay.max_active(prev, state)`` then
    replays that step's physics steps world by world in one ``MjData``
    (:func:`peghole_mjx.sim.free.replay_ctrl`), from the step's start state with the recorded
    torques and the world's friction scale, counting after every ``mj_step``. The replay is
    the env's own step: its end state must equal the env's bit for bit (a RuntimeError
    otherwise). How the presets' and the task folders' contact caps are measured
    (:func:`max_active_contacts`, ``benchmarks/perf/contact_caps.py``)."""

    def __init__(self, env: PegHoleEnv):
        if env.engine.name != "mujoco":
            raise ValueError(f"contact replay needs the mujoco engine, got {env.engine.name!r}")
        self.env = env
        self.model = copy.copy(env.engine.model)
        self.friction0 = np.array(self.model.pair_friction)
        self.data = mujoco.MjData(self.model)
        self.row = np.empty(env.engine.nstate)
        self.log: list[np.ndarray] = []

    def __enter__(self) -> ContactReplay:
        self.log.clear()
        self.env.engine.ctrl_log = self.log
        return self

    def __exit__(self, *exc: object) -> None:
        self.env.engine.ctrl_log = None

    def max_active(self, prev: Any, state: Any) -> int:
        """The most active contacts in any world after any physics step of the env step
        from ``prev`` to ``state`` (batched states)."""
        m, d = self.model, self.data
        jax.block_until_ready(state.obs)
        ctrl = np.stack(self.log, axis=1)  # (worlds, substeps, nu)
        self.log.clear()
        start = jax.tree.map(np.asarray, prev.data)
        end = np.asarray(state.data.state)
        fscale = np.asarray(prev.info["friction_scale"], float)
        finite = np.asarray(state.metrics["nan"]) == 0
        most = 0

        def count(d: mujoco.MjData) -> None:
            nonlocal most
            most = max(most, int(np.sum(d.contact.dist[: d.ncon] <= 0.0)))

        for w in range(ctrl.shape[0]):
            m.pair_friction[:] = self.friction0 * fscale[w]
            self.env.engine.to_mjdata(jax.tree.map(lambda x, w=w: x[w], start), m, d)
            free.replay_ctrl(m, d, ctrl[w], count)
            mujoco.mj_getState(m, d, self.row, STATE_SPEC)
            if finite[w] and not np.array_equal(self.row, end[w].view(np.float64)):
                raise RuntimeError(f"world {w}: the replayed step differs from the env's")
        return most


#: each env's batched reset and step, jitted once: ``task make`` counts contacts under two
#: policies, and a fresh ``jax.jit(jax.vmap(...))`` per call compiled the reset and the step
#: twice (2026-12-04; docs/guide/own_parts.md, time of the contact count)
_BATCHED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

# The contact count's ``reset_start`` is compiled for one world and called per world (decided
# 2026-12-05, docs/research/models.md): on the 2-core CPU, for issue 54's triangular
# task, ``jax.jit(jax.vmap(env.reset_start))`` over 4 worlds took 8.5 s to trace, 44 s to
# compile and 7.5 s per call; ``jax.jit(env.reset_start)`` 22 s to trace and compile and
# 2 ms per world; the same draws, the joint angles within float32 rounding (4e-7 rad).


def batched_reset_step(env: PegHoleEnv) -> tuple[Callable, Callable]:
    """The batched reset and ``jax.jit(jax.vmap(env.step))``, made once per env (so compiled
    once per batch shape, whatever the policy). On an engine with host callbacks (``mujoco``)
    the reset is two graphs: ``reset_start``, pure JAX and most of the compile, kept by the
    persistent compilation cache across processes, compiled for one world and called world by
    world (the note above), then the small batched ``reset_finish``."""
    fns = _BATCHED.get(env)
    if fns is None:
        if env.engine.host_callbacks:
            start = jax.jit(env.reset_start)
            finish = jax.jit(jax.vmap(env.reset_finish))

            def reset(rngs: jax.Array) -> Any:
                starts = [start(k) for k in rngs]
                return finish(jax.tree.map(lambda *xs: jnp.stack(xs), *starts))

        else:
            reset = jax.jit(functools.partial(batch_reset, env))
        fns = _BATCHED[env] = (reset, jax.jit(jax.vmap(env.step)))
    return fns


def max_active_contacts(
    env: PegHoleEnv,
    act: Callable[[jax.Array, jax.Array], jax.Array],
    worlds: int = 4,
    env_steps: int = 200,
    seed: int = 0,
    replays: bool = False,
) -> dict[str, int]:
    """The most active contacts (distance <= 0) in any world after any physics step, ``worlds``
    worlds of ``env`` (on its ``mujoco`` engine) run for ``env_steps`` env steps with
    ``act(obs, rng) -> action``; a finished world restarts from its start state. Counted by
    :class:`ContactReplay`. Returns the maximum, the episodes that ended and the env steps
    run.

    ``replays``: ``act`` ignores its observation and its key (the scripted policy), so a
    restarted world replays its first episode exactly (the whole state, its key included, is
    put back): the run ends once every world has ended an episode, as the rest would count
    the same contacts again (decided 2026-12-05, docs/research/models.md)."""
    reset, step = batched_reset_step(env)
    act_v = jax.jit(jax.vmap(act))
    state = start = reset(jax.random.split(jax.random.PRNGKey(seed), worlds))
    key = jax.random.PRNGKey(seed + 1)
    most, episodes, ran = 0, 0, 0
    ended = np.zeros(worlds, bool)
    with ContactReplay(env) as replay:
        for _ in range(env_steps):
            key, sub = jax.random.split(key)
            prev = state
            state = step(prev, act_v(prev.obs, jax.random.split(sub, worlds)))
            ran += 1
            most = max(most, replay.max_active(prev, state))
            done = np.asarray(state.done) > 0
            if done.any():
                episodes += int(done.sum())
                ended |= done
                if replays and ended.all():
                    break
                state = restart_done(state, start)
    return {"max_active": most, "episodes_ended": episodes, "env_steps": ran}
