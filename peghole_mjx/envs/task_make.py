"""Making a task folder: meshes -> convex pieces -> checks -> contact cap -> folder.

``peghole task make PEG HOLE`` (a user's meshes: a part that is an extrusion along +z cut
into its exact convex pieces, :mod:`peghole_mjx.geometry.extrusion`; a round pair whose exact
pieces exceed the cap, or a tapered one, as N-gons with N set by the clearance,
:mod:`peghole_mjx.geometry.revolve`; any other decomposed by CoACD) and ``peghole task builtin
NAME`` (the built-in parts of :mod:`peghole_mjx.geometry.shapes`, exact pieces) run one
pipeline, :func:`build_task`:

1. the output folder checked (a new folder, or a task folder to replace that holds only the
   program's files: :func:`peghole_mjx.files.fileio.check_replaceable`, made with the same
   parameters unless ``force``: :func:`peghole_mjx.files.fileio.check_same_parameters`; no link
   loop, a name that fits with the temporary names beside it) and its lock taken
   (:class:`peghole_mjx.files.lock.OutputLock`: one writer per task folder) before any work;
2. the meshes checked as a peg in its hole (:func:`~peghole_mjx.geometry.decompose.
   check_assembly`: sizes, two parts, the peg inside the hole, no overlap, no undercut along
   +z; :func:`~peghole_mjx.geometry.task_check.check_blind_hole`: a bottom under the peg)
   and their radial clearance measured;
3. the convex pieces (exact for an extrusion or a built-in, else CoACD's, whose pieces and
   time are estimated first and refused up front past the caps:
   :mod:`peghole_mjx.geometry.coacd_budget`) checked against the caps (pieces per part,
   vertices per piece, contact pairs);
4. the frames, start pose, clearance, extraction sweep, drop test and hull intrusion
   (:func:`~peghole_mjx.geometry.task_check.place_and_check`);
5. the folder written to a temporary sibling, the MeshExtract env built from it on the
   ``mujoco`` engine and its contacts counted under the scripted and a random policy
   (:func:`~peghole_mjx.envs.contacts.max_active_contacts`, as the presets' caps were
   measured); more than ``max_contacts`` is refused, the cap set above the maximum;
6. the final files (with the cap) hashed into ``manifest.json`` and the temporary folder
   renamed onto the output (:func:`peghole_mjx.files.fileio.replace_dir`).

Any failure removes the temporary folder: nothing half-written is left.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from peghole_mjx import __version__
from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import check, dumps
from peghole_mjx.envs import rollout
from peghole_mjx.envs.config import sim_options
from peghole_mjx.envs.contacts import max_active_contacts
from peghole_mjx.envs.mesh_extract import MeshExtract, default_config
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import OutputLock
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry import coacd_budget
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.decompose import (
    CoacdParams,
    check_assembly,
    estimate_radial_clearance_mm,
    load_mesh,
    run_coacd,
)
from peghole_mjx.geometry.extrusion import exact_pieces
from peghole_mjx.geometry.mjcf import build_scene
from peghole_mjx.geometry.revolve import revolved_pair
from peghole_mjx.geometry.shapes import builtin_parts
from peghole_mjx.geometry.task_check import TaskGeometry, check_blind_hole, place_and_check
from peghole_mjx.sim import free

#: the peg's density when no mass is given (kg/m^3; printed PLA, as ``models decompose``)
PEG_DENSITY_KG_M3 = 1200.0
#: the contact cap set above the measured maximum: + max(4, a quarter of it)
CAP_MARGIN = 0.25
#: a task folder's size besides its meshes (bytes): hulls as text, the scene, the reports
FOLDER_BYTES = 4 << 20


@dataclass(frozen=True)
class TaskCaps:
    """What a task may hold: convex pieces per part, vertices per piece, active contacts."""

    max_hulls: int = tf.MAX_HULLS
    max_hull_vertices: int = tf.MAX_HULL_VERTICES
    max_contacts: int = tf.MAX_CONTACTS

    def __post_init__(self):
        check("max_hulls", self.max_hulls, "--max-hulls")
        check("max_hull_vertices", self.max_hull_vertices, "--max-ch-vertex")
        check("max_contacts", self.max_contacts, "--max-contacts")


@dataclass(frozen=True)
class ContactRun:
    """The rollouts that measure a task's contacts: worlds and env steps per policy."""

    worlds: int = 4
    env_steps: int = 200
    seed: int = 0

    def __post_init__(self):
        check("contact_worlds", self.worlds, "--contact-worlds")
        check("contact_steps", self.env_steps, "--contact-steps")


