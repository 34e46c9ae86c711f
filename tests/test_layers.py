"""Layering: warpcli's import graph has no cycle, and no module reaches a layer above its own.

The graph is read from the source with `ast`, not from ``sys.modules``, so it
holds every import a module can make: absolute and relative, ``import x`` and
``from x import y``, at the top, inside functions and under ``TYPE_CHECKING``
(a type a module names is a module it depends on). Modules loaded by name are
edges too: a string such as ``"warpcli.maps.optimize:optimized"`` (the
registries, `warpcli._native.Kernels`) and, in a module that imports by
relative name (``importlib.import_module(f".{name}", __name__)``, the package's
lazy exports), a string naming a sibling module.

Importing ``warpcli.a.b`` also runs ``warpcli/a/__init__.py``; those implicit
edges are left out: a package's ``__init__`` is its facade (``volume`` and
``maps.fem`` gather their modules there), and an edge from every submodule up
to it would make each such package a cycle of its own.

Layers are checked on the transitive closure: a module may not reach a module
of a higher layer, nor another component of its own layer, through any chain
of imports (``raster.imageio -> options -> maps.registry`` is ``raster``
reaching ``maps``).
"""

from __future__ import annotations

import ast
import functools
import os
import re
from collections import deque

import pytest

from conftest import REPO

ROOT = os.path.join(REPO, "warpcli")

#: The layers, bottom to top: each a name and its components, each component
#: the modules it holds (names below ``warpcli``; a package stands for all its
#: modules; ``__init__`` is the ``warpcli`` package itself, the public API). A
#: module may import its own component and anything in a lower layer; the
#: components of one layer know nothing of each other.
LAYERS = [
    # Values, files, conventions and the seam shared by 2D and 3D (mapping,
    # simplicial, distortion): nothing here knows how a map is made or an image
    # is read. `options` is here, not above the maps: maps (MapOptions,
    # WEIGHTS), raster (INTERPOLATIONS) and pipelines all read it, so it reads
    # only name tables (`raster.dtypes`, free of numpy, is one); the registry
    # of implementations sits in `maps`.
    ("base", {
        "base": (
            "errors", "files", "budget", "capture", "outputs", "grid", "boundary", "polygon", "mapping",
            "simplicial", "distortion", "options", "raster.dtypes", "_native", "_elf", "_jit", "_fork", "_cached", "_extensions", "_arrays", "_switches", "cores",
        ),
    }),
    # Maps see points and Jacobians, raster sees pixels: neither knows the other.
    ("core", {"maps": ("maps",), "raster": ("raster",)}),
    # Measuring and drawing a map: through raster, and maps only by duck typing (see NEVER).
    ("report", {"report": ("report",)}),
    # Where each output pixel comes from (the sampling plan, the paste of a retouch), what a
    # sequence's frames and keyframes are, a map as scikit-image's transforms are called, annotations through it.
    ("sampling", {"sampling": ("plan", "composite", "sequence", "keyframes", "transform", "annotations", "within")}),
    # What runs a warp from files: 2D runs beside 3D, neither knowing the other (see NEVER).
    ("runs", {
        "runs": ("tiled", "pipeline", "batch", "distributed", "points", "surface"),
        "volume": ("volume",),
    }),
    # Applications over the runs: the browser editor (its server, session and preview).
    ("apps", {"edit": ("edit",)}),
    # The public API: lazy exports of all of the above.
    ("api", {"api": ("__init__",)}),
    ("cli", {"cli": ("cli", "__main__", "_entry")}),
]  # fmt: skip

#: Components of different layers that must still not reach each other: (from, to, why).
NEVER = [
    ("report", "maps", "a report reads a map through a Protocol (warpcli/report/__init__.py), never its classes"),
    ("volume", "maps", "3D builds on the seam it shares with 2D (mapping, simplicial, distortion), not on 2D's maps"),
    ("volume", "report", "3D reports its own maps (volume/report.py)"),
]

#: Names LAYERS lists before the module exists (issue 20's branches create them).
COMING: set[str] = set()

#: Cycles tolerated for now, each the set of its modules (below ``warpcli``);
#: an entry that is no longer a cycle fails too, so that it is removed. Empty at the end.
ALLOWED_CYCLES: list[set[str]] = []

#: Modules whose reach above their layer is someone else's to remove (strict:
#: each fails the day its reach is gone, so that the entry is removed too).
KNOWN_VIOLATIONS: dict[str, str] = {}


def _short(module: str) -> str:
    return module.removeprefix("warpcli.") if module != "warpcli" else "__init__"


@functools.cache
def _module_files(root: str = ROOT) -> dict[str, str]:
    """Every module under warpcli/, by dotted name (a package by its own name), to its file."""
    out = {}
    for dirpath, dirnames, files in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for f in sorted(files):
            if f.endswith(".py"):
                parts = os.path.relpath(os.path.join(dirpath, f[:-3]), os.path.dirname(root)).split(os.sep)
                if parts[-1] == "__init__":
                    parts.pop()
                out[".".join(parts)] = os.path.join(dirpath, f)
    return out


