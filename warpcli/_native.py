"""Compiled kernels without numba at run time: numba compiles them once, later processes load the machine code.

warpcli's inner loops are numba functions (``@njit`` in the ``_kernels``
modules). Importing numba and loading even cached functions costs about 0.4 s
in every process (numba builds its typing and lowering registries, which also
import scipy.linalg): more than a whole 1-megapixel warp. So a kernel is called
through `Kernels`, which compiles it with numba only once per argument types,
as a C-callable wrapper (`numba.cfunc` over `numba.carray` views of the
arrays), keeps that machine code on disk (the object file LLVM emits for
MCJIT), and in later processes loads it and calls it through ctypes, with
numba never imported. On x86-64 Linux `warpcli._elf` loads the object (a
fraction of a millisecond per kernel, no LLVM in the process); elsewhere, or
for an object it refuses, llvmlite's MCJIT does (0.04 s of CPU and 50 MB of
memory to load llvmlite, then a millisecond per kernel). Both run the same
bytes of machine code.

The code is numba's own: the same function compiled for the same array types
(C-contiguous, as numba types a contiguous array), emitted for this CPU with
the options numba's JIT uses. Without fast-math flags (numba's default) LLVM
keeps every floating-point operation as written (no reassociation, no fused
multiply-add), so results are bit for bit those of calling the ``@njit``
function (tests/test_native.py checks every kernel). Anything the native route
does not cover runs the ``@njit`` function itself, with the same results: arguments other than C-contiguous aligned arrays
and Python ints, floats and bools; ``NUMBA_DISABLE_JIT=1``;
``WARPCLI_NATIVE=0``; a kernel whose code needs numba's runtime (allocation:
kernels take scratch arrays instead); a missing llvmlite.

Only numba's error paths are left out: the wrapper's hand-over of an exception
to Python and the release of arrays numba allocated, which these kernels never
reach (they raise nothing and allocate nothing). Their calls are bound to a
trap, so a kernel that did reach one would stop the process rather than
corrupt memory. Any other outside reference refuses the native route.

The cache lives beside numba's: ``__pycache__`` next to the kernel module, or
``$NUMBA_CACHE_DIR/warpcli``, or the user's cache directory when the package's
is not writable. Each entry is keyed by the kernel's source (and the sources
it names), the argument types, numba's and llvmlite's versions and this CPU,
so an edit, an upgrade or another machine compiles anew (LLVM's name of this
CPU and its features are kept in the cache too, `_identity`, so that loading
needs no LLVM); files are written
atomically, so concurrent processes are safe, and a process about to compile
a kernel another one is compiling waits for that one's file (a lock file
beside it) instead of compiling it too.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import logging
import mmap
import os
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import IO, Any

import numpy as np

# ctypes, json and tempfile are imported where kernels are loaded
# (usually on the thread that loads them while the maps are solved), not here.

__all__ = ["Kernels", "cores", "locked_file", "native_enabled", "parallel"]

_log = logging.getLogger("warpcli")

#: Bumped when the cache format or the way wrappers are made changes.
_FORMAT = 2
_MAGIC = b"warpcli-native\n"

#: Environment variable: ``0`` calls the numba functions themselves.
NATIVE_ENV = "WARPCLI_NATIVE"

# Outside references that numba emits for its error paths only (raising into
# Python, freeing arrays it allocated): bound to a trap (see the module docstring).
_ERROR_PATH = frozenset(
    {
        "numba_gil_ensure", "numba_gil_release", "numba_unpickle", "numba_do_raise",
        "numba_runtime_build_excinfo_struct", "numba_fatal_error", "NRT_Free", "NRT_MemInfo_call_dtor",
        "PyErr_WriteUnraisable", "PyErr_Clear", "PyErr_SetString", "PyErr_SetNone", "PyErr_SetObject",
        "PyErr_Occurred", "PyErr_Fetch", "PyErr_Restore", "PyErr_NoMemory", "Py_DecRef", "Py_IncRef",
        "PyUnicode_FromString", "PyBytes_FromStringAndSize", "PyExc_RuntimeError", "PyExc_StopIteration",
        "PyExc_SystemError", "PyExc_MemoryError", "PyExc_ZeroDivisionError", "PyExc_ValueError",
        "PyExc_IndexError", "PyExc_TypeError", "PyExc_AssertionError", "PyExc_NotImplementedError",
    }
)  # fmt: skip

# C library functions the code may call, found in every process.
_LIBC = frozenset(
    {
        "memset", "memcpy", "memmove", "ceil", "floor", "trunc", "rint", "nearbyint", "round", "sqrt",
        "fabs", "fmod", "pow", "exp", "log", "sin", "cos", "tan", "atan2", "hypot",
    }
)  # fmt: skip


def cores() -> int:
    """The cores this run may keep busy (`warpcli.cores.budget`: ``--jobs``, else the process's affinity)."""
    from .cores import budget

    return budget()


def parallel(fn: Callable[[Any], None], parts: Sequence[Any]) -> None:
    """``fn(part)`` for every part, the parts shared out over `cores` threads (none with a budget of 1).

    For independent pieces of work that write disjoint outputs, mostly in
    kernels (which release the GIL): the results do not depend on how the
    parts are shared out. The first error raised is raised here, after every
    thread has finished.
    """
    workers = min(len(parts), cores())
    if workers <= 1:
        for part in parts:
            fn(part)
        return
    errors: list[BaseException] = []
    # each thread takes the next part when it is free (parts of unequal work: a pull-back's bands
    # of rows cross a polygon's widest rows or miss it; every other part fixed to one thread left
    # a core idle for a third of a 1 MP BEM pull-back, measured)
    todo = iter(parts)
    lock = threading.Lock()

    def run() -> None:
        try:
            while not errors:
                with lock:
                    part = next(todo, todo)
                if part is todo:
                    return
                fn(part)
        except BaseException as err:  # raised by the caller below
            errors.append(err)

    threads = [threading.Thread(target=run) for _ in range(1, workers)]
    for t in threads:
        t.start()
    run()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]