def _ancestor(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


#: the files of a task folder (a folder written before 2026-12-04 has no ownership manifest:
#: these are the names a new task may replace in it)
TASK_FOLDER_FILES = (*tf.FILES, tf.MANIFEST)


def check_out_task_dir(
    out: str | Path, extra_bytes: int = 0, parameters: dict | None = None, force: bool = False
) -> Path:
    """``out`` may receive a task folder: a new folder, an empty one or a task folder (which
    is replaced whole; with ``parameters``, only one made with the same unless ``force``);
    its nearest existing folder writable with room. Nothing is created."""
    out = Path(out)
    fileio.check_no_link_loop(out, "--out")
    fileio.check_name_length(out, "--out")
    if out.is_symlink():  # replaced whole at the end: refused before the work (2026-12-05)
        raise UserInputError(
            f"--out {out} is a symbolic link (to {os.readlink(out)}): a task folder is "
            "written whole and never replaces a link; give the folder's own path"
        )
    if out.exists():
        if not out.is_dir():
            raise UserInputError(f"--out {out} is an existing file, not a folder")
        if any(out.iterdir()) and not (out / tf.MANIFEST).is_file():
            raise UserInputError(
                f"--out {out} holds other files: give a new folder (a task folder is replaced)"
            )
        # a task folder is replaced only when every file in it is the program's (2026-12-04)
        fileio.check_replaceable(out, TASK_FOLDER_FILES)
        if parameters is not None:  # a rerun of other parameters (2026-12-05)
            fileio.check_same_parameters(out, parameters, force)
    base = _ancestor(out.parent)
    if not base.is_dir() or not os.access(base, os.W_OK | os.X_OK):
        raise UserInputError(f"--out {out}: {base} is not a writable folder")
    fileio.check_room(base, FOLDER_BYTES + extra_bytes)
    return out


@contextlib.contextmanager
def _temporary_sibling(out: Path):
    """A temporary folder beside ``out`` (its parents created); removed, with the parents it
    created, unless it was renamed onto ``out``."""
    created = []
    p = out.absolute().parent
    while not p.exists():
        created.append(p)
        p = p.parent
    for q in reversed(created):
        q.mkdir()
    tmp = fileio.temp_dir_beside(out)  # a unique new name: never a folder of the user's
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for q in created:  # innermost first; only if still empty
            with contextlib.suppress(OSError):
                q.rmdir()
        raise


def _spec(
    g: TaskGeometry,
    name: str,
    friction: float,
    radial_mm: float,
    face_vertices: int,
    measured: int = 0,
    cap: int = 0,
    folder: str = "",
) -> tf.TaskSpec:
    return tf.TaskSpec(
        name=name,
        peg_hulls=tuple(g.peg_hulls),
        hole_hulls=tuple(g.hole_hulls),
        length_mm=g.length_mm,
        hole_depth_mm=g.rest_depth_mm,
        start_depth_mm=g.start_depth_mm,
        floor_mm=g.floor_mm,
        friction=friction,
        peg_mass_kg=g.peg_mass_kg,
        clearance_mm=g.effective_min_mm,
        radial_clearance_mm=radial_mm,
        contact_measured_max=measured,
        contact_cap=cap,
        max_face_vertices=face_vertices,
        folder=folder,
    )


def _task_doc(
    name: str,
    source: dict[str, Any],
    g: TaskGeometry,
    friction: float,
    radial_mm: float,
    caps: TaskCaps,
    face_vertices: int,
    contacts: dict[str, Any],
    timing: dict[str, float],
    exact: bool,
) -> dict[str, Any]:
    peg_v = max(len(h) for h in g.peg_hulls)
    hole_v = max(len(h) for h in g.hole_hulls)
    return {
        "name": name,
        "source": source,
        "frames": {
            "hole": "origin at the mouth on the peg's axis (x, y of the tip point at the start "
            "pose, z of the hole part's top), +z the extraction direction, metres",
            "peg": "origin at the mount (top, above the tip point), +z from the mount to the "
            "tip, x along the hole frame's -x, metres; the tip at (0, 0, length)",
        },
        "peg": {
            "hulls": len(g.peg_hulls),
            "hull_vertices_max": peg_v,
            "mass_kg": g.peg_mass_kg,
            "length_mm": g.length_mm,
        },
        "hole": {"hulls": len(g.hole_hulls), "hull_vertices_max": hole_v, "floor_mm": g.floor_mm},
        "poses": {
            "start_depth_mm": g.start_depth_mm,
            "rest_depth_mm": g.rest_depth_mm,
            "centring_mm": list(g.centring_mm),
            "why": "start pose: the peg centred in its clearance, its tip 0.5 mm above the "
            "bottom (tip_gap_mm, as the presets)",
        },
        "success": "the env's success_margin_mm above the mouth: the tip is the peg's lowest "
        "point and the mouth the hole part's top, so the peg is then clear of the hole part",
        "friction": friction,
        "caps": {
            **asdict(caps),
            "max_pairs": tf.MAX_PAIRS,
            "max_face_vertices": face_vertices,
            "mjx_max_face_vertices": tf.MJX_MAX_FACE_VERTICES,
            "engines": ["mujoco", "mjx"]
            if face_vertices <= tf.MJX_MAX_FACE_VERTICES
            else ["mujoco"],
        },
        "contacts": {"pairs": len(g.peg_hulls) * len(g.hole_hulls), **contacts},
        "checks": {
            "clearance": {
                "radial_mm": radial_mm,
                "effective_min_mm": g.effective_min_mm,
                "effective_max_mm": g.effective_max_mm,
                "how": "radial: the meshes' smallest gap beside the peg; effective: the "
                "pieces' diametral free travel at the start pose, 8 directions both ways "
                "(MuJoCo distance queries)",
                "start_gap_mm": g.start_gap_mm,
            },
            "extraction_sweep": {
                "passed": True,
                "min_gap_mm": g.sweep_min_gap_mm,
                "steps": g.sweep_steps,
            },
            "drop_test": {"passed": True, "gap_mm": g.drop_gap_mm, "engine": "mujoco"},
            "hull_intrusion": {
                "pieces": "exact" if exact else source.get("pieces", "CoACD"),
                "peg_excess_mm": g.excess_peg_mm,
                "hole_excess_mm": g.excess_hole_mm,
                "warnings": g.warnings,
            },
        },
        "timing_s": timing,
        "made": provenance(),
    }


def build_task(
    peg_mesh,
    hole_mesh,
    peg_hulls,
    hole_hulls,
    out: str | Path,
    *,
    name: str,
    source: dict[str, Any],
    exact: bool,
    friction: float = 0.266,
    peg_mass_kg: float | None = None,
    caps: TaskCaps = TaskCaps(),
    contacts: ContactRun = ContactRun(),
    progress: bool = False,
    t0: float | None = None,
    parameters: dict | None = None,
) -> dict[str, Any]:
    """Steps 2-6 of the module docstring for meshes and pieces in metres (assembled pose),
    the meshes already checked as a peg in its hole (``check_assembly``); returns
    ``task.json``'s content. ``parameters``: what the task is made of and with, recorded in
    the folder's ownership manifest; the caller holds the output's lock and has checked the
    folder's parameters under it (``check_out_task_dir``)."""
    t0 = time.perf_counter() if t0 is None else t0
    out = Path(out)
    friction = check("friction", friction)
    tf.check_caps(
        len(peg_hulls),
        len(hole_hulls),
        max(len(h) for h in (*peg_hulls, *hole_hulls)),
        caps.max_hulls,
        caps.max_hull_vertices,
    )
    radial = estimate_radial_clearance_mm(peg_mesh, hole_mesh)
    if radial <= 0:
        raise UserInputError(
            f"radial clearance {radial:.4f} mm: the peg touches or overlaps the hole in the "
            "assembled pose"
        )
    mass = (
        check("peg_mass_kg", peg_mass_kg, kind="mass_kg")
        if peg_mass_kg is not None
        else PEG_DENSITY_KG_M3 * float(peg_mesh.volume)
    )
    config = default_config()
    sim = sim_options(config)  # the env's contact settings
    t1 = time.perf_counter()
    with prog.phase("checking the pieces (start pose, clearance, sweep, drop)", enabled=progress):
        g = place_and_check(
            peg_mesh,
            hole_mesh,
            list(peg_hulls),
            list(hole_hulls),
            friction=friction,
            peg_mass_kg=mass,
            radial_clearance_mm=radial,
            run_passive=free.run_passive,
            sim=sim,
        )
        if exact:
            g.warnings.clear()  # the pieces are the part: a sampled excess is the sampling's
    face_vertices = tf.max_face_vertices([*g.peg_hulls, *g.hole_hulls])
    t2 = time.perf_counter()
    meshes = {
        tf.PEG_MESH: g.peg_mesh.export(file_type="stl"),
        tf.HOLE_MESH: g.hole_mesh.export(file_type="stl"),
        tf.PEG_HULLS: tf.hulls_json(g.peg_hulls, "peg").encode(),
        tf.HOLE_HULLS: tf.hulls_json(g.hole_hulls, "hole").encode(),
    }
    # the folder's parameters were checked under the lock the caller holds: here its room
    check_out_task_dir(out, sum(len(v) for v in meshes.values()))

    def files(measured: int, cap: int, counts: dict, timing: dict) -> dict[str, bytes]:
        spec = _spec(g, name, friction, radial, face_vertices, measured, cap)
        scene = build_scene(spec, sim=sim, contact_cap=cap)
        scene.compile()
        doc = _task_doc(
            name, source, g, friction, radial, caps, face_vertices, counts, timing, exact
        )
        return {
            **meshes,
            tf.SCENE: scene.to_xml().encode(),
            tf.TASK_FILE: (dumps(doc, indent=2) + "\n").encode(),
        }

    def write(folder: Path, contents: dict[str, bytes]) -> None:
        for fname, data in contents.items():
            (folder / fname).write_bytes(data)
        (folder / tf.MANIFEST).write_text(tf.manifest_json(contents, __version__))

    with _temporary_sibling(out) as tmp:
        write(tmp, files(0, 0, {"measured_max": 0, "cap": 0}, {}))
        with prog.phase("building the MeshExtract env (mujoco engine)", enabled=progress):
            env = MeshExtract(config, {"task": str(tmp), "engine": "mujoco"})
        runs = {}
        for policy_name, policy in (
            ("scripted", rollout.scripted_policy(env)),
            ("random", rollout.random_policy(env)),
        ):
            with prog.phase(f"counting contacts, {policy_name} policy", enabled=progress):
                runs[policy_name] = max_active_contacts(
                    env, policy, contacts.worlds, contacts.env_steps, contacts.seed,
                    replays=policy_name == "scripted",  # a constant action (2026-12-05)
                )  # fmt: skip
        measured = max(r["max_active"] for r in runs.values())
        if measured > caps.max_contacts:
            raise UserInputError(
                f"{measured} active peg-hole contacts measured, more than the cap of "
                f"{caps.max_contacts} (--max-contacts): decompose the parts more coarsely"
            )
        cap = measured + max(4, math.ceil(CAP_MARGIN * measured))
        t3 = time.perf_counter()
        counts = {
            "measured_max": measured,
            "cap": cap,
            "how": "most active contacts (distance <= 0) after any physics step, MuJoCo C, "
            "the scripted and a random policy, finished worlds restarted (the scripted run "
            "ends once every world has ended an episode: a restart replays it); cap = max + "
            f"max(4, {CAP_MARGIN:g} max)",
            "worlds": contacts.worlds,
            "env_steps_per_policy": contacts.env_steps,
            "per_policy": runs,
        }
        timing = {
            "meshes_and_pieces": round(t1 - t0, 2),
            "checks": round(t2 - t1, 2),
            "contacts": round(t3 - t2, 2),
        }
        timing["total"] = round(time.perf_counter() - t0, 2)
        final = files(measured, cap, counts, timing)
        for stale in (tf.SCENE, tf.TASK_FILE, tf.MANIFEST):
            (tmp / stale).unlink()
        write(tmp, final)
        fileio.replace_dir(tmp, out, known=TASK_FOLDER_FILES, parameters=parameters)
    return tf.read_task_json(out)


#: ``--pieces`` of ``task make``: exact pieces where a part is an extrusion (or both parts are
#: revolved), else CoACD's; ``revolve``: the revolution N-gons or a refusal (2026-12-05)
PIECES = ("auto", "exact", "revolve", "coacd")
#: the ``--pieces`` that try a part's exact extrusion pieces
EXACT_TRIED = ("auto", "exact")
EXACT = "exact extrusion"
COACD = "CoACD"


def _part_pieces(
    label: str,
    mesh,
    params: CoacdParams,
    pieces: str,
    progress: bool,
    max_hulls: int,
    exact=None,
    coacd_max_s: float = coacd_budget.COACD_MAX_S,
    clearance: float | None = None,
    estimate_s: float = coacd_budget.ESTIMATE_S,
) -> tuple[list | None, dict[str, Any]]:
    """One part's convex pieces and the record of how they were made (``task.json``'s
    ``source.decomposition``); ``exact``: :func:`exact_pieces` of ``mesh`` if already made.
    A part for CoACD is estimated in at most ``estimate_s`` and refused when it exceeds
    ``max_hulls`` or ``coacd_max_s`` (:mod:`peghole_mjx.geometry.coacd_budget`); its hulls
    are None then, made by :func:`_run_coacd` once every part passed."""
    if pieces != "coacd":
        exact = exact_pieces(mesh) if exact is None else exact
        if not isinstance(exact, str):
            if len(exact.hulls) > max_hulls:
                raise UserInputError(
                    f"the {label} part is an extrusion whose exact convex pieces number "
                    f"{len(exact.hulls)}, more than the cap of {max_hulls} (--max-hulls): a "
                    "cavity of n edges needs n pieces; export round features with fewer "
                    "facets, or use --pieces coacd"
                )
            return exact.hulls, exact.record
        if pieces == "exact":
            raise UserInputError(
                f"--pieces exact: the {label} part is not an extrusion along +z ({exact}); "
                "use --pieces auto (CoACD for it)"
            )
        why = f"not an extrusion along +z: {exact}"
    else:
        why = "--pieces coacd"
    # bounded (2026-12-05, geometry/coacd_budget.py): estimated in seconds, refused up front;
    # the run itself is the caller's, once every part's estimate passed (_run_coacd)
    with prog.phase(f"estimating CoACD on the {label} part (a coarse run)", enabled=progress):
        est = coacd_budget.estimate(mesh, params, estimate_s, run_coacd)
    refused = coacd_budget.refusal(label, est, params, mesh, max_hulls, coacd_max_s, clearance)
    if refused:
        raise UserInputError(refused)
    estimate = {"pieces": est.pieces, "seconds": round(est.seconds, 1), "complete": est.complete}
    return None, {"method": COACD, "why": why, "estimate": estimate, "_est": est}


def _run_coacd(label, mesh, params, record, max_hulls, coacd_max_s, progress) -> list:
    """The CoACD run of a part whose estimate (``record["_est"]``) passed."""
    est = record.pop("_est")
    hulls = coacd_budget.run_bounded(
        mesh, params, est, label, coacd_max_s, progress, run_coacd, max_hulls
    )
    record["pieces"] = len(hulls)
    return hulls


def make_task(
    peg_path: str | Path,
    hole_path: str | Path,
    out: str | Path,
    *,
    units: str = "mm",
    params: CoacdParams | None = None,
    friction: float = 0.266,
    peg_mass_kg: float | None = None,
    caps: TaskCaps = TaskCaps(),
    contacts: ContactRun = ContactRun(),
    progress: bool = False,
    pieces: str = "auto",
    force: bool = False,
    coacd_max_s: float = coacd_budget.COACD_MAX_S,
) -> dict[str, Any]:
    """``peghole task make``: a user's peg and hole meshes (assembled pose, +z extraction)
    decomposed, then :func:`build_task`. ``pieces`` (:data:`PIECES`): ``auto`` takes the
    exact pieces of a part that is an extrusion along +z
    (:mod:`peghole_mjx.geometry.extrusion`); when those do not fit the cap (or a part is no
    extrusion) and both parts are revolved about +z, their N-gon pieces
    (:func:`~peghole_mjx.geometry.revolve.revolved_pair`); CoACD's for any other part;
    ``exact`` refuses a part that is not an extrusion; ``revolve`` takes the N-gon pieces of
    a pair revolved about +z and refuses any other; ``coacd`` runs CoACD on both. CoACD is
    estimated first and refused up front past the piece cap or ``coacd_max_s`` seconds a part.
    ``force``: replace a task folder made with other parameters."""
    t0 = time.perf_counter()
    params = params or CoacdParams()
    if pieces not in PIECES:
        raise UserInputError(f"unknown --pieces {pieces!r}; choose one of {list(PIECES)}")
    coacd_max_s = check("coacd_max_s", coacd_max_s, "--coacd-max-s")
    check_out_task_dir(out)
    peg = load_mesh(peg_path, units)
    hole = load_mesh(hole_path, units)
    parameters = {
        "command": "task make",
        "peg_mesh_sha256": fileio.sha256_file(peg_path),
        "hole_mesh_sha256": fileio.sha256_file(hole_path),
        "units": units,
        "pieces": pieces,
        "coacd": asdict(params),
        **_shared_parameters(friction, peg_mass_kg, caps, contacts),
    }
    # one writer per task folder (2026-12-05), taken before the decomposition
    with OutputLock(out, "peghole task make"):
        check_out_task_dir(out, 0, parameters, force)
        check_assembly(peg, hole, units)  # before the decomposition
        check_blind_hole(peg, hole)
        hulls, records = {}, {}
        meshes = {"peg": peg, "hole": hole}
        exact_made = (
            {k: exact_pieces(m) for k, m in meshes.items()} if pieces in EXACT_TRIED else {}
        )
        revolved = None
        fits = all(
            not isinstance(e, str) and len(e.hulls) <= caps.max_hulls for e in exact_made.values()
        )
        # the clearance sizes the N-gons and words a CoACD refusal: measured when needed
        radial = None if fits and exact_made else estimate_radial_clearance_mm(peg, hole)
        if pieces == "revolve" or (pieces == "auto" and not fits):
            # round parts (a fine M-gon export, a cone): N-gons sized by the clearance (2026-12-04)
            revolved = revolved_pair(peg, hole, radial, caps.max_hulls)
            if pieces == "revolve" and isinstance(revolved, str):
                raise UserInputError(
                    f"--pieces revolve: the pair is not revolved about +z ({revolved}); use "
                    "--pieces auto"
                )
        if revolved is not None and not isinstance(revolved, str):
            hulls = {"peg": revolved.peg_hulls, "hole": revolved.hole_hulls}
            records = revolved.records
        else:
            # the parts' CoACD estimates all come first: a verdict within 30 s (issue 54)
            coacd_parts = sum(
                pieces == "coacd" or isinstance(exact_made.get(k), str) for k in meshes
            )
            # counted from the command's start where there is one (its imports included)
            began = t0 if prog.command_start() is None else prog.command_start()
            estimate_s = coacd_budget.estimate_budget(time.perf_counter() - began, coacd_parts)
            for label, mesh in meshes.items():
                hulls[label], records[label] = _part_pieces(
                    label, mesh, params, pieces, progress, caps.max_hulls, exact_made.get(label),
                    coacd_max_s, radial, estimate_s,
                )  # fmt: skip
                if revolved is not None:
                    records[label]["not_revolved"] = revolved
            for label, mesh in meshes.items():
                if hulls[label] is None:
                    hulls[label] = _run_coacd(
                        label, mesh, params, records[label], caps.max_hulls, coacd_max_s,
                        progress,
                    )  # fmt: skip
        methods = {r["method"] for r in records.values()}
        source = {
            "kind": "meshes",
            "peg_mesh": str(Path(peg_path).name),
            "hole_mesh": str(Path(hole_path).name),
            "peg_mesh_sha256": parameters["peg_mesh_sha256"],
            "hole_mesh_sha256": parameters["hole_mesh_sha256"],
            "units": units,
            "pieces": " + ".join(sorted(methods)) if len(methods) > 1 else methods.pop(),
            "decomposition": records,
        }
        if any(r["method"] == COACD for r in records.values()):
            source["coacd"] = asdict(params)
        exact = all(r["method"] == EXACT for r in records.values())
        return build_task(
            peg,
            hole,
            hulls["peg"],
            hulls["hole"],
            out,
            name=Path(peg_path).stem,
            source=source,
            exact=exact,
            friction=friction,
            peg_mass_kg=peg_mass_kg,
            caps=caps,
            contacts=contacts,
            progress=progress,
            t0=t0,
            parameters=parameters,
        )


def _shared_parameters(friction, peg_mass_kg, caps: TaskCaps, contacts: ContactRun) -> dict:
    return {
        "friction": friction,
        "peg_mass_kg": peg_mass_kg,
        "caps": asdict(caps),
        "contacts": asdict(contacts),
    }


def make_builtin(
    name: str,
    clearance_mm: float,
    out: str | Path,
    *,
    friction: float = 0.266,
    peg_mass_kg: float | None = None,
    caps: TaskCaps = TaskCaps(),
    contacts: ContactRun = ContactRun(),
    progress: bool = False,
    force: bool = False,
) -> dict[str, Any]:
    """``peghole task builtin``: a built-in part (:mod:`peghole_mjx.geometry.shapes`), its
    exact pieces, then :func:`build_task`. ``force``: replace a task folder made with other
    parameters."""
    t0 = time.perf_counter()
    check_out_task_dir(out)
    parameters = {
        "command": "task builtin",
        "builtin": name,
        "clearance_mm": clearance_mm,
        **_shared_parameters(friction, peg_mass_kg, caps, contacts),
    }
    with OutputLock(out, "peghole task builtin"):  # one writer per task folder (2026-12-05)
        check_out_task_dir(out, 0, parameters, force)
        parts = builtin_parts(name, clearance_mm)
        check_assembly(parts.peg_mesh, parts.hole_mesh)
        check_blind_hole(parts.peg_mesh, parts.hole_mesh)
        source = {
            "kind": "builtin",
            "builtin": name,
            "clearance_mm": parts.clearance_mm,
            "description": parts.description,
            "pieces": "exact",
        }
        return build_task(
            parts.peg_mesh,
            parts.hole_mesh,
            parts.peg_hulls,
            parts.hole_hulls,
            out,
            name=name,
            source=source,
            exact=True,
            friction=friction,
            peg_mass_kg=peg_mass_kg,
            caps=caps,
            contacts=contacts,
            progress=progress,
            t0=t0,
            parameters=parameters,
        )


__all__ = ["ContactRun", "TaskCaps", "build_task", "make_builtin", "make_task"]