_ABSOLUTE_NAME = re.compile(r"^warpcli(\.\w+)+(:\w+)?$")
_RELATIVE_NAME = re.compile(r"^\w+(\.\w+)*$")


def _docstrings(tree: ast.AST) -> set[int]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                found.add(id(first.value))
    return found


def _imports_by_relative_name(tree: ast.AST) -> bool:
    """Whether the module calls ``import_module`` with a name starting with a dot."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and node.args:
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            first = node.args[0]
            if isinstance(first, ast.JoinedStr) and first.values:
                first = first.values[0]
            if name == "import_module" and isinstance(first, ast.Constant) and str(first.value).startswith("."):
                return True
    return False


def _edges(module: str, path: str, modules: dict[str, str], top: str) -> dict[str, str]:
    """The ``modules`` that ``module`` imports or loads by name, each with where and how (for messages)."""
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    package = module if path.endswith("__init__.py") else module.rpartition(".")[0]
    where = os.path.relpath(path, top)
    out: dict[str, str] = {}

    def add(target: str, line: int, how: str) -> None:
        if target in modules and target != module:
            out.setdefault(target, f"{where}:{line} {how}")

    def deepest(name: str) -> str:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    docstrings = _docstrings(tree)
    relative_names = _imports_by_relative_name(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(deepest(alias.name), node.lineno, f"imports {alias.name}")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                add(sub if sub in modules else deepest(base), node.lineno, f"imports {sub}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            text = node.value
            if _ABSOLUTE_NAME.match(text):
                add(deepest(text.partition(":")[0]), node.lineno, f"loads {text!r} by name")
            elif relative_names and _RELATIVE_NAME.match(text):
                add(f"{package}.{text}", node.lineno, f"loads {text!r} by relative name")
    return out


@functools.cache
def import_graph(root: str = ROOT) -> dict[str, dict[str, str]]:
    """warpcli's import graph: module -> {imported module: "file:line how"}."""
    modules = _module_files(root)
    return {m: _edges(m, p, modules, os.path.dirname(root)) for m, p in modules.items()}


def _component(module: str) -> tuple[int, str] | None:
    """(layer index, component) of a module: the component listing its longest prefix."""
    parts = _short(module).split(".")
    for k in range(len(parts), 0, -1):
        prefix = ".".join(parts[:k])
        for index, (_, components) in enumerate(LAYERS):
            for name, members in components.items():
                if prefix in members:
                    return index, name
    return None


def _path(graph: dict[str, dict[str, str]], start: str, goal: str) -> list[str]:
    """The edges of a shortest chain of imports from start to goal, as "file:line how" lines."""
    parent = {start: None}
    queue = deque([start])
    while queue:
        m = queue.popleft()
        if m == goal:
            break
        for t in graph[m]:
            if t not in parent:
                parent[t] = m
                queue.append(t)
    chain = []
    while parent.get(goal) is not None:
        chain.append(graph[parent[goal]][goal])
        goal = parent[goal]
    return chain[::-1]


def _reach(graph: dict[str, dict[str, str]], start: str) -> set[str]:
    seen, stack = set(), [start]
    while stack:
        for t in graph[stack.pop()]:
            if t not in seen:
                seen.add(t)
                stack.append(t)
    seen.discard(start)
    return seen


def _cycles(graph: dict[str, dict[str, str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(graph[root]))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(graph[child])))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = set()
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    component.add(m)
                    if m == node:
                        break
                if len(component) > 1:
                    found.append(component)
    return found


def _describe_cycle(graph: dict[str, dict[str, str]], component: set[str]) -> str:
    first = min(component)
    inner = {m: {t: how for t, how in graph[m].items() if t in component} for m in component}
    back = min(m for m in component if first in inner[m])
    chain = _path(inner, first, back) + [inner[back][first]]
    return f"cycle between {', '.join(sorted(_short(m) for m in component))}:\n    " + "\n    ".join(chain)


_SAMPLE = {
    "__init__.py": """
import importlib
_EXPORTS = {"thing": "a.lazy"}
def __getattr__(name):
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
""",
    "base.py": '''"""Docstrings name nothing: "warpcli.top"."""''',
    "top.py": "import warpcli.a.b as b\nfrom warpcli import base\n",
    "a/__init__.py": "",
    "a/b.py": """
from typing import TYPE_CHECKING
from . import c
from .. import base
if TYPE_CHECKING:
    from .typed import T
def later():
    from .inner.deep import f
""",
    "a/c.py": "TABLE = {'x': 'warpcli.a.plugin:build', 'y': 'warpcli.a.inner.deep.f'}\n",
    "a/lazy.py": "",
    "a/plugin.py": "",
    "a/typed.py": "",
    "a/inner/__init__.py": "",
    "a/inner/deep.py": "from ...base import X\nfrom ..c import TABLE\n",
}


