"""The package's architecture: the import-linter contracts of ``.importlinter`` hold (layers, no
import cycle, the package never imports the benchmarks), and every import of the package sits
at the top of its module, but for the optional extras.

import-linter 2.17 runs as ``lint-imports`` does (its click command, in a subprocess whose
working directory is the repository root, so that the custom contract types of ``tests/``
import). Cheap: no JAX graph is built or compiled.
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "peghole_mjx"

#: modules that may be imported inside a function: the optional extras of pyproject.toml (cad,
#: gym, playground, bench, export, warp; a function-local import keeps the package usable
#: without them, and ``peghole_mjx.core._optional`` names the extra to install), and tensorboardX,
#: a dependency that imports torch and boto3 (3.7 s on the 2-core CPU, 2026-12-02) and whose
#: numbers metrics.csv holds anyway
OPTIONAL_EXTRAS = frozenset(
    {
        "coacd",
        "trimesh",
        "manifold3d",
        "rtree",
        "gymnasium",
        "mujoco_playground",
        "playground",
        "pybullet",
        "stable_baselines3",
        "torch",
        "onnx",
        "onnxruntime",
        "warp",
        "mujoco_warp",
        "tensorboardX",
        "mkdocs",
    }
)
#: the modules that import by name (``importlib.import_module``), and why
DYNAMIC_IMPORTS = {
    "peghole_mjx/cli/main.py": "the command groups of GROUPS, each when the parser is built",
    "peghole_mjx/core/lazy.py": (
        "a command's module, when the command runs (peghole --help stays fast)"
    ),
    "peghole_mjx/core/_optional.py": "an optional extra, with the pip command that installs it",
}


def lint_imports(config: Path, cwd: Path, pythonpath: str | None = None):
    """``lint-imports CONFIG --no-cache`` in ``cwd``: the finished process."""
    env = None if pythonpath is None else {**os.environ, "PYTHONPATH": pythonpath}
    code = "from importlinter.cli import lint_imports_command; lint_imports_command()"
    return subprocess.run(
        [sys.executable, "-c", code, str(config), "--no-cache"],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )


def test_the_import_contracts_hold():
    res = lint_imports(ROOT / ".importlinter", ROOT)
    assert res.returncode == 0, res.stdout[-6000:] + res.stderr[-3000:]
    assert "0 broken" in res.stdout
    for name in ("layers", "no import cycles", "does not import benchmarks"):
        assert name in res.stdout


def test_the_acyclic_modules_contract_finds_a_cycle_through_a_function_local_import(tmp_path):
    """The custom contract type breaks on a cycle whose second half is an import inside a
    function (the kind the package had), and names both imports with their lines."""
    pkg = tmp_path / "cyc_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from cyc_pkg import b\n")
    (pkg / "b.py").write_text("def f():\n    from cyc_pkg import a\n\n    return a\n")
    (pkg / "c.py").write_text("from cyc_pkg import a\n")  # imports into the cycle: not in it
    config = tmp_path / "contracts.ini"
    config.write_text(
        textwrap.dedent(
            """\
            [importlinter]
            root_packages =
                cyc_pkg
            contract_types =
                acyclic_modules: tests.architecture_contracts_b.AcyclicModulesContract

            [importlinter:contract:cycles]
            name = no cycles
            type = acyclic_modules
            packages =
                cyc_pkg
            """
        )
    )
    res = lint_imports(config, tmp_path, pythonpath=f"{tmp_path}:{ROOT}")
    assert res.returncode == 1, res.stdout + res.stderr
    assert "Import cycle among cyc_pkg.a, cyc_pkg.b" in res.stdout
    assert "cyc_pkg.a -> cyc_pkg.b (l.1)" in res.stdout
    assert "cyc_pkg.b -> cyc_pkg.a (l.2)" in res.stdout
    assert "cyc_pkg.c" not in res.stdout.split("Broken contracts")[-1]
    # without the function-local half the same package keeps the contract
    (pkg / "b.py").write_text("def f():\n    return 1\n")
    assert lint_imports(config, tmp_path, pythonpath=f"{tmp_path}:{ROOT}").returncode == 0


def in_function_imports(path: Path, rel: str | None = None) -> list[str]:
    """``file:line: statement`` of every import inside a function of ``path`` (``rel``: its
    name in the repository) whose module is not an optional extra, and of every import by
    name outside :data:`DYNAMIC_IMPORTS`."""
    rel = rel or path.relative_to(ROOT).as_posix()
    tree = ast.parse(path.read_text(), filename=rel)
    found = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if in_function and isinstance(child, ast.Import | ast.ImportFrom):
                if isinstance(child, ast.Import):
                    modules = [a.name for a in child.names]
                else:
                    modules = ["." * child.level + (child.module or "")]
                if not all(m.split(".")[0] in OPTIONAL_EXTRAS for m in modules):
                    found.append(f"{rel}:{child.lineno}: {ast.unparse(child)}")
            if isinstance(child, ast.Call) and rel not in DYNAMIC_IMPORTS:
                f = child.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if name in ("import_module", "__import__"):
                    found.append(f"{rel}:{child.lineno}: {ast.unparse(child)}")
            visit(child, inner)

    visit(tree, False)
    return found


def test_imports_sit_at_the_top_of_their_modules():
    """Imports of the package's own modules and of its dependencies are at module top (an
    import cycle or a slow start is fixed where it arises, not hidden in a function); only
    the optional extras (:data:`OPTIONAL_EXTRAS`) are imported where they are used."""
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 50
    found = [line for path in files for line in in_function_imports(path)]
    assert not found, "imports inside functions:\n" + "\n".join(found)


def test_the_in_function_import_check_sees_methods_nested_functions_and_import_module(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text(
        textwrap.dedent(
            """\
            import importlib


            class A:
                def m(self):
                    import numpy as np

                    def inner():
                        from peghole_mjx.files import fileio
                        import trimesh

                    return importlib.import_module("peghole_mjx.envs")
            """
        )
    )
    found = in_function_imports(sample, "peghole_mjx/sample.py")
    assert [line.split(": ", 1)[1] for line in found] == [
        "import numpy as np",
        "from peghole_mjx.files import fileio",
        "importlib.import_module('peghole_mjx.envs')",
    ]


def test_the_package_root_holds_the_layers_folders_and_three_entry_modules():
    """The tree shows the layers: every module lives in a layer's folder except the demo, the
    Gymnasium adapter and the robot-side runner, and every folder is a layer of the contract."""
    modules = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert modules == ["__init__.py", "demo.py", "deploy.py", "gym.py"]
    folders = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    contract = (ROOT / ".importlinter").read_text()
    layers = contract.split("[importlinter:contract:peghole-layers]")[1].split("ignore_imports")[0]
    named = set(re.findall(r"peghole_mjx\.(\w+)", layers))
    assert folders == named - {"demo", "deploy", "gym"}
    assert folders == {
        "cli",
        "training",
        "policies",
        "envs",
        "experiments",
        "sim",
        "control",
        "analysis",
        "geometry",
        "files",
        "core",
    }


#: the functions that advance a physics state, called or passed on (``jax.jit(mjx.step)``):
#: MuJoCo C's step functions and rollout, MJX's step, a ``mujoco.batch`` step or rollout
_STEPPING = re.compile(
    r"\b(mj_step[12]?|mujoco\.rollout|mjx\.step|batch\.step|batch\.rollout)\b(?!_)"
)


def _code_lines(path: Path) -> list[tuple[int, str]]:
    """The lines of a module that hold code (docstrings and comments left out)."""
    text = path.read_text()
    doc_lines: set[int] = set()
    for node in ast.walk(ast.parse(text)):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            v = body[0].value
            if isinstance(v, ast.Constant) and isinstance(v.value, str):
                doc_lines.update(range(v.lineno, v.end_lineno + 1))
    return [
        (i, line.split("#", 1)[0])
        for i, line in enumerate(text.splitlines(), 1)
        if i not in doc_lines
    ]


def test_physics_is_stepped_in_the_sim_layer_only():
    """Issue 51: the sim layer (``peghole_mjx/sim/``) is the only place the package steps
    physics; the envs, the experiments, the geometry checks and the contact replay are its
    clients."""
    found = [
        f"{path.relative_to(ROOT)}:{i}: {line.strip()}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if "sim" not in path.relative_to(PACKAGE).parts[:1]
        for i, line in _code_lines(path)
        if _STEPPING.search(line)
    ]
    assert found == []
    # the pattern finds what it must (the sim layer steps)
    sim_hits = [
        line
        for path in (PACKAGE / "sim").rglob("*.py")
        for _, line in _code_lines(path)
        if _STEPPING.search(line)
    ]
    assert any("mjx.step" in s for s in sim_hits) and any("mj_step" in s for s in sim_hits)
    assert any("batch.step" in s for s in sim_hits)