def _sha256(data: bytes = b"") -> Any:
    """``hashlib.sha256(data)``, from the interpreter's own SHA-256 where it has one: importing
    hashlib loads OpenSSL first (8-15 ms a process, measured), for the same digests."""
    for name in ("_sha2", "_sha256"):  # CPython 3.12+, 3.11
        try:
            return importlib.import_module(name).sha256(data)
        except (ImportError, AttributeError):
            continue
    import hashlib

    return hashlib.sha256(data)


def native_enabled() -> bool:
    """Whether kernels may run as cached machine code (else as numba functions)."""
    return os.environ.get(NATIVE_ENV, "1") != "0" and os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")


class Kernels:
    """The compiled kernels of one module, called by attribute name.

    Parameters
    ----------
    module : str
        The module defining the ``@njit`` kernels, e.g.
        ``"warpcli.raster._kernels"``; imported only to compile (or when the
        native route is not taken).
    depends : sequence of str
        Other source files, relative to the module's directory, whose contents
        the compiled code depends on (constants numba freezes at compile time).

    Examples
    --------
    >>> k = Kernels("warpcli.raster._kernels")
    >>> out = np.zeros(3)
    >>> k.store(np.array([0.4, 2.5, 300.0]), out, 0.0, 255.0, True)
    >>> out.tolist()
    [0.0, 2.0, 255.0]
    """

    def __init__(self, module: str, depends: Sequence[str] = ()) -> None:
        self.module = module
        self.depends = tuple(depends)
        self._calls: dict[tuple, Callable[..., Any]] = {}
        self._source_digest: tuple[str, str] | None = None

    def __getattr__(self, name: str) -> Callable[..., Any]:
        if name.startswith("_"):
            raise AttributeError(name)

        def call(*args: Any) -> Any:
            return self._call(name, args)

        call.__name__ = name
        call.__qualname__ = f"{self.module}.{name}"
        self.__dict__[name] = call
        return call

    def _call(self, name: str, args: tuple) -> Any:
        variant = _variant(args)
        fn = self._calls.get((name, variant)) if variant is not None else None
        if fn is None:
            fn = self._resolve(name, variant)
        return fn(*args)

    def _resolve(self, name: str, variant: tuple | None) -> Callable[..., Any]:
        with _LOCK:
            fn = self._calls.get((name, variant)) if variant is not None else None
            if fn is not None:
                return fn
            native = None
            if variant is not None and native_enabled():
                try:
                    native = self._native(name, variant)
                except Exception as err:  # any failure falls back to numba, with the same results
                    _log.debug("kernel %s.%s%s: native route not taken (%s: %s)", self.module, name, variant,
                               type(err).__name__, err)  # fmt: skip
            fn = native or getattr(importlib.import_module(self.module), name)
            if variant is not None:
                self._calls[(name, variant)] = fn
            return fn

    # The native route.

    def _source(self) -> tuple[str, str]:
        """A digest of the kernel module's source (and of the files it depends on), and its folder."""
        if self._source_digest is None:
            spec = importlib.util.find_spec(self.module)
            if spec is None or not spec.origin:
                raise ImportError(f"no source for {self.module}")
            folder = os.path.dirname(spec.origin)
            h = _sha256()
            for path in (spec.origin, *(os.path.join(folder, d) for d in self.depends)):
                with open(path, "rb") as fh:
                    h.update(fh.read())
            self._source_digest = (h.hexdigest(), folder)
        return self._source_digest

    def _native(self, name: str, variant: tuple) -> Callable[..., Any]:
        import json

        jit = _jit()
        digest, folder = self._source()
        key = _sha256(json.dumps([_FORMAT, self.module, name, variant, digest, jit.identity]).encode())
        symbol = f"warpcli_{name}_{key.hexdigest()[:24]}"
        if not jit.has(symbol):
            # One file per kernel and argument types; a new source, numba or
            # CPU gives it a new key, and the file it replaces is removed.
            kind = _sha256(json.dumps([self.module, name, variant]).encode()).hexdigest()[:8]
            filename = f"{self.module.rsplit('.', 1)[-1]}.{name}.{kind}-{key.hexdigest()[:24]}.native"
            dirs = _cache_dirs(folder)
            entry = _cached_entry(dirs, filename, symbol)
            if entry is None:
                # Processes starting together on a fresh install (a farm, ``pytest -n``) would each
                # compile the same kernel (seconds of CPU each): one compiles, the others wait for
                # it and load its file.
                with compiling_kernel(), _compiling(dirs, filename):
                    entry = _cached_entry(dirs, filename, symbol)
                    if entry is None:
                        _say_compiling(dirs)
                        entry = _compile(self.module, name, variant, symbol, _llvm())
                        jit.add(entry)  # kept only if it loads
                        _write_entry(dirs, filename, entry)
                        return jit.function(symbol, variant)
            jit.add(entry)
        return jit.function(symbol, variant)


