"""Nothing of the user's is ever deleted or overwritten (issue 53, decided 2026-12-04), and an
exported policy refuses what it cannot trust.

Each data-loss case lists and hashes the user's files before and after the command and
asserts that they are unchanged. One real ``peghole export rect`` (``exported``) serves the
whole module; every other command here is refused before its work starts.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_faults import assert_one_line, peghole

from peghole_mjx import deploy
from peghole_mjx.cli import main as cli
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.deploy import DeployedPolicy
from peghole_mjx.files import fileio
from peghole_mjx.policies import save_policy

Z3 = np.zeros(3)


def hashes(folder: Path) -> dict[str, str]:
    """``relative path -> SHA-256`` of every file under ``folder``."""
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``peghole export rect --out mydata`` beside the user's ``mydata.tmp/`` and
    ``mydata.old/``: ``(root, exit status, the user's files before)``."""
    root = tmp_path_factory.mktemp("own")
    for name in ("mydata.tmp", "mydata.old"):
        (root / name).mkdir()
        (root / name / "results.csv").write_text(f"precious {name}\n")
    before = hashes(root)
    rc = cli.main(["export", "rect", "--out", str(root / "mydata")])
    return root, rc, before


# ---------------------------------------------------------------------- 1. file ownership
def test_export_never_touches_the_users_tmp_and_old_folders(exported):
    root, rc, before = exported
    assert rc == 0
    after = hashes(root)
    assert {k: v for k, v in after.items() if not k.startswith("mydata/")} == before
    # nothing left beside the output: the temporary folders had unique names, now gone
    assert sorted(p.name for p in root.iterdir()) == ["mydata", "mydata.old", "mydata.tmp"]
    owned = json.loads((root / "mydata" / fileio.OWNER_MANIFEST).read_text())["files"]
    assert owned == ["action.json", "policy.json", "policy.onnx"]


def test_export_force_replaces_its_own_export_and_keeps_the_users_old_folder(
    exported, tmp_path, capsys
):
    out = tmp_path / "mydata"
    shutil.copytree(exported[0] / "mydata", out)
    (tmp_path / "mydata.old").mkdir()
    (tmp_path / "mydata.old" / "results.csv").write_text("precious\n")
    before = hashes(tmp_path / "mydata.old")
    rc, _, err = peghole(["export", "rect", "--out", out, "--force"], capsys)
    assert rc == 0, err
    assert hashes(tmp_path / "mydata.old") == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mydata", "mydata.old"]
    assert fileio.owned_files(out) == {"action.json", "policy.json", "policy.onnx"}


