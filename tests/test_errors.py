"""The error module and optional dependencies: errors.py depends on nothing in the package; a
missing extra gives one line naming the install command."""

import subprocess
import sys

import pytest

from peghole_mjx.cli import main as cli
from peghole_mjx.core.errors import MissingExtraError, UserInputError


@pytest.mark.parametrize("module", ["trimesh", "coacd"])
def test_decompose_without_the_cad_extra_names_it(tmp_path, capsys, monkeypatch, module):
    """Simulate an install without the cad extra: a ``None`` entry in sys.modules makes
    ``import`` raise ImportError, as a missing package does."""
    monkeypatch.setitem(sys.modules, module, None)
    part = tmp_path / "part.stl"
    part.write_bytes(b"solid x\nendsolid x\n")
    if module == "coacd":  # load_mesh needs trimesh only; CoACD is reached in run_coacd
        from peghole_mjx.geometry.decompose import run_coacd

        with pytest.raises(MissingExtraError, match=r'coacd.*pip install -e "\.\[cad\]"'):
            run_coacd(None)
        return
    rc = cli.main(["models", "decompose", str(part), str(part), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert 'needs trimesh, which is not installed: pip install -e ".[cad]"' in lines[0]
    assert not (tmp_path / "o" / "scene.xml").exists()


def test_missing_extra_error_is_a_user_input_and_an_import_error():
    from peghole_mjx.core._optional import optional_import

    with pytest.raises(MissingExtraError) as info:
        optional_import("gymnasium_not_installed_here", "the test")
    assert isinstance(info.value, UserInputError)
    assert isinstance(info.value, ImportError)
    assert "pip install gymnasium_not_installed_here" in str(info.value)


def test_errors_module_imports_nothing_from_the_package():
    """Any module can raise the package's errors without an import cycle (``core/__init__.py``
    imports nothing)."""
    code = (
        "import sys, peghole_mjx.core.errors; "
        "print(sorted(m for m in sys.modules if m.startswith('peghole_mjx.')))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "['peghole_mjx.core', 'peghole_mjx.core.errors']"


def test_specs_reexports_the_geometry_error():
    from peghole_mjx.core import errors
    from peghole_mjx.geometry import specs

    assert specs.InfeasibleGeometryError is errors.InfeasibleGeometryError
    assert errors.InfeasibleGeometryError in errors.REPORTED_ERRORS