def _variant(args: tuple) -> tuple | None:
    """What the compiled code depends on in the arguments, or None if the native route cannot take them.

    Arrays must be C-contiguous and aligned (numba types them ``C``);
    scalars are Python ints (int64), floats (float64) and bools.
    """
    out = []
    for a in args:
        if isinstance(a, np.ndarray):
            flags = a.flags
            if not (flags.c_contiguous and flags.aligned) or a.dtype.kind not in "biuf" or not a.dtype.isnative:
                return None
            out.append((a.dtype.str, a.ndim))
        elif isinstance(a, bool):
            out.append("b")
        elif isinstance(a, int):
            if not -(2**63) <= a < 2**63:
                return None
            out.append("i")
        elif isinstance(a, float):
            out.append("f")
        else:
            return None
    return tuple(out)


_LOCK = threading.RLock()
_JIT = None
_LLVM = None

#: How many of this process's threads are compiling a kernel, or waiting for another process
#: compiling it (`compiling`).
_BUSY = [0]
_BUSY_LOCK = threading.Lock()
_SAID = [False]
#: Each process's count (capped at 255) in the byte of its pid modulo the size, in memory shared
#: with the children it forks (which build maps, and compile what they need there). Only a
#: process's own byte is written by it.
_SHARED_BUSY = mmap.mmap(-1, 4096)


def _count_busy(change: int) -> None:
    with _BUSY_LOCK:
        _BUSY[0] += change
        _SHARED_BUSY[os.getpid() % len(_SHARED_BUSY)] = min(_BUSY[0], 255)


@contextlib.contextmanager
def compiling_kernel() -> Iterator[None]:
    """Mark the block as compiling a kernel (or waiting for one being compiled elsewhere): `compiling`."""
    _count_busy(1)
    try:
        yield
    finally:
        _count_busy(-1)


def process_gone(pid: int) -> None:
    """A child forked by this process was killed: what it was compiling no longer counts."""
    _SHARED_BUSY[pid % len(_SHARED_BUSY)] = 0


