"""Test configuration: one copy of warpcli under test, and derandomized hypothesis."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

# Bytecode is written and read, as for an installed warpcli, even where the shell sets
# PYTHONDONTWRITEBYTECODE (this project's CI does): otherwise every test module is rewritten by
# pytest anew in each xdist worker, and every process the suite starts compiles warpcli's
# modules from source (see `pytest_configure`).
sys.dont_write_bytecode = False
from hypothesis import settings

import warpcli

#: The checkout these tests belong to.
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Exactly one copy of the code is tested: the one in this checkout. A copy
# installed elsewhere (pip install . without -e) would be tested by the CLI
# subprocesses while the working tree was tested in-process; refuse to run.
_here = os.path.dirname(os.path.abspath(warpcli.__file__))
if _here != os.path.join(REPO, "warpcli"):
    raise pytest.UsageError(
        f"the tests import warpcli from {_here}, not from this checkout ({REPO}); "
        "install it in editable mode: pip install -e '.[test]'"
    )

# No unseeded randomness anywhere, tests included: the same examples every run.
settings.register_profile("warpcli", derandomize=True, deadline=None, max_examples=40)
# Longer local fuzzing: WARPCLI_FUZZ=long python -m pytest tests/test_fuzz.py (random, many examples).
settings.register_profile("long", derandomize=False, deadline=None, max_examples=2000)
settings.load_profile("long" if os.environ.get("WARPCLI_FUZZ") == "long" else "warpcli")


# Heavy tests (dense checks at full density, default-m fits of many-gons): not in the default
# run's time budget. WARPCLI_HEAVY=1 python -m pytest ... runs them too.
HEAVY = os.environ.get("WARPCLI_HEAVY") == "1"


def pytest_configure(config):
    config.addinivalue_line("markers", "heavy: a long test, run only with WARPCLI_HEAVY=1")
    config.addinivalue_line(
        "markers", "forks: the test is about forked children (map builders, batch workers): keep them in-process"
    )
    if not hasattr(config, "workerinput"):  # once, in the process that starts xdist's workers
        # The CLI subprocesses, the docs build and the README's commands each import warpcli; with
        # PYTHONDONTWRITEBYTECODE set none of them writes its bytecode, so each compiled about 70
        # modules from source (0.26 s of CPU a process, measured in bench/jobs.py), as an editable
        # install leaves them uncompiled. compileall writes them whatever that variable says.
        import compileall

        compileall.compile_dir(os.path.join(REPO, "warpcli"), quiet=1)
        _rewrite_test_modules_in_a_child(config)


def _rewrite_test_modules_in_a_child(config) -> None:
    """With xdist workers, write pytest's rewritten bytecode of the collected test modules once.

    Every worker collects every test file; in a fresh clone (no ``__pycache__``) each rewrote the
    asserts of all of them at the same time, about 4.4 s of CPU a worker of the 8.5 s its
    collection took (measured: 4 s warm). Written first by a child of this process, while this
    one starts the workers, they are read by the workers from pytest's own cache
    (``_pytest.assertion.rewrite``: a module a worker reaches first it rewrites itself, as
    before; each file is written whole and renamed, as pytest does for concurrent processes).
    A child, not a thread: on a thread the rewriting held the interpreter lock that this
    process needed to start and feed the workers (measured: they began collecting 2-3 s later).
    No thread of pytest's or xdist's runs yet (they come with the session); the child only reads
    and writes these files and ends with ``os._exit``. The module is pytest's own, not its public
    API: anything unexpected leaves the workers to rewrite as before.
    """
    workers = config.getoption("numprocesses", None)
    if not workers or getattr(config.option, "dist", "no") == "no" or sys.dont_write_bytecode:
        return
    if not hasattr(os, "fork") or _REWRITE_CHILD:
        return
    try:
        from _pytest.assertion import rewrite

        state = config.stash[rewrite.assertstate_key]
        tests = Path(REPO, "tests")
        base = config.rootpath if config.args_source == pytest.Config.ArgsSource.TESTPATHS else config.invocation_params.dir
        files: set[Path] = set()
        for arg in config.args:  # only the files this run collects
            p = Path(base, arg.split("::")[0]).resolve()
            if p.is_dir():
                files.update(f for f in tests.glob("test_*.py") if p in f.parents)
            elif p.parent == tests and p.name.startswith("test_") and p.suffix == ".py":
                files.add(p)
        cache = rewrite.get_cache_dir(Path(tests, "conftest.py"))
        if not files or not rewrite.try_makedirs(cache):
            return
    except Exception:  # noqa: BLE001 (an optimisation only: the workers rewrite what is missing)
        return
    pid = os.fork()
    if pid:
        _REWRITE_CHILD.append(pid)
        return
    try:
        for fn in sorted(files):
            pyc = cache / (fn.name[:-3] + rewrite.PYC_TAIL)
            if rewrite._read_pyc(fn, pyc, state.trace) is None:
                source_hash, co = rewrite._rewrite_test(fn, config)
                rewrite._write_pyc(state, co, source_hash, pyc)
    finally:
        os._exit(0)


def pytest_unconfigure(config):
    while _REWRITE_CHILD:  # reaped, so that its CPU is counted with the run's
        try:
            os.waitpid(_REWRITE_CHILD.pop(), 0)
        except ChildProcessError:
            pass


_REWRITE_CHILD: list = []


@pytest.fixture(autouse=True)
def _no_forks_from_the_test_process(request, monkeypatch):
    """In this process, maps are built and batches run on threads, not in forked children.

    A fork write-protects every page of the forking process, which then takes a
    fault for each page it writes again: cheap for ``warp`` (a small process),
    dear for a test process that has grown to hundreds of MB over a run (measured,
    test_tiled, test_pipeline, test_annotations and test_golden in one process:
    23.3 s user + 8.9 s system and 1.9M page faults with forks, 21.8 + 2.1 s and
    0.47M on threads). The results are the same either way (`warpcli._fork`: "the same
    result"; tests/test_fork.py and tests/test_cores.py check it, marked
    ``forks``, like every test about the children themselves). Only the
    attribute is replaced, not ``WARPCLI_FORK``: the CLI run as a subprocess
    forks as it does for users.
    """
    if request.node.get_closest_marker("forks") is None:
        from warpcli import _fork

        monkeypatch.setattr(_fork, "available", lambda: False)


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist: ``-n N`` hands out whole test files (in collection order), not single tests.

    Many files build maps or fixtures once per process and share them (`helpers.built_map`,
    module-scoped fixtures); split test by test (xdist's "load"), both workers built them (the
    map contract's maps, about 25 s of CPU twice). The files are small beside the whole run
    (the largest about 100 s of 550), so the two workers still end close together (measured:
    11 s of worker time apart in a 5-minute run). ``--dist load`` given explicitly is taken
    the same way (xdist cannot tell it from -n's default); any other ``--dist`` is left alone.
    Not xdist's loadgroup: under pytest 9 it groups nothing (xdist 3.8 renames tests through
    ``item._nodeid``, which pytest 9 no longer reads).
    """
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadFileScheduling

    config.option.loadscopereorder = False  # collection order: the doctests' small files come last
    return LoadFileScheduling(config, log)


def pytest_collection_modifyitems(config, items):
    if HEAVY:
        return
    skip = pytest.mark.skip(reason="heavy: WARPCLI_HEAVY=1 runs it")
    for item in items:
        if "heavy" in item.keywords:
            item.add_marker(skip)
