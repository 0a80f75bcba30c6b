"""The suite's file order (tests/conftest.py): the longest files first, and pytest-xdist told
to hand out files in that order."""

from pathlib import Path

from conftest import SLOWEST_FIRST

TESTS = Path(__file__).parent


def test_every_listed_file_exists_once():
    """A renamed or removed test file would silently lose its place in the order."""
    assert len(set(SLOWEST_FIRST)) == len(SLOWEST_FIRST)
    missing = [name for name in SLOWEST_FIRST if not (TESTS / name).is_file()]
    assert not missing, f"tests/conftest.py SLOWEST_FIRST names missing files: {missing}"


def test_collection_starts_with_the_listed_files_in_their_order(request):
    """This session's own collection: files of the list come first, in the list's order."""
    files = []
    for item in request.session.items:
        if not files or files[-1] != item.path.name:
            files.append(item.path.name)
    listed = [f for f in files if f in SLOWEST_FIRST]
    assert files[: len(listed)] == listed
    assert listed == [f for f in SLOWEST_FIRST if f in listed]


def test_xdist_keeps_the_collection_order(pytestconfig):
    """Where pytest-xdist is loaded, its reordering of files by test count is off."""
    if hasattr(pytestconfig.option, "loadscopereorder"):
        assert pytestconfig.option.loadscopereorder is False
