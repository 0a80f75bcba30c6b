"""Task folders (peghole task make | builtin | show) and the MeshExtract env that reads them.

One built-in task (the hexagonal peg, the fewest pieces: 1 x 7) is made once for the module at
a short contact count; the bad inputs run against copies of it or against tiny meshes. The
three documented commands for a user's own STL pair (task make -> train -> evaluate) run at
the smallest sizes. Skipped without the ``cad`` extra (CoACD, trimesh, manifold3d).
"""

import json
import shutil

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("coacd")
pytest.importorskip("manifold3d")

from peghole_mjx import envs  # noqa: E402
from peghole_mjx.cli.main import main  # noqa: E402
from peghole_mjx.core.errors import UserInputError  # noqa: E402
from peghole_mjx.core.validation import loads  # noqa: E402
from peghole_mjx.envs.rollout import rollout, scripted_policy  # noqa: E402
from peghole_mjx.envs.task_make import ContactRun, make_builtin  # noqa: E402
from peghole_mjx.geometry import task as tf  # noqa: E402
from peghole_mjx.geometry.shapes import BUILTINS, builtin_parts, offset_convex  # noqa: E402

#: the module's contact count: 2 worlds, 40 env steps per policy (a scripted pull ends in ~110)
SHORT = ContactRun(worlds=2, env_steps=40)


@pytest.fixture(scope="module")
def hex_task(tmp_path_factory):
    out = tmp_path_factory.mktemp("tasks") / "hex"
    doc = make_builtin("hex", 0.2, out, contacts=SHORT)
    return out, doc


@pytest.fixture(scope="module")
def hex_env(hex_task):
    return envs.load("MeshExtract", config_overrides={"task": str(hex_task[0]), "engine": "mujoco"})


def _leftovers(out) -> list[str]:
    """The output folder, or a temporary sibling of it, if any was left."""
    return sorted(p.name for p in out.parent.iterdir() if p.name.lstrip(".").startswith(out.name))


def _refused(argv, capsys, match: str) -> str:
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2, err
    assert err[-1].startswith("peghole: error: ") and match in err[-1], err[-1]
    return err[-1]


# ------------------------------------------------------------------ shapes and folder


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_parts_are_closed_solids_with_exact_convex_pieces(name):
    parts = builtin_parts(name, 0.1)
    assert parts.peg_mesh.is_watertight and parts.hole_mesh.is_watertight
    # the peg's pieces are the peg: their volumes add up to the mesh's
    vol = sum(trimesh.Trimesh(h).convex_hull.volume for h in parts.peg_hulls)
    assert vol == pytest.approx(parts.peg_mesh.volume, rel=1e-6)
    assert tf.max_face_vertices(parts.peg_hulls + parts.hole_hulls) <= tf.MJX_MAX_FACE_VERTICES


def test_offset_polygon_keeps_every_edge_parallel_at_the_distance():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    np.testing.assert_allclose(
        offset_convex(square, 0.1), [[-0.1, -0.1], [1.1, -0.1], [1.1, 1.1], [-0.1, 1.1]]
    )


def test_builtin_clearance_outside_its_range_is_refused(tmp_path, capsys):
    out = tmp_path / "t"
    with pytest.raises(SystemExit) as exc:  # argparse's one usage line
        main(["task", "builtin", "hex", "--clearance-mm", "0.5", "--out", str(out)])
    assert exc.value.code == 2 and "[0.1, 0.4]" in capsys.readouterr().err
    with pytest.raises(UserInputError, match=r"\[0.1, 0.4\]"):
        make_builtin("hex", 0.05, out)
    assert not out.exists()