def compiling() -> bool:
    """Whether this process, or a child it forked, is compiling a kernel now (or waiting for another
    process to).

    That happens on the first runs after an install or an upgrade (each
    kernel once per argument types, cached on disk after): a first BEM warp
    compiles for about 10 s, most of it in the children that build the maps.
    The ``warp`` command's progress line says so (`warpcli.cli.progress`), so
    that nobody takes it for the warp's speed.
    """
    return bool(_SHARED_BUSY[:].strip(b"\0"))


def _say_compiling(dirs: list[str]) -> None:
    """Log once per process (``-v``) that kernels are being compiled, and where they are kept."""
    if not _SAID[0]:
        _SAID[0] = True
        _log.info("compiling warpcli's kernels for this machine (once: they are kept in %s)", dirs[0])




def _hold_for_fork() -> None:
    _LOCK.acquire()


def _release_after_fork() -> None:
    _LOCK.release()


def _new_lock_in_child() -> None:
    global _LOCK, _BUSY_LOCK
    _LOCK = threading.RLock()
    _BUSY_LOCK = threading.Lock()
    _BUSY[0] = 0  # the parent's threads, compiling or not, are not this process's
    _SHARED_BUSY[os.getpid() % len(_SHARED_BUSY)] = 0  # nor a byte left by a process of this pid before


if hasattr(os, "register_at_fork"):
    # A forked child may load kernels (a BEM or MFS map certified there: `warpcli._fork`): a fork
    # waits until no thread of the parent is loading one, so the child never inherits the lock
    # held, or the JIT engine half way through adding a kernel, by a thread it does not have.
    os.register_at_fork(before=_hold_for_fork, after_in_parent=_release_after_fork, after_in_child=_new_lock_in_child)


class _Llvm:
    """llvmlite's MCJIT engine and this CPU's target machine: to compile kernels, and to load those
    `warpcli._elf` does not (another machine, or an object it refuses)."""

    def __init__(self) -> None:
        import llvmlite
        import llvmlite.binding as llvm

        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        self.llvm = llvm
        triple = llvm.get_process_triple()
        cpu = llvm.get_host_cpu_name()
        try:
            features = llvm.get_host_cpu_features().flatten()
        except RuntimeError:
            features = ""
        target = llvm.Target.from_triple(triple)
        # The target machine of numba's JIT (numba.core.codegen.JITCPUCodegen):
        # this CPU, static relocations on x86, the JIT code model.
        reloc = "static" if target.name.startswith("x86") else ("pic" if target.name.startswith("ppc") else "default")
        self.tm = target.create_target_machine(
            cpu=cpu, features=features, opt=3, reloc=reloc, codemodel="jitdefault", jit=True
        )
        self.engine = llvm.create_mcjit_compiler(llvm.parse_assembly(""), self.tm)
        self._objects: list = []
        #: What the machine code depends on besides the kernel and its arguments.
        self.identity = [triple, cpu, features, llvmlite.__version__, _numba_version(), sys.implementation.cache_tag]

    def add(self, entry: dict) -> int:
        """Load a compiled kernel (an entry of `_compile` or of the cache); the address of its function."""
        llvm = self.llvm
        missing = [s for s in entry["externs"] if not llvm.address_of_symbol(s)]
        if missing:
            # MCJIT would abort the process on an unresolved symbol: refuse first.
            raise RuntimeError(f"unresolved symbols {missing}")
        obj = llvm.ObjectFileRef.from_data(entry["object"])
        self.engine.add_object_file(obj)
        self.engine.finalize_object()
        self._objects.append(obj)
        address = self.engine.get_function_address(entry["symbol"])
        if not address:
            raise RuntimeError(f"no symbol {entry['symbol']} in the compiled code")
        return address


def _numba_version() -> str:
    """A digest of the installed numba's version file, read without importing numba ("" if none)."""
    spec = importlib.util.find_spec("numba")
    if spec is None or not spec.origin:
        return ""
    try:
        with open(os.path.join(os.path.dirname(spec.origin), "_version.py"), "rb") as fh:
            return _sha256(fh.read()).hexdigest()[:16]
    except OSError:
        return ""


