"""A pytest plugin (``-p suiteplug``, this folder on PYTHONPATH): when each test ran, where, and its CPU.

``SUITELOG_TESTS=path``: one JSON line per test and process (xdist worker):
worker, test id, start and end (epoch seconds), CPU seconds (user + system of
the process and of the children it waited for). ``SUITELOG_EVENTS=path``: the
start-up's milestones per process (configure, collection finished).
"""

from __future__ import annotations

import json
import os
import resource
import time

_start: dict[str, tuple[float, float]] = {}


def _cpu() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def _write(var: str, record: dict) -> None:
    path = os.environ.get(var)
    if path:
        record["w"] = os.environ.get("PYTEST_XDIST_WORKER", "main")
        with open(path, "a") as fh:
            fh.write(json.dumps(record) + "\n")


def pytest_configure(config):
    _write("SUITELOG_EVENTS", {"ev": "configure", "t": time.time(), "cpu": _cpu()})


def pytest_collection_finish(session):
    _write("SUITELOG_EVENTS", {"ev": "collected", "t": time.time(), "cpu": _cpu()})


def pytest_runtest_logstart(nodeid, location):
    _start[nodeid] = (time.time(), _cpu())


def pytest_runtest_logfinish(nodeid, location):
    t0, c0 = _start.pop(nodeid, (time.time(), _cpu()))
    _write("SUITELOG_TESTS", {"id": nodeid, "t0": t0, "t1": time.time(), "cpu": _cpu() - c0})