def test_task_folder_round_trip(hex_task, capsys):
    out, doc = hex_task
    man = json.loads((out / tf.MANIFEST).read_text())
    assert man["format"] == tf.FORMAT and man["format_version"] == tf.FORMAT_VERSION
    assert sorted(man["files"]) == sorted(tf.FILES)
    from peghole_mjx.files.fileio import OWNER_MANIFEST

    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([*tf.FILES, tf.MANIFEST, OWNER_MANIFEST])
    spec = tf.load_task(out)
    assert len(spec.peg_hulls) == 1 and len(spec.hole_hulls) == 7
    assert spec.length_mm == pytest.approx(50.0, abs=1e-6)
    assert spec.start_depth_mm == pytest.approx(39.5, abs=1e-3)  # 0.5 mm above the bottom
    assert spec.hole_depth_mm == pytest.approx(40.0, abs=1e-3)
    # the hulls' free travel across the hexagon's flats is the clearance (0.2 mm)
    assert spec.clearance_mm == pytest.approx(0.2, abs=2e-3)
    assert doc["checks"]["clearance"]["radial_mm"] == pytest.approx(0.1, abs=1e-3)
    assert 1 <= spec.contact_measured_max < spec.contact_cap <= tf.MAX_CONTACTS + 16
    assert doc["contacts"]["cap"] == spec.contact_cap
    assert doc["caps"]["engines"] == ["mujoco", "mjx"]
    # the tip is on the hole axis: the peg's pieces centred about the peg frame's z axis
    verts = np.concatenate(spec.peg_hulls)
    np.testing.assert_allclose(verts[:, :2].mean(axis=0), 0.0, atol=1e-9)
    assert verts[:, 2].min() == pytest.approx(0.0, abs=1e-12)  # the mount
    assert main(["task", "show", str(out), "--json"]) == 0
    assert loads(capsys.readouterr().out) == doc


# ------------------------------------------------------------------ the env


def test_mesh_extract_steps_and_the_scripted_baseline_pulls_the_peg_out(hex_env, hex_task):
    """Reset at the start pose (tip 39.5 mm deep), a few steps, then the scripted Ch 2-3 pull:
    every episode extracted in about (39.5 + 5) mm / 20 mm/s = 2.2 s."""
    import jax
    import jax.numpy as jnp

    env = hex_env
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(1), 2))
    np.testing.assert_allclose(state.info["depth_mm"], 39.5, atol=0.05)
    step = jax.jit(jax.vmap(env.step))
    for _ in range(3):
        state = step(state, jnp.zeros((2, env.action_size)))
    assert state.obs.shape == (2, env.observation_size) and np.isfinite(state.obs).all()
    res = rollout(env, scripted_policy(env), 4, seed=0, progress=False).summary()
    assert res.success_rate == 1.0 and res.nan_worlds == 0 and res.overflow_worlds == 0
    assert 1.9 < res.mean_time_s < 2.8
    assert env.mj_model.npair == 7


def test_mesh_extract_config_is_the_shared_one_plus_its_task():
    """MeshExtract's config: every entry of the other envs' (so every number has its range in
    validation.RANGES), no preset, and ``task``; registered apart from ALL_ENVS."""
    from peghole_mjx.envs.config import leaves

    mesh = dict(leaves(envs.get_default_config("MeshExtract")))
    rect = dict(leaves(envs.get_default_config("RectExtract")))
    assert set(mesh) - set(rect) == {"task"} and set(rect) == set(mesh) - {"task"}
    assert mesh["task"] == "" and mesh["preset"] == ""
    assert envs.TASK_ENVS == ("MeshExtract",) and "MeshExtract" not in envs.ALL_ENVS
    assert set(envs.ENV_NAMES) == {*envs.ALL_ENVS, *envs.TASK_ENVS}


def test_task_entry_missing_or_absent_is_refused(tmp_path, capsys):
    with pytest.raises(UserInputError, match="needs a task folder"):
        envs.load("MeshExtract")
    missing = tmp_path / "nowhere"
    _refused(
        ["envs", "rollout", "--env", "MeshExtract", "--set", f"task={missing}", "--episodes", "1"],
        capsys,
        "not found",
    )
    with pytest.raises(UserInputError, match="unknown env config key 'task'"):
        envs.load("RectExtract", config_overrides={"task": str(missing)})


def test_a_task_env_takes_no_preset_geometry_or_other_representation(hex_task):
    task = str(hex_task[0])
    for over, match in (
        ({"preset": "rect-2"}, "leave preset and geometry empty"),
        ({"geometry": '{"peg_w_mm": 59.9}'}, "leave preset and geometry empty"),
        ({"representation": "box"}, "convex pieces"),
    ):
        with pytest.raises(UserInputError, match=match):
            envs.load("MeshExtract", config_overrides={"task": task, "engine": "mujoco", **over})


# ------------------------------------------------------------------ bad input


def _box(lo, hi):
    b = trimesh.creation.box(np.subtract(hi, lo))
    b.apply_translation(np.add(lo, hi) / 2)
    return b


def _write(folder, peg, hole):
    folder.mkdir(parents=True, exist_ok=True)
    peg.export(folder / "peg.stl")
    hole.export(folder / "hole.stl")
    return str(folder / "peg.stl"), str(folder / "hole.stl")