@pytest.mark.parametrize("legacy", [False, True], ids=["with_manifest", "before_manifests"])
def test_export_force_refuses_the_users_files_in_the_output(exported, tmp_path, capsys, legacy):
    out = tmp_path / "mydata"
    shutil.copytree(exported[0] / "mydata", out)
    if legacy:  # an export written before 2026-12-04: no ownership manifest
        (out / fileio.OWNER_MANIFEST).unlink()
    (out / "NOTES.md").write_text("my notes\n")
    before = hashes(out)
    rc, _, err = peghole(["export", "dual", "--out", out, "--force"], capsys)
    assert rc == 2
    assert_one_line(err, str(out), "NOTES.md", "did not write")
    assert hashes(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mydata"]


def test_replace_dir_replaces_only_the_programs_own_folder(tmp_path):
    final = tmp_path / "out"
    tmp = fileio.temp_dir_beside(final)
    assert tmp.parent == tmp_path and tmp.name.startswith(".out.tmp-")
    (tmp / "a.txt").write_text("1")
    fileio.replace_dir(tmp, final)
    assert fileio.owned_files(final) == {"a.txt"}
    # the program's own folder is replaced; nothing is left beside it
    tmp = fileio.temp_dir_beside(final)
    (tmp / "a.txt").write_text("2")
    fileio.replace_dir(tmp, final)
    assert (final / "a.txt").read_text() == "2"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    # a file of the user's appears (e.g. while the work ran): refused at the swap, kept
    (final / "sub").mkdir()
    (final / "sub" / "mine.csv").write_text("precious")
    before = hashes(final)
    tmp = fileio.temp_dir_beside(final)
    (tmp / "a.txt").write_text("3")
    with pytest.raises(UserInputError, match=r"did not write \(sub/mine.csv\)") as e:
        fileio.replace_dir(tmp, final)
    assert "\n" not in str(e.value)
    assert hashes(final) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_save_policy_keeps_the_users_folders_and_files(tmp_path):
    params = {"w": np.arange(3.0)}
    (tmp_path / "pol.tmp").mkdir()
    (tmp_path / "pol.tmp" / "mine.txt").write_text("precious")
    (tmp_path / "pol.old").mkdir()
    (tmp_path / "pol.old" / "mine.txt").write_text("precious too")
    before = hashes(tmp_path)
    save_policy(tmp_path / "pol", params, {"env": "RectExtract"})
    save_policy(tmp_path / "pol", params, {"env": "RectExtract"})  # replaces its own
    after = hashes(tmp_path)
    assert {k: v for k, v in after.items() if not k.startswith("pol/")} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pol", "pol.old", "pol.tmp"]
    (tmp_path / "pol" / "NOTES.md").write_text("mine")
    before = hashes(tmp_path)
    with pytest.raises(UserInputError, match=r"did not write \(NOTES.md\)"):
        save_policy(tmp_path / "pol", params, {"env": "RectExtract"})
    assert hashes(tmp_path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pol", "pol.old", "pol.tmp"]


def test_task_make_over_a_task_folder_refuses_the_users_files(tmp_path, capsys):
    out = tmp_path / "task"
    out.mkdir()
    (out / "manifest.json").write_text("{}\n")  # a task folder (written before manifests)
    (out / "NOTES.md").write_text("my notes\n")
    before = hashes(tmp_path)
    rc, _, err = peghole(["task", "make", "peg.stl", "hole.stl", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, "NOTES.md", "did not write")
    assert hashes(tmp_path) == before


# ---------------------------------------------------------------------- 2. training's --out
def test_train_refuses_a_non_empty_folder_that_is_not_a_run(tmp_path, capsys):
    out = tmp_path / "u"
    out.mkdir()
    (out / "metrics.csv").write_text("step,return\n0,1.5\n")
    (out / "summary.json").write_text('{"mine": true}\n')
    before = hashes(tmp_path)
    rc, _, err = peghole(["train", "--env", "RectExtract", "--quick", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, f"--out {out} is not empty", "metrics.csv, summary.json")
    assert hashes(tmp_path) == before
    assert sorted(p.name for p in out.iterdir()) == ["metrics.csv", "summary.json"]


def test_train_refuses_a_copy_of_a_published_policy_folder(tmp_path, capsys):
    """A published policy folder has metrics.csv, summary.json and curves.png but no run.json:
    a new run into a copy of it is refused and overwrites none of them."""
    from peghole_mjx import policies

    out = tmp_path / "rect_copy"
    shutil.copytree(Path(policies.__file__).parent / "rect_extract", out)
    before = hashes(tmp_path)
    rc, _, err = peghole(["train", "--env", "RectExtract", "--quick", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, f"--out {out} is not empty", "no run.json", "metrics.csv")
    assert hashes(tmp_path) == before


def test_train_refuses_an_empty_out(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "metrics.csv").write_text("mine\n")
    before = hashes(tmp_path)
    for flag in ("--out", "--resume"):
        argv = ["train", flag, ""] + (
            ["--env", "RectExtract", "--quick"] if flag == "--out" else []
        )
        rc, _, err = peghole(argv, capsys)
        assert rc == 2
        assert_one_line(err, f"argument {flag}: an empty path is not a run folder")
    assert hashes(tmp_path) == before


# ---------------------------------------------------------------------- 3. deploy's trust
@pytest.fixture
def export_copy(exported, tmp_path) -> Path:
    folder = tmp_path / "export"
    shutil.copytree(exported[0] / "mydata", folder)
    return folder


def _edit_spec(folder: Path, edit) -> None:
    spec = json.loads((folder / "action.json").read_text())
    edit(spec)
    (folder / "action.json").write_text(json.dumps(spec))


def _write_model(folder: Path, inputs: int, out_size: int) -> None:
    """A valid ONNX model of ``inputs`` inputs (batch, the export's observation size) and one
    output (batch, out_size), its SHA-256 recorded in action.json (so only its signature is
    wrong)."""
    pytest.importorskip("onnx")
    from onnx import TensorProto, helper, numpy_helper

    n = json.loads((folder / "action.json").read_text())["observation"]["size"]
    ins = [
        helper.make_tensor_value_info(f"obs{i}", TensorProto.FLOAT, ["batch", n])
        for i in range(inputs)
    ]
    w = numpy_helper.from_array(np.zeros((n, out_size), np.float32), "w")
    out = helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", out_size])
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs0", "w"], ["action"])], "g", ins, [out], [w]
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    data = model.SerializeToString()
    (folder / "policy.onnx").write_bytes(data)
    _edit_spec(folder, lambda s: s["onnx"].update(sha256=hashlib.sha256(data).hexdigest()))


def test_an_edited_onnx_file_is_refused(export_copy):
    onnx = pytest.importorskip("onnx")
    from onnx import numpy_helper

    model = onnx.load(export_copy / "policy.onnx")
    init = model.graph.initializer[-1]
    arr = numpy_helper.to_array(init).copy()
    arr.flat[0] += 1.0  # a valid model, one weight changed
    init.CopyFrom(numpy_helper.from_array(arr, init.name))
    onnx.save(model, export_copy / "policy.onnx")
    with pytest.raises(CorruptFileError, match=r"policy.onnx is not the model.*SHA-256") as e:
        DeployedPolicy(export_copy)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("inputs", "out_size", "match"),
    [(2, 8, "2 inputs and 1 outputs"), (1, 5, r"gives actions of shape \['batch', 5\]")],
)
def test_an_onnx_model_of_the_wrong_signature_is_refused_at_load(
    export_copy, inputs, out_size, match
):
    _write_model(export_copy, inputs, out_size)
    with pytest.raises(CorruptFileError, match=match) as e:
        DeployedPolicy(export_copy)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda s: s["decode"]["tip_step_m"].__setitem__(0, float("nan")), "holds NaN"),
        (lambda s: s["decode"].__setitem__("force_ff_step_N", float("inf")), "holds Infinity"),
        (lambda s: s["action"].__setitem__("size", 1), "action size 1"),
        (
            lambda s: s["decode"]["learned_gains"]["k_xy"].__setitem__("hi", 1e9),
            r"k_xy on \[50, 1e\+09\], outside the robot's range \[0, 5000\]",
        ),
        (lambda s: s["decode"]["fixed_gains"].__setitem__("L_C_m", -0.5), "L_C_m = -0.5"),
    ],
    ids=["nan", "infinity", "action_size_1", "gain_range", "fixed_L_C"],
)
def test_an_untrustworthy_action_json_is_refused_at_load(export_copy, edit, match):
    _edit_spec(export_copy, edit)
    with pytest.raises(CorruptFileError, match=match) as e:
        DeployedPolicy(export_copy)
    assert "\n" not in str(e.value)


def test_a_deeply_nested_action_json_is_refused_in_one_line(export_copy):
    (export_copy / "action.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(CorruptFileError, match="nested too deeply") as e:
        DeployedPolicy(export_copy)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"k_xy_N_m": -1e9}, r"k_xy_N_m = -1000000000.0 is refused"),
        ({"k_rot_Nm_rad": float("inf")}, "k_rot_Nm_rad = inf is refused"),
        ({"L_C_m": float("nan")}, "L_C_m = nan is refused"),
        ({"L_C_m": 5.0}, r"L_C_m = 5.0 is refused.*\[0, 0.15\]"),
    ],
)
def test_reset_refuses_gains_outside_the_robots_ranges(export_copy, kw, match):
    p, fresh = DeployedPolicy(export_copy), DeployedPolicy(export_copy)
    for q in (p, fresh):
        q.reset(commanded_tip_m=(0.0, 0.0, -0.03))
    with pytest.raises(UserInputError, match=match) as e:
        p.reset(commanded_tip_m=(0.0, 0.0, -0.05), **kw)
    assert "\n" not in str(e.value)
    # the refused reset changed nothing: the state is the first reset's
    args = ([0.2, 0.1, 2.0, 0.0, 0.0, 0.0], [0.0, 1e-4, 0.06], [0.0, 0.0, 0.0])
    a, b = p.act(*args), fresh.act(*args)
    np.testing.assert_array_equal(a.tip_target_m, b.tip_target_m)
    np.testing.assert_array_equal(a.stiffness, b.stiffness)


