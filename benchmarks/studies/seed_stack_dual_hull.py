"""Why the seed stack could not run the dual task: PyBullet collides a one-mesh peg as its hull.

The thesis loaded its dual peg (two round pegs joined by a bridge: non-convex) into PyBullet
as ONE mesh; for a moving body PyBullet collides a mesh as its convex hull, which fills the
space between the two pegs. This benchmark builds the DualExtract peg-hole in PyBullet twice,
from the project's geometry (preset, pieces and start pose:
``get_default_config("DualExtract")``, :func:`peghole_mjx.geometry.parts.peg_parts` /
``hole_parts``, exact 16-gon pieces, Bullet's collision margin cut to 0.01 mm):

* ``hull``: the peg as one mesh file (all its pieces' triangles in one object), which
  PyBullet turns into one convex hull, as the seed stack did;
* ``compound``: the peg as the compound of its convex pieces (two 16-gon prisms and the
  bridge box), our approach.

The hole block is the same in both: its convex pieces (16 wedges and a floor per hole) as
static bodies. Each run places the peg inserted at the env's start pose (tip 0.5 mm above the
hole bottom, no initial error), records the contacts there (deepest penetration, count, the
contact normal force of the first step), holds the start pose for ``--hold-s`` (a fixed
constraint capped at the impedance law's 60 N axial force limit) and records how far the peg
was pushed (whether it can be placed inserted at all), then pulls straight up at the scripted
method's 20 mm/s for the env's episode time (8 s) and records when the tip left the hole by
the env's success margin; ``extracted`` is that from the inserted start (the env's
success). Writes ``benchmarks/results/studies/seed_stack_dual_hull.json``.

Run: ``python -m benchmarks.studies.seed_stack_dual_hull`` (under a minute on one CPU core).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from benchmarks.common import (
    STUDIES_RESULTS,
    cpu_device,
    load_average,
    out_file,
    table,
    utc_now,
    versions_dict,
)
from peghole_mjx.envs import get_default_config
from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT
from peghole_mjx.geometry.parts import hole_parts, peg_parts, peg_tip_z_m
from peghole_mjx.geometry.specs import MM, DualSpec, get_preset

RESULTS = STUDIES_RESULTS / "seed_stack_dual_hull.json"
HOLE_XY_M = (0.6, 0.0)  # as the MJCF scene (any place on the floor would do)
#: Bullet's collision margin of every shape, m: its default (0.04 for a convex hull) would
#: inflate each piece far beyond the 0.05 mm radial clearance of dual-2
COLLISION_MARGIN_M = 1e-5
#: a peg "placed inserted": pushed less than this from the start pose while held there, mm
PLACED_TOL_MM = 1.0
#: the quat (x, y, z, w) of TOOL_DOWN_MAT = diag(-1, 1, -1): a half turn about y
PEG_DOWN_QUAT = (0.0, 1.0, 0.0, 0.0)
assert np.allclose(np.diag(TOOL_DOWN_MAT), (-1.0, 1.0, -1.0))


def _write_obj(path: Path, pieces: list[np.ndarray]) -> Path:
    """One OBJ object holding the triangulated convex hull of each vertex set."""
    lines, base = [], 1
    for verts in pieces:
        hull = ConvexHull(verts)
        lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in verts]
        lines += [f"f {a + base} {b + base} {c + base}" for a, b, c in hull.simplices]
        base += len(verts)
    path.write_text("\n".join(lines) + "\n")
    return path


def _xyzw(q_wxyz: np.ndarray) -> list[float]:
    w, x, y, z = (float(v) for v in q_wxyz)
    return [x, y, z, w]


class DualWorld:
    """One PyBullet world: the dual hole block and the peg (``hull`` or ``compound``)."""

    def __init__(self, peg_model: str, env: str = "DualExtract"):
        import pybullet as p

        if peg_model not in ("hull", "compound"):
            raise ValueError(f"peg_model is 'hull' or 'compound', not {peg_model!r}")
        self.p, self.model = p, peg_model
        self.c = get_default_config(env)
        self.spec = get_preset(self.c.preset)
        if not isinstance(self.spec, DualSpec):
            raise ValueError(f"{env} is not a dual peg-hole env")
        self.cid = p.connect(p.DIRECT)
        kw = self.kw = {"physicsClientId": self.cid}
        self._tmp = tempfile.TemporaryDirectory(prefix="peghole_dual_")
        tmp = Path(self._tmp.name)
        p.setGravity(0, 0, -9.81, **kw)
        p.setPhysicsEngineParameter(fixedTimeStep=float(self.c.sim_dt), numSubSteps=0, **kw)
        depth = self.spec.hole_depth_mm * MM
        self.top_z = depth + self.spec.floor_mm * MM
        self.hole_pos = np.array([HOLE_XY_M[0], HOLE_XY_M[1], self.top_z])
        self.hole_ids = []
        meshes: dict[str, int] = {}
        for i, part in enumerate(hole_parts(self.spec, representation="mesh")):
            if part.kind == "box":
                shape = p.createCollisionShape(
                    p.GEOM_BOX, halfExtents=[float(v) for v in part.half_size], **kw
                )
            else:
                key = part.mesh or part.name
                if key not in meshes:
                    obj = _write_obj(tmp / f"hole_{i}.obj", [part.local_corners()])
                    meshes[key] = p.createCollisionShape(p.GEOM_MESH, fileName=str(obj), **kw)
                shape = meshes[key]
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                basePosition=(self.hole_pos + part.pos).tolist(),
                baseOrientation=_xyzw(part.quat),
                **kw,
            )
            p.changeDynamics(
                body,
                -1,
                lateralFriction=self.spec.friction,
                collisionMargin=COLLISION_MARGIN_M,
                **kw,
            )
            self.hole_ids.append(body)
        pieces = peg_parts(self.spec, representation="mesh")
        self.hull_volume_m3 = float(peg_parts(self.spec, single_hull=True)[0].volume)
        self.compound_volume_m3 = float(sum(pc.volume for pc in pieces))
        if peg_model == "hull":  # one mesh file, one object: PyBullet collides its hull
            obj = _write_obj(tmp / "peg.obj", [pc.corners() for pc in pieces])
            shape = p.createCollisionShape(p.GEOM_MESH, fileName=str(obj), **kw)
        else:  # one convex shape per piece
            files, types, halves, poss, orns = [], [], [], [], []
            for k, pc in enumerate(pieces):
                if pc.kind == "box":
                    types.append(p.GEOM_BOX)
                    halves.append([float(v) for v in pc.half_size])
                    files.append("")
                else:
                    types.append(p.GEOM_MESH)
                    halves.append([0.0, 0.0, 0.0])
                    files.append(str(_write_obj(tmp / f"peg_{k}.obj", [pc.local_corners()])))
                poss.append([float(v) for v in pc.pos])
                orns.append(_xyzw(pc.quat))
            shape = p.createCollisionShapeArray(
                shapeTypes=types,
                halfExtents=halves,
                fileNames=files,
                collisionFramePositions=poss,
                collisionFrameOrientations=orns,
                **kw,
            )
        self.tip_z = peg_tip_z_m(self.spec)
        # start pose: tip 0.5 mm above the hole bottom (the env's reset), peg axis vertical
        self.depth0_mm = self.spec.hole_depth_mm - 0.5
        tip0 = self.hole_pos - np.array([0.0, 0.0, self.depth0_mm * MM])
        self.start = tip0 + np.array([0.0, 0.0, self.tip_z])  # peg frame origin (mount)
        self.peg = p.createMultiBody(
            baseMass=float(self.spec.peg_mass_kg),
            baseCollisionShapeIndex=shape,
            basePosition=self.start.tolist(),
            baseOrientation=list(PEG_DOWN_QUAT),
            baseInertialFramePosition=[0.0, 0.0, 0.5 * self.tip_z],
            **kw,
        )
        p.changeDynamics(
            self.peg,
            -1,
            lateralFriction=1.0,
            linearDamping=0.0,
            collisionMargin=COLLISION_MARGIN_M,
            **kw,
        )
        self.hold = p.createConstraint(
            self.peg,
            -1,
            -1,
            -1,
            p.JOINT_FIXED,
            [0, 0, 0],
            [0, 0, 0],
            self.start.tolist(),
            childFrameOrientation=list(PEG_DOWN_QUAT),
            **kw,
        )
        self.max_force_N = float(self.c.limits.max_force_N[2])
        p.changeConstraint(self.hold, maxForce=self.max_force_N, **kw)

    def close(self) -> None:
        self.p.disconnect(self.cid)
        self._tmp.cleanup()

    def contacts(self) -> tuple[float, int, float]:
        """Deepest penetration (mm, >= 0), contact count, summed normal force (N)."""
        pts = [
            c
            for h in self.hole_ids
            for c in self.p.getContactPoints(self.peg, h, physicsClientId=self.cid)
        ]
        pen = max((-c[8] for c in pts), default=0.0)
        return max(pen, 0.0) / MM, len(pts), float(sum(c[9] for c in pts))

    def origin(self) -> np.ndarray:
        return np.array(self.p.getBasePositionAndOrientation(self.peg, **self.kw)[0])

    def tip_depth_mm(self) -> float:
        """Depth of the peg tip below the hole mouth (negative: above it), mm."""
        tip = self.origin() - np.array([0.0, 0.0, self.tip_z])
        return float((self.top_z - tip[2]) / MM)

    def run(self, hold_s: float, pull_speed_m_s: float, pull_s: float | None = None) -> dict:
        """Contacts at the start pose, the hold, then the straight pull (``pull_s``, default
        the env's episode time); the run's record."""
        p, kw = self.p, self.kw
        p.performCollisionDetection(**kw)
        pen0, n0, _ = self.contacts()
        dt = float(self.c.sim_dt)
        p.stepSimulation(**kw)
        _, _, f_first = self.contacts()
        peak_f, peak_pen = f_first, pen0
        for _ in range(round(hold_s / dt) - 1):
            p.stepSimulation(**kw)
            pen, _, f = self.contacts()
            peak_f, peak_pen = max(peak_f, f), max(peak_pen, pen)
        moved_mm = float(np.linalg.norm(self.origin() - self.start) / MM)
        placed = moved_mm < PLACED_TOL_MM
        depth_hold = self.tip_depth_mm()
        if pull_s is None:
            pull_s = float(self.c.episode_length * self.c.ctrl_dt)
        target = self.start.copy()
        out_at = None
        min_depth = depth_hold
        for k in range(round(pull_s / dt)):
            target[2] += pull_speed_m_s * dt
            p.changeConstraint(
                self.hold, jointChildPivot=target.tolist(), maxForce=self.max_force_N, **kw
            )
            p.stepSimulation(**kw)
            d = self.tip_depth_mm()
            min_depth = min(min_depth, d)
            if out_at is None and d < -self.c.success_margin_mm:
                out_at = (k + 1) * dt
        return {
            "peg_model": self.model,
            "peg_collision_volume_cm3": round(
                (self.hull_volume_m3 if self.model == "hull" else self.compound_volume_m3) * 1e6,
                2,
            ),
            "start_penetration_mm": round(pen0, 3),
            "start_contacts": n0,
            "first_step_normal_force_N": round(f_first, 2),
            "hold_peak_normal_force_N": round(peak_f, 2),
            "hold_peak_penetration_mm": round(peak_pen, 3),
            "displacement_after_hold_mm": round(moved_mm, 3),
            "tip_depth_after_hold_mm": round(depth_hold, 2),
            "placed_inserted": placed,
            "pull_s": pull_s,
            "min_tip_depth_mm": round(min_depth, 2),
            "tip_depth_end_mm": round(self.tip_depth_mm(), 2),
            # the tip left the hole by the env's success margin (from wherever the hold left it)
            "tip_out_at_s": None if out_at is None else round(out_at, 3),
            # the env's success: that, from the inserted start pose
            "extracted": bool(placed and out_at is not None),
        }


def run_both(
    hold_s: float = 0.2, env: str = "DualExtract", pull_s: float | None = None
) -> list[dict]:
    """The hull run and the compound run (each in its own PyBullet world)."""
    runs = []
    for model in ("hull", "compound"):
        world = DualWorld(model, env)
        try:
            runs.append(world.run(hold_s, SCRIPTED_SPEED_M_S, pull_s))
        finally:
            world.close()
    return runs


@table("seed_stack_dual_hull")
def seed_stack_dual_hull_table() -> str:
    """The dual peg in PyBullet, one mesh (hull) vs convex pieces."""
    d = json.loads(RESULTS.read_text())
    names = {
        "hull": "one mesh (PyBullet's hull, the seed stack)",
        "compound": "compound of convex pieces (ours)",
    }
    lines = [
        "| peg model | collision volume cm^3 | penetration at the start pose mm | contact normal "
        "force, first step N | pushed off the start pose after the hold mm | placed inserted "
        "| tip out of the hole at s | extracted from the inserted start |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in d["runs"]:
        out = "-" if r["tip_out_at_s"] is None else f"{r['tip_out_at_s']:.2f}"
        lines.append(
            f"| {names[r['peg_model']]} | {r['peg_collision_volume_cm3']:.2f} | "
            f"{r['start_penetration_mm']:.2f} | {r['first_step_normal_force_N']:.0f} | "
            f"{r['displacement_after_hold_mm']:.2f} | {'yes' if r['placed_inserted'] else 'no'} "
            f"| {out} | {'yes' if r['extracted'] else 'no'} |"
        )
    lines.append("")
    lines.append(
        f"{d['device']}; {d['date'][:10]}; hold {d['hold_s']:g} s; `{d['command'].strip()}`."
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hold-s", type=float, default=0.2, help="hold at the start pose, s")
    ap.add_argument("--note", default="")
    ap.add_argument("--out", type=out_file, default=RESULTS)
    args = ap.parse_args(argv)
    load0 = load_average()
    runs = run_both(args.hold_s)
    c = get_default_config("DualExtract")
    result = {
        "benchmark": "dual peg in PyBullet: one mesh (convex hull) vs the compound of its pieces",
        "env": "DualExtract",
        "preset": c.preset,
        "device": cpu_device(),
        "versions": versions_dict(),
        "date": utc_now(),
        "command": "python -m benchmarks.studies.seed_stack_dual_hull " + " ".join(sys.argv[1:]),
        "note": args.note,
        "load_average_before": load0,
        "load_average_after": load_average(),
        "hold_s": args.hold_s,
        "placed_tolerance_mm": PLACED_TOL_MM,
        "runs": runs,
    }
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    for r in runs:
        print(json.dumps(r))
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
