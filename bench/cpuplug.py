"""A pytest plugin: CPU seconds and page faults per test and per file, children included.

Load it with ``-p cpuplug`` (``PYTHONPATH=bench``) and name an output file in
``CPUPLUG_OUT``; every process (each xdist worker, and the controller) appends
one JSON line at the end: per file and per test, [user, system, children's
user, children's system, minor page faults] since the previous test ended
(`resource.getrusage` of the process and of the children it waited for).

    PYTHONPATH=bench CPUPLUG_OUT=cpu.jsonl python -m pytest -q -n auto -p cpuplug
"""

from __future__ import annotations

import json
import os
import resource
import time

_last: list[float] = []
_files: dict[str, list[float]] = {}
_tests: dict[str, list[float]] = {}
_t0 = 0.0


def _usage() -> list[float]:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return [s.ru_utime, s.ru_stime, c.ru_utime, c.ru_stime, s.ru_minflt + c.ru_minflt]


def pytest_sessionstart(session):
    global _last, _t0
    _last, _t0 = _usage(), time.time()


def pytest_runtest_logfinish(nodeid, location):
    global _last
    now = _usage()
    step = [a - b for a, b in zip(now, _last)]
    for table, key in ((_files, nodeid.split("::")[0]), (_tests, nodeid)):
        table[key] = [a + b for a, b in zip(table.get(key, [0.0] * 5), step)]
    _last = now


def pytest_sessionfinish(session):
    line = {"worker": os.environ.get("PYTEST_XDIST_WORKER", "main"), "files": _files, "tests": _tests,
            "total": _usage(), "wall": time.time() - _t0, "end": time.time()}  # fmt: skip
    with open(os.environ["CPUPLUG_OUT"], "a") as fh:
        fh.write(json.dumps(line) + "\n")