@pytest.mark.parametrize("shape", [(1,), (8, 1), (1, 8)])
def test_an_action_that_is_not_one_vector_is_refused(export_copy, shape):
    p = DeployedPolicy(export_copy)
    p.reset(commanded_tip_m=(0.0, 0.0, -0.03))
    with pytest.raises(UserInputError, match=rf"shape \({shape[0]}, ?(\d*)\) refused: one action"):
        p.decode(np.zeros(shape))
    assert p.decode(np.zeros(8)).step == 1  # nothing advanced before


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda p: p.flange_pose(Z3, np.eye(3), Z3, Z3), r"hole_rot .* got shape \(3,\)"),
        (lambda p: p.flange_pose(Z3, np.eye(2), Z3, np.eye(3)), r"flange_rot .* shape \(2, 2\)"),
        (lambda p: p.flange_pose(Z3, np.eye(3), Z3, np.full((3, 3), np.nan)), "hole_rot holds NaN"),
        (lambda p: p.wrench_from_sensor(Z3, Z3, Z3), r"sensor_rot_in_hole .* shape \(3,\)"),
        (lambda p: p.wrench_from_sensor(Z3, Z3, "x"), "sensor_rot_in_hole must be a 3 x 3"),
        (lambda p: deploy.rot_from_rotvec(np.ones((3, 1))), r"got shape \(3, 1\)"),
        (lambda p: deploy.rot_from_rotvec(np.ones(2)), r"got shape \(2,\)"),
        (lambda p: deploy.rotvec_from_mat(np.eye(2)), r"got shape \(2, 2\)"),
    ],
    ids=[
        "hole_rot_vector",
        "flange_rot_2x2",
        "hole_rot_nan",
        "sensor_rot_vector",
        "sensor_rot_text",
        "rotvec_column",
        "rotvec_2",
        "mat_2x2",
    ],
)
def test_wrong_shaped_arguments_to_the_public_helpers_are_one_line(export_copy, call, match):
    """The deploy module's public helpers (reading poses, an F/T sensor, rotations) refuse
    an argument of the wrong shape, or a non-finite rotation, in one line (an IndexError or a
    matmul ValueError before); nothing of the policy's state changes."""
    p = DeployedPolicy(export_copy)
    p.reset(commanded_tip_m=(0.0, 0.0, -0.03))
    with pytest.raises(UserInputError, match=match) as e:
        call(p)
    assert "\n" not in str(e.value)
    pos, tilt = p.flange_pose(Z3, np.eye(3), Z3, np.eye(3))  # the right shapes: accepted
    assert pos.shape == tilt.shape == (3,) and np.all(np.isfinite(tilt))
    assert p.wrench_from_sensor(Z3, Z3, np.eye(3)).shape == (6,)