def test_the_graph_sees_every_kind_of_import(tmp_path):
    """The reader itself, on a package made for it: every way to import, and loading by name."""
    for name, text in _SAMPLE.items():
        (tmp_path / "warpcli" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "warpcli" / name).write_text(text)
    graph = {m: set(t) for m, t in import_graph(str(tmp_path / "warpcli")).items()}
    assert graph == {
        "warpcli": {"warpcli.a.lazy"},  # relative names, in a module that imports by them
        "warpcli.base": set(),  # a docstring is not a name
        "warpcli.top": {"warpcli.a.b", "warpcli.base"},  # import a.b.c; from package import module
        "warpcli.a": set(),
        "warpcli.a.b": {"warpcli.a.c", "warpcli.base", "warpcli.a.typed", "warpcli.a.inner.deep"},
        "warpcli.a.c": {"warpcli.a.plugin", "warpcli.a.inner.deep"},  # registry strings, module:attr or dotted
        "warpcli.a.lazy": set(),
        "warpcli.a.plugin": set(),
        "warpcli.a.typed": set(),
        "warpcli.a.inner": set(),
        "warpcli.a.inner.deep": {"warpcli.base", "warpcli.a.c"},  # from ...base import X: the module
    }
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]


def test_the_graph_of_warpcli_holds_its_registries():
    graph = import_graph()
    assert "warpcli.maps.optimize" in graph["warpcli.maps.registry"]  # "warpcli.maps.optimize:optimized"
    assert "warpcli.pipeline" in graph["warpcli"]  # the lazy exports


def test_every_module_has_a_layer():
    missing = [m for m in import_graph() if _component(m) is None]
    assert not missing, (
        "modules in no layer: "
        + ", ".join(f"{_short(m)} ({_module_files()[m]})" for m in missing)
        + "; add each to LAYERS in tests/test_layers.py, in the lowest layer it belongs to"
    )


def test_every_listed_module_exists():
    listed = {name for _, components in LAYERS for members in components.values() for name in members}
    present = {_short(m) for m in import_graph()}
    stale = sorted(n for n in listed - COMING if not any(p == n or p.startswith(n + ".") for p in present))
    assert not stale, f"LAYERS lists modules that do not exist: {', '.join(stale)}"


def test_no_import_cycles():
    graph = import_graph()
    allowed = [{f"warpcli.{m}" for m in cycle} for cycle in ALLOWED_CYCLES]
    cycles = _cycles(graph)
    bad = [_describe_cycle(graph, c) for c in cycles if c not in allowed]
    gone = [sorted(a) for a in allowed if a not in cycles]
    assert not bad, "import cycles (break each; ALLOWED_CYCLES is for cycles others are removing):\n" + "\n".join(bad)
    assert not gone, f"no longer cycles, remove them from ALLOWED_CYCLES: {gone}"


def _params():
    for module in _module_files():
        short = _short(module)
        if short in KNOWN_VIOLATIONS:
            yield pytest.param(module, id=short, marks=pytest.mark.xfail(reason=KNOWN_VIOLATIONS[short], strict=True))
        else:
            yield pytest.param(module, id=short)


@pytest.mark.parametrize("module", list(_params()))
def test_no_module_reaches_above_its_layer(module):
    graph = import_graph()
    own = _component(module)
    if own is None:
        pytest.fail(f"{_short(module)} is in no layer: add it to LAYERS in tests/test_layers.py")
    never = {(a, b): why for a, b, why in NEVER}
    bad: dict[tuple[int, str], list[str]] = {}
    for target in _reach(graph, module):
        theirs = _component(target)
        if theirs is None or theirs[1] == own[1]:
            continue  # a module in no layer fails test_every_module_has_a_layer
        if theirs[0] < own[0] and (own[1], theirs[1]) not in never:
            continue
        bad.setdefault(theirs, []).append(target)
    messages = []
    for (layer, component), targets in sorted(bad.items()):
        chains = sorted((_path(graph, module, t), t) for t in targets)
        chains.sort(key=lambda chain: len(chain[0]))
        if (own[1], component) in never:
            rule = never[own[1], component]
        elif layer == own[0]:
            rule = f"{own[1]} and {component} share layer {LAYERS[layer][0]!r} and know nothing of each other"
        else:
            rule = f"layer {LAYERS[layer][0]!r} is above {LAYERS[own[0]][0]!r}"
        messages.append(
            f"{_short(module)} ({own[1]}) reaches {component} ({rule}): "
            + ", ".join(_short(t) for _, t in chains)
            + "; the shortest chain:\n    "
            + "\n    ".join(chains[0][0])
        )
    assert not messages, "\n".join(messages)