def _block_with(cavities):
    block = _box((-12, -12, -30), (12, 12, 0))
    return block.difference(trimesh.boolean.union(cavities) if len(cavities) > 1 else cavities[0])


@pytest.fixture(scope="module")
def user_pair(tmp_path_factory):
    """A user's own pair, not a built-in: a 10 x 10 mm square peg, 30 mm long, 25 mm deep in a
    12 x 12 mm hole (1 mm radial clearance)."""
    peg = _box((-5, -5, -25), (5, 5, 5))
    hole = _block_with([_box((-6, -6, -25), (6, 6, 1))])
    return _write(tmp_path_factory.mktemp("user") / "stl", peg, hole)


def test_bad_meshes_are_refused_in_one_line_with_nothing_written(tmp_path, capsys):
    peg = _box((-5, -5, -25), (5, 5, 5))
    cases = {
        # a box with a face missing: no inside
        "closed manifold solid": (
            trimesh.Trimesh(peg.vertices, peg.faces[:-2], process=False),
            _block_with([_box((-6, -6, -25), (6, 6, 1))]),
        ),
        # 13 x 13 mm in a 12 x 12 mm hole
        "no interference": (
            _box((-6.5, -6.5, -25), (6.5, 6.5, 5)),
            _block_with([_box((-6, -6, -25), (6, 6, 1))]),
        ),
        # a foot under a narrower mouth (a T-slot): it cannot come out along +z
        "extractable along +z": (
            trimesh.boolean.union(
                [_box((-2, -2, -12), (2, 2, 5)), _box((-5, -5, -24), (5, 5, -12))]
            ),
            _block_with([_box((-3, -3, -6), (3, 3, 1)), _box((-6, -6, -25), (6, 6, -6))]),
        ),
    }
    for i, (match, (p, h)) in enumerate(cases.items()):
        pe, ho = _write(tmp_path / f"in{i}", p, h)
        out = tmp_path / f"out{i}"
        _refused(["task", "make", pe, ho, "--out", str(out)], capsys, match)
        assert _leftovers(out) == [], match


def test_pieces_that_block_the_hole_are_refused():
    """The checks on the convex pieces (what the simulator collides), not the meshes: a piece
    in the clearance (hull intrusion) and one across the way out (the extraction sweep)."""
    from peghole_mjx.geometry.task_check import place_and_check
    from peghole_mjx.sim.free import run_passive

    parts = builtin_parts("hex", 0.2)
    mm = 1e-3

    def slab(x0, x1, z0, z1):
        return _box((x0, -20, z0), (x1, 20, z1)).vertices * mm

    kw = {"friction": 0.266, "peg_mass_kg": 0.02, "radial_clearance_mm": 0.1}
    kw["run_passive"] = run_passive
    for extra, match in (
        (slab(10.0, 10.15, -30, -20), "touch or overlap"),  # into the 0.1 mm gap beside a flat
        (slab(-20, 20, 12, 13), "not extractable along"),  # a lid over the peg's top (10 mm)
    ):
        with pytest.raises(UserInputError, match=match):
            place_and_check(
                parts.peg_mesh, parts.hole_mesh, parts.peg_hulls, [*parts.hole_hulls, extra], **kw
            )


def test_damaged_folders_are_refused(hex_task, tmp_path, capsys):
    src = hex_task[0]

    def copy(name):
        dst = tmp_path / name
        shutil.copytree(src, dst)
        return dst

    newer = copy("newer")
    man = json.loads((newer / tf.MANIFEST).read_text())
    (newer / tf.MANIFEST).write_text(json.dumps({**man, "format_version": 2}))
    missing = copy("missing")
    (missing / tf.PEG_HULLS).unlink()
    altered = copy("altered")
    text = (altered / tf.HOLE_HULLS).read_text()
    (altered / tf.HOLE_HULLS).write_text(text.replace("0.0", "0.1", 1))
    for folder, match in (
        (newer, "format version 2"),
        (missing, f"{tf.PEG_HULLS} is missing"),
        (altered, f"{tf.HOLE_HULLS} does not match its SHA-256"),
        (tmp_path, "not a task folder"),
    ):
        _refused(["task", "show", str(folder)], capsys, match)
        with pytest.raises(UserInputError, match=match):
            envs.load("MeshExtract", config_overrides={"task": str(folder), "engine": "mujoco"})