def _identity() -> list:
    """What the machine code depends on besides the kernel and its arguments: `_Llvm.identity`.

    Asking LLVM for this CPU's name and features means loading llvmlite (most
    of the 0.04 s that `warpcli._elf` saves), so the answer is kept in the
    cache, in a file named by a digest of everything it depends on that can be
    read without LLVM (`_machine_probe`): what LLVM reads of the processor,
    llvmlite's and numba's installed files, the interpreter. A new CPU, an
    upgrade or another machine sharing the cache finds no file and asks LLVM.
    """
    import json

    probe = _machine_probe()
    if probe is None:
        return _llvm().identity
    filename = f"identity-{_sha256(json.dumps(probe).encode()).hexdigest()[:24]}.json"
    dirs = _cache_dirs(os.path.dirname(os.path.abspath(__file__)))
    for d in dirs:
        try:
            with open(os.path.join(d, filename), "rb") as fh:
                stored = json.loads(fh.read())
        except (OSError, ValueError):
            continue
        if isinstance(stored, dict) and stored.get("probe") == probe and isinstance(stored.get("identity"), list):
            return stored["identity"]
    identity = _llvm().identity
    # Kept beside those of other probes (interpreters or machines sharing the cache).
    _write_file(dirs, filename, json.dumps({"probe": probe, "identity": identity}).encode(), replace=False)
    return identity


def _machine_probe() -> list | None:
    """What `_identity` depends on, read without LLVM: what LLVM reads of the processor
    (`warpcli._elf.processor`: the ``cpuid`` leaves and the OS's enabled register state, so a
    CPU, a VM or an emulator that reports other features gets another file), llvmlite's and
    numba's installed files and the interpreter; None where `warpcli._elf` does not load the
    kernels (they are loaded with llvmlite then, which answers at no extra cost)."""
    from . import _elf

    if not _elf.supported():
        return None
    spec = importlib.util.find_spec("llvmlite")
    if spec is None or not spec.origin:
        return None
    folder = os.path.dirname(spec.origin)
    try:
        with open(os.path.join(folder, "_version.py"), "rb") as fh:
            version = fh.read().decode("utf-8", "replace")
        library = os.stat(os.path.join(folder, "binding", "libllvmlite.so"))
        cpu = _elf.processor()
    except (OSError, _elf.Unsupported):
        return None
    return [_FORMAT, cpu, version, [library.st_size, library.st_mtime_ns], _numba_version(),
            sys.implementation.cache_tag]  # fmt: skip


#: Whether cached kernels are loaded by `warpcli._elf` where it can (else always by MCJIT).
ELF_LOADER = True


class _Code:
    """Every kernel loaded in this process, by symbol; and what their machine code depends on.

    A kernel's object is loaded by `warpcli._elf` where it can be (x86-64
    Linux: no llvmlite in the process), else by MCJIT; the bytes run are the
    same either way.
    """

    def __init__(self) -> None:
        self._loaded: dict[str, tuple[int, str]] = {}  # symbol: (address, return type)
        self._identity: list | None = None
        #: How each kernel was loaded: "elf" or "mcjit".
        self.routes: dict[str, str] = {}

    @property
    def identity(self) -> list:
        """What the machine code depends on besides the kernel and its arguments (`_identity`)."""
        if self._identity is None:
            self._identity = _identity()
        return self._identity

    def has(self, symbol: str) -> bool:
        """Whether the kernel ``symbol`` is loaded (a kernel is loaded once per process)."""
        return symbol in self._loaded

    def add(self, entry: dict) -> None:
        """Load a compiled kernel (an entry of `_compile` or of the cache)."""
        from . import _elf

        address, route = None, "elf"
        if ELF_LOADER and _elf.supported():
            symbol = entry["symbol"]
            try:
                address = _elf.load(entry["object"], _LIBC, (symbol,)).address(symbol)
            except Exception as err:  # noqa: BLE001  (MCJIT loads whatever this loader does not)
                _log.debug("kernel %s: loaded by MCJIT (%s: %s)", symbol, type(err).__name__, err)
        if address is None:
            address, route = _llvm().add(entry), "mcjit"
        self._loaded[entry["symbol"]] = (address, entry["restype"])
        self.routes[entry["symbol"]] = route

    def function(self, symbol: str, variant: tuple) -> Callable[..., Any]:
        """A Python callable for the loaded kernel ``symbol``, taking arguments of ``variant``."""
        import ctypes

        address, ret = self._loaded[symbol]
        params: list = []
        for code in variant:
            if isinstance(code, tuple):  # an array: its data pointer, then its shape
                params += [ctypes.c_void_p] + [ctypes.c_int64] * code[1]
            else:
                params.append(ctypes.c_double if code == "f" else ctypes.c_int64)
        restype = {"int64": ctypes.c_int64, "float64": ctypes.c_double, "void": None}[ret]
        # CFUNCTYPE releases the GIL for the call, as ``nogil=True`` does.
        cfn = ctypes.CFUNCTYPE(restype, *params)(address)
        arrays = [isinstance(code, tuple) for code in variant]

        def call(*args: Any) -> Any:
            flat = []
            for a, is_array in zip(args, arrays):
                if is_array:
                    flat.append(a.ctypes.data)
                    flat.extend(a.shape)
                else:
                    flat.append(a)
            return cfn(*flat)

        call._native = cfn  # type: ignore[attr-defined]  # keeps the function, and says which route was taken
        return call


