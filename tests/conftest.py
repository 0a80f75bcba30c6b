"""Shared test setup: quiet mjx import, CPU-only JAX, one compilation cache for the session.

The persistent XLA compilation cache is shared by the test process and every ``peghole``
subprocess a test starts (they inherit the environment), so a graph compiled once (an env
step takes about a minute on a 2-core CPU) is loaded from disk afterwards. It only saves
time: results are the same with or without it.
"""

import os
import tempfile

if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    os.environ["JAX_COMPILATION_CACHE_DIR"] = os.path.join(
        tempfile.gettempdir(), "peghole_mjx_test_jax_cache"
    )
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
# a size bound turns on JAX's file lock around every cache read and write: the suite's two
# pytest-xdist workers and their subprocesses share the folder, and an unlocked reader could
# load an entry another process is still writing
os.environ.setdefault("JAX_COMPILATION_CACHE_MAX_SIZE", str(16 << 30))

import ctypes
import ctypes.util
import gc

import jax
import pytest

import peghole_mjx.core._mjx  # noqa: F401
from peghole_mjx.core import runtime

# the commands' process-wide settings (XLA's CPU flag, headless GL; the cache folder above is
# kept): importing the package sets nothing. Importing JAX starts no backend, so XLA_FLAGS set
# here still applies to the first computation
runtime.configure()

#: tests/test_playground.py is the optional suite (README): .ci/run installs MuJoCo Playground
#: and runs it by name after the main suite, so a run over the folder leaves it out (where
#: Playground happened to be installed it ran twice, 2 min each, 2026-12-03)
collect_ignore = ["test_playground.py"]

#: the test files that take longest, longest first (seconds of test time in one suite run,
#: 2-core CPU, 2026-12-03: 593, 484, 372, 263, 201, 197, 180, 125, 111, 101, 100, 98, 90, 84,
#: 71, 68, 66; every other file under 41 s). They are collected first and pytest-xdist hands
#: out whole files in collection order (:func:`pytest_configure`), so the two workers start
#: on the long files and end on short ones. With xdist's default order (files with the most
#: tests first) the long few-test files came last and one worker ran test_every_env.py alone
#: for its last 3 min.
SLOWEST_FIRST = (
    "test_training.py",
    "test_envs.py",
    "test_every_env.py",
    "test_docs.py",
    "test_tasks.py",
    "test_shifts.py",
    "test_stuck.py",
    "test_policies.py",
    "test_export.py",
    "test_engines.py",
    "test_benchmarks.py",
    "test_functional_training.py",
    "test_distributed.py",
    "test_experiment.py",
    "test_decompose.py",
    "test_transfer.py",
    "test_control.py",
)


def pytest_configure(config):
    """Under pytest-xdist's ``--dist loadfile``, hand out files in collection order."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(items):
    """The files of :data:`SLOWEST_FIRST` first, in its order; the others after them, in
    their own order (a stable sort: tests keep their order within a file)."""
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Drop every compiled executable when a test module ends.

    XLA:CPU maps the code of each loaded executable into the process. Kept for the whole
    suite, they passed Linux's default limit of 65,530 memory maps (``vm.max_map_count``) and
    the next executable load crashed the process (SIGSEGV in CI, SIGABRT here, 2026-12-02;
    test_training.py alone reaches 30,000 maps and 6.3 GB). A graph that a later module needs
    loads again from the persistent cache.

    Then glibc's ``malloc_trim`` hands the freed heap back to the system: without it the
    worker's resident memory only grows, module after module (measured 2026-12-02: an MJX
    rollout's process at 1.07 GB after ``jax.clear_caches``, 0.42 GB after the trim).
    """
    yield
    release_compiled_code()


def release_compiled_code() -> None:
    """Drop JAX's compiled executables and traces, collect, hand the freed heap back."""
    jax.clear_caches()
    gc.collect()
    if _LIBC is not None:
        _LIBC.malloc_trim(0)


@pytest.fixture
def release_after():
    """Request it (or make it autouse in a module) to release compiled code after each test
    of a module whose tests share no graphs."""
    yield
    release_compiled_code()


def _glibc():
    """glibc through ctypes, or None on a system without ``malloc_trim`` (musl, macOS)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        libc.malloc_trim  # noqa: B018 - the attribute lookup is the check
    except (OSError, AttributeError, TypeError):
        return None
    return libc


_LIBC = _glibc()