def test_more_pieces_or_contacts_than_the_caps_are_refused(tmp_path, capsys):
    out = tmp_path / "l"
    _refused(
        ["task", "builtin", "l_section", "--max-hulls", "4", "--out", str(out)],
        capsys,
        "the hole has 14 convex pieces, more than the cap of 4",
    )
    assert _leftovers(out) == []
    out = tmp_path / "h"
    argv = ["task", "builtin", "hex", "--out", str(out), "--max-contacts", "1"]
    argv += ["--contact-worlds", "2", "--contact-steps", "40"]
    _refused(argv, capsys, "more than the cap of 1 (--max-contacts)")
    assert _leftovers(out) == []


def test_out_holding_other_files_is_refused(tmp_path, capsys):
    (tmp_path / "keep.txt").write_text("mine")
    _refused(["task", "builtin", "hex", "--out", str(tmp_path)], capsys, "holds other files")
    assert (tmp_path / "keep.txt").read_text() == "mine"


# ------------------------------------------------------------------ the three commands


@pytest.mark.slow
def test_a_users_stl_pair_goes_from_meshes_to_an_evaluated_policy(
    user_pair, hex_task, tmp_path, capsys
):
    """docs/guide/tasks.md's three commands at the smallest sizes: make the task (CoACD: 12
    pieces for the block in about 3 s), train a tiny SAC run on it, evaluate it against the
    scripted baseline; then the policy on another task (a cross evaluation)."""
    peg, hole = user_pair
    task = tmp_path / "task"
    make = ["task", "make", peg, hole, "--out", str(task), "--json"]
    make += ["--threshold", "0.05", "--contact-worlds", "2", "--contact-steps", "20"]
    make += ["--pieces", "coacd"]  # a box in a box is an extrusion: CoACD asked for here
    assert main(make) == 0
    doc = loads(capsys.readouterr().out)
    assert doc["source"]["pieces"] == "CoACD" and doc["hole"]["hulls"] >= 4
    assert doc["checks"]["clearance"]["radial_mm"] == pytest.approx(1.0, abs=0.01)
    run = tmp_path / "run"
    tiny = {
        "num_timesteps": 20,
        "num_envs": 2,
        "steps_per_call": 5,
        "eval_every": 20,
        "num_eval_envs": 2,
        "batch_size": 8,
        "grad_updates_per_step": 1,
        "min_replay_size": 10,
        "max_replay_size": 200,
        "hidden_layer_sizes": [16, 16],
        "env.episode_length": 10,
    }
    train = ["train", "--env", "MeshExtract", "--quick", "--engine", "mujoco", "--no-video"]
    train += [f"--set=env.task={task}", "--out", str(run), "--no-progress"]
    train += [f"--set={k}={json.dumps(v)}" for k, v in tiny.items()]
    assert main(train) == 0
    capsys.readouterr()
    assert main(["evaluate", str(run), "--episodes", "2", "--json"]) == 0
    res = loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert res["env"] == "MeshExtract" and res["episodes"] == 2
    assert res["task"] == str(task.resolve()) and res["baseline"]["episodes"] == 2
    # generalisation: the policy on another task's parts, a cross evaluation
    other = ["evaluate", str(run), "--episodes", "2", "--json", "--policy-only"]
    _refused([*other, f"--set=env.task={hex_task[0]}"], capsys, "differs from the policy's")
    assert main([*other, f"--set=env.task={hex_task[0]}", "--cross"]) == 0
    res = loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert res["task"] == str(hex_task[0].resolve())
    assert res["differs_from_training"]["task"] == [str(task.resolve()), res["task"]]


def test_the_declared_verdict_of_the_task_policies_study():
    """benchmarks/evals/task_policies.py's verdict: success first, force only when success is
    unresolved (benchmarks/results/evals/task_policies_decisions.txt)."""
    from benchmarks.evals.task_policies import verdict

    def d(lo, hi):
        return {"mean": (lo + hi) / 2, "ci95": [lo, hi]}

    assert verdict(d(0.01, 0.1), d(1.0, 2.0)) == "better"  # more success beats more force
    assert verdict(d(-0.1, -0.01), d(-5.0, -4.0)) == "worse"
    assert verdict(d(0.0, 0.0), d(-7.6, -6.1)) == "better"  # both always succeed: the force
    assert verdict(d(-0.03, 0.0), d(0.5, 1.0)) == "worse"
    assert verdict(d(-0.03, 0.02), d(-0.5, 0.4)) == "no difference resolved"