def _jit() -> _Code:
    global _JIT
    if _JIT is None:
        _JIT = _Code()
    return _JIT


def _llvm() -> _Llvm:
    global _LLVM
    if _LLVM is None:
        _LLVM = _Llvm()
    return _LLVM


def _cache_dirs(folder: str) -> list[str]:
    """Where cached kernels are looked for, in order; the first writable one gets new ones."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return [os.path.join(env, "warpcli")]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [os.path.join(folder, "__pycache__"), os.path.join(base, "warpcli", "native")]


def _cached_entry(dirs: list[str], filename: str, symbol: str) -> dict | None:
    """The cache's entry ``filename`` for ``symbol`` in the first of ``dirs`` that has it, or None."""
    for d in dirs:
        entry = _read_entry(os.path.join(d, filename))
        if entry is not None and entry.get("symbol") == symbol:
            return entry
    return None


@contextlib.contextmanager
def _compiling(dirs: list[str], filename: str) -> Iterator[None]:
    """Hold the lock of kernel ``filename`` (a lock file in the first writable cache directory).

    A process compiling a kernel holds it; another one needing the same
    kernel waits, then finds the file written. Where no directory is writable
    or there is no ``fcntl``, nothing is held (each process compiles; the
    cache's atomic writes keep that safe). The lock file is named by the
    kernel and its argument types, not by its source: an edit reuses it.
    """
    lock = f".{filename.rsplit('-', 1)[0]}.lock"
    for d in dirs:
        try:
            os.makedirs(d, exist_ok=True)
            fh = locked_file(os.path.join(d, lock))
        except OSError:
            continue
        with fh:
            yield
        return
    yield


def locked_file(path: str) -> IO[str]:
    """``path`` opened for appending, with an exclusive ``flock`` on it: the lock is released
    when the file is closed (use it in a ``with``).

    Raises OSError when the file cannot be opened. Where there is no ``fcntl``
    (not POSIX) or the file system has no locks, the file is returned unlocked.
    Used by both compile locks: this module's kernels and numba's (`warpcli._jit`).
    """
    fh = open(path, "a")  # noqa: SIM115  (the caller closes it)
    try:
        import fcntl

        fcntl.flock(fh, fcntl.LOCK_EX)
    except (ImportError, OSError):  # not POSIX, or a file system without locks
        pass
    return fh


def _read_entry(path: str) -> dict | None:
    import json

    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None
    if not data.startswith(_MAGIC):
        return None
    head, sep, obj = data[len(_MAGIC) :].partition(b"\n")
    if not sep:
        return None
    try:
        entry = json.loads(head)
    except ValueError:
        return None
    if len(obj) != entry.get("size") or _sha256(obj).hexdigest() != entry.get("sha256"):
        return None  # cut short or damaged: compiled again
    entry["object"] = obj
    return entry


def _write_entry(dirs: list[str], filename: str, entry: dict) -> None:
    import json

    head = {k: v for k, v in entry.items() if k != "object"}
    head["size"] = len(entry["object"])
    head["sha256"] = _sha256(entry["object"]).hexdigest()
    _write_file(dirs, filename, _MAGIC + json.dumps(head).encode() + b"\n" + entry["object"])


def _write_file(dirs: list[str], filename: str, data: bytes, replace: bool = True) -> None:
    """Write ``data`` atomically to ``filename`` in the first writable of ``dirs``; with
    ``replace``, removing the files it replaces there: those of the same name up to its last
    ``-`` (older keys)."""
    import tempfile

    for d in dirs:
        try:
            os.makedirs(d, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{filename}.", dir=d)
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(data)
                os.chmod(tmp, 0o644)  # like numba's cache files (mkstemp makes them private)
                os.replace(tmp, os.path.join(d, filename))
            except BaseException:
                os.unlink(tmp)
                raise
            stem, suffix = filename.rsplit("-", 1)[0] + "-", os.path.splitext(filename)[1]
            for old in os.listdir(d) if replace else ():
                if old.startswith(stem) and old.endswith(suffix) and old != filename:
                    with contextlib.suppress(OSError):
                        os.unlink(os.path.join(d, old))
            return
        except OSError:
            continue
    _log.debug("no writable cache directory for %s (tried %s)", filename, ", ".join(dirs))


def _compile(module: str, name: str, variant: tuple, symbol: str, llvm: _Llvm) -> dict:
    """Compile kernel ``name`` of ``module`` for ``variant`` with numba; its machine code and how to call it."""
    from numba import carray, cfunc, from_dtype, types

    dispatcher = getattr(importlib.import_module(module), name)
    argtypes, params, names, call = [], [], [], []
    for i, code in enumerate(variant):
        if isinstance(code, tuple):
            dtype, ndim = from_dtype(np.dtype(code[0])), code[1]
            dims = [f"n{i}_{d}" for d in range(ndim)]
            argtypes.append(types.Array(dtype, ndim, "C"))
            params += [types.CPointer(dtype)] + [types.int64] * ndim
            names += [f"p{i}", *dims]
            call.append(f"carray(p{i}, ({', '.join(dims)},))")
        else:
            argtypes.append({"i": types.int64, "f": types.float64, "b": types.boolean}[code])
            params.append(types.float64 if code == "f" else types.int64)
            names.append(f"x{i}")
            call.append(f"x{i} != 0" if code == "b" else f"x{i}")
    dispatcher.compile(tuple(argtypes))
    restype = next(s.return_type for s in dispatcher.nopython_signatures if tuple(s.args) == tuple(argtypes))
    if restype == types.none:
        ret, sig = "void", types.void(*params)
    elif restype in (types.int64, types.float64):
        ret, sig = str(restype), restype(*params)
    else:
        raise TypeError(f"{name} returns {restype}; the native route takes int64, float64 or nothing")
    namespace = {"kernel": dispatcher, "carray": carray}
    exec(f"def wrapper({', '.join(names)}):\n    return kernel({', '.join(call)})\n", namespace)  # noqa: S102
    wrapper = cfunc(sig)(namespace["wrapper"])
    obj, externs = _machine_code(llvm, wrapper.inspect_llvm(), wrapper.native_name, symbol)
    return {"format": _FORMAT, "symbol": symbol, "restype": ret, "externs": externs, "object": obj}


def _machine_code(target: _Llvm, ir: str, entry_name: str, symbol: str) -> tuple[bytes, list[str]]:
    """The object code of a wrapper's module, self-contained but for the C library.

    The entry is renamed to ``symbol`` and everything else made internal, so
    kernels compiled in different processes never clash in one engine; numba's
    error-path references are bound to a trap (see the module docstring).
    """
    llvm = target.llvm
    mod = llvm.parse_assembly(ir)
    externs, stubs = [], []
    for fn in mod.functions:
        if not fn.is_declaration or fn.name.startswith("llvm."):
            continue
        if fn.name in _LIBC:
            externs.append(fn.name)
        elif fn.name in _ERROR_PATH:
            ret, _, args = str(fn.global_value_type).partition(" (")  # "ret (args)"
            stubs.append(f"define {ret} @{fn.name}({args[:-1]}) {{\n  call void @llvm.trap()\n  unreachable\n}}")
        else:
            raise RuntimeError(f"compiled code calls {fn.name}, which only numba's runtime provides")
    for gv in mod.global_variables:
        if gv.is_declaration:
            if gv.name not in _ERROR_PATH:
                raise RuntimeError(f"compiled code uses {gv.name}, which only numba's runtime provides")
            stubs.append(f"@{gv.name} = global {gv.global_value_type} zeroinitializer")
    if stubs:
        stub = llvm.parse_assembly("declare void @llvm.trap()\n" + "\n".join(stubs) + "\n")
        stub.triple = mod.triple
        stub.data_layout = mod.data_layout
        mod.link_in(stub)
    mod.get_function(entry_name).name = symbol
    for fn in mod.functions:
        if not fn.is_declaration and fn.name != symbol:
            fn.linkage = "internal"
    for gv in mod.global_variables:
        if not gv.is_declaration:
            gv.linkage = "internal"
    mod.verify()
    return target.tm.emit_object(mod), sorted(externs)
