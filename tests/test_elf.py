"""Tests of warpcli._elf: objects LLVM emits for its JIT, loaded without LLVM, run as MCJIT runs them."""

from __future__ import annotations

import ctypes
import json
import math
import struct

import numpy as np
import pytest

from warpcli import _elf, _native

pytestmark = pytest.mark.skipif(not _elf.supported(), reason="warpcli._elf loads x86-64 Linux objects only")


def _object(ir: str) -> bytes:
    """``ir`` compiled to an object as warpcli's kernels are (`_native._Llvm`: MCJIT's target machine)."""
    target = _native._llvm()
    mod = target.llvm.parse_assembly(ir)
    mod.triple = target.llvm.get_process_triple()
    mod.data_layout = str(target.tm.target_data)
    mod.verify()
    return target.tm.emit_object(mod)


def _function(address: int, n_args: int, restype=ctypes.c_double, argtype=ctypes.c_double):
    return ctypes.CFUNCTYPE(restype, *[argtype] * n_args)(address)


def _mcjit(obj: bytes, name: str) -> int:
    return _native._llvm().add({"object": obj, "symbol": name, "externs": []})


def _hex(x: float) -> str:
    return "0x%016X" % struct.unpack("<Q", struct.pack("<d", x))[0]


def _divide(x: float, y: float) -> float:
    """x / y in IEEE arithmetic (Python raises on a zero divisor)."""
    if y != 0:
        return x / y
    if x == 0 or math.isnan(x):
        return math.nan
    return math.copysign(math.inf, x) * math.copysign(1.0, y)


def _expression(rng: np.random.Generator, depth: int) -> tuple[list[str], str, object]:
    """A random arithmetic expression of the arguments a, b, c and constants: its IR lines, its
    value's name, and a Python function computing it with the same IEEE operations."""
    lines: list[str] = []
    counter = [0]

    def node(d: int):
        if d == 0 or rng.random() < 0.2:
            if rng.random() < 0.5:
                arg = "abc"[int(rng.integers(3))]
                return f"%{arg}", (lambda env, arg=arg: env[arg])
            value = float(rng.choice([rng.normal(0, 1e3), rng.uniform(-1, 1), float(rng.integers(-9, 10)) / 8]))
            return _hex(value), (lambda env, value=value: value)
        op = str(rng.choice(["fadd", "fsub", "fmul", "fdiv"]))
        (left, fl), (right, fr) = node(d - 1), node(d - 1)
        counter[0] += 1
        name = f"%t{counter[0]}"
        lines.append(f"  {name} = {op} double {left}, {right}")
        py = {"fadd": lambda x, y: x + y, "fsub": lambda x, y: x - y, "fmul": lambda x, y: x * y,
              "fdiv": _divide}[op]  # fmt: skip
        return name, (lambda env, fl=fl, fr=fr, py=py: py(fl(env), fr(env)))

    result, fn = node(depth)
    return lines, result, fn


@pytest.mark.parametrize("seed", range(12))
def test_generated_arithmetic_runs_as_ieee_arithmetic_and_as_mcjit_runs_it(seed):
    """Random expressions with constants (a constant pool, reached by absolute relocations): the
    loaded code gives Python's IEEE results, bit for bit, and MCJIT's."""
    rng = np.random.default_rng(seed)
    bodies, checks = [], []
    for k in range(6):
        lines, result, fn = _expression(rng, 5)
        bodies.append(f"define double @f{k}(double %a, double %b, double %c) {{\n" + "\n".join(lines)
                      + f"\n  ret double {result}\n}}")  # fmt: skip
        checks.append(fn)
    obj = _object("\n".join(bodies))
    loaded = _elf.load(obj)
    args = rng.normal(0, 10, (40, 3))
    args[0] = [0.0, -0.0, 1.0]
    for k, fn in enumerate(checks):
        ours = _function(loaded.address(f"f{k}"), 3)
        theirs = _function(_mcjit(obj, f"f{k}"), 3)
        for a, b, c in args:
            got = ours(a, b, c)
            want = fn({"a": float(a), "b": float(b), "c": float(c)})
            assert struct.pack("<d", got) == struct.pack("<d", theirs(a, b, c))
            if not math.isnan(want):  # NaN's sign and payload are not Python's to say
                assert struct.pack("<d", got) == struct.pack("<d", want)


def test_tables_globals_and_c_library_calls():
    """A switch over a table, a writable global and calls of the C library (undefined symbols the
    process resolves): the same values as the table, and as libm called directly."""
    table = [1.5, -2.25, 1e300, 0.0, math.pi, -7.0, 3.0, 11.0]
    cases = "\n".join(f"    i64 {k}, label %c{k}" for k in range(8))
    blocks = "\n".join(f"c{k}:\n  ret double {_hex(v)}" for k, v in enumerate(table))
    ir = f"""
declare double @log(double)
declare double @hypot(double, double)
@counter = internal global i64 0

define double @pick(i64 %k) {{
entry:
  switch i64 %k, label %other [
{cases}
  ]
{blocks}
other:
  ret double -1.0
}}

define double @calls(double %x, double %y) {{
  %l = call double @log(double %x)
  %h = call double @hypot(double %l, double %y)
  ret double %h
}}

define i64 @count() {{
  %n = load i64, ptr @counter
  %m = add i64 %n, 1
  store i64 %m, ptr @counter
  ret i64 %m
}}
"""
    loaded = _elf.load(_object(ir), externs={"log", "hypot"})
    pick = _function(loaded.address("pick"), 1, argtype=ctypes.c_int64)
    assert [pick(k) for k in range(8)] == table and pick(8) == -1.0 and pick(-1) == -1.0
    libm = ctypes.CDLL(None)
    libm.log.restype = libm.hypot.restype = ctypes.c_double
    libm.log.argtypes, libm.hypot.argtypes = [ctypes.c_double], [ctypes.c_double, ctypes.c_double]
    calls = _function(loaded.address("calls"), 2)
    for x, y in np.random.default_rng(3).uniform(0.01, 100, (50, 2)):
        assert calls(x, y) == libm.hypot(libm.log(x), y)
    count = _function(loaded.address("count"), 0, restype=ctypes.c_int64)
    assert [count() for _ in range(3)] == [1, 2, 3]


def test_code_is_executable_and_not_writable():
    loaded = _elf.load(_object("define i64 @one() {\n  ret i64 1\n}"))
    address = loaded.address("one")
    with open("/proc/self/maps") as fh:
        for line in fh:
            span, perms = line.split()[:2]
            lo, hi = (int(x, 16) for x in span.split("-"))
            if lo <= address < hi:
                assert perms.startswith("r-x")
                break
        else:
            pytest.fail("the function's page is not mapped")


def _patched(obj: bytes, fn) -> bytes:
    data = bytearray(obj)
    fn(data)
    return bytes(data)


def _first_relocation(data: bytearray) -> int:
    """The file offset of the first relocation of a section that is loaded."""
    shoff, shnum = struct.unpack_from("<Q", data, 40)[0], struct.unpack_from("<H", data, 60)[0]
    headers = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + 64 * i) for i in range(shnum)]
    for h in headers:
        if h[1] == 4 and headers[h[7]][2] & 0x2 and headers[h[7]][1] != 0x70000001 and h[5]:
            return h[4]
    raise AssertionError("no relocation in a loaded section")


def _section(data: bytearray, name: str) -> list:
    """Section ``name``'s header fields, and its header's offset last."""
    shoff, shnum, shstrndx = struct.unpack_from("<Q", data, 40)[0], *struct.unpack_from("<HH", data, 60)
    names = struct.unpack_from("<IIQQQQIIQQ", data, shoff + 64 * shstrndx)[4]
    for i in range(shnum):
        header = list(struct.unpack_from("<IIQQQQIIQQ", data, shoff + 64 * i))
        if bytes(data[names + header[0] : names + header[0] + len(name) + 1]) == name.encode() + b"\0":
            return header + [shoff + 64 * i]
    raise AssertionError(f"no section {name}")


def _set_section(data: bytearray, name: str, flags: int = 0, align: int | None = None, kind: int | None = None,
                 offset: int | None = None, size: int | None = None) -> None:
    """Add ``flags`` to section ``name``'s, and set its alignment, type, offset or size."""
    *header, at = _section(data, name)
    header[2] |= flags
    for field, value in ((8, align), (1, kind), (4, offset), (5, size)):
        header[field] = header[field] if value is None else value
    struct.pack_into("<IIQQQQIIQQ", data, at, *header)


def test_what_it_cannot_load_is_refused_not_loaded_wrong():
    ir = f"declare double @cbrt(double)\ndefine double @f(double %x) {{\n  %y = fmul double %x, {_hex(1.1)}\n" \
         "  %z = call double @cbrt(double %y)\n  ret double %z\n}"  # fmt: skip
    obj = _object(ir)
    assert _elf.load(obj, externs={"cbrt"}).address("f")  # the object itself loads
    with pytest.raises(_elf.Unsupported, match="undefined symbol cbrt"):
        _elf.load(obj)  # a symbol it was not told it may use
    with pytest.raises(_elf.Unsupported, match="not in this process"):
        _elf.load(obj.replace(b"cbrt\0", b"cbrx\0"), externs={"cbrx"})
    with pytest.raises(_elf.Unsupported, match="no function"):
        _elf.load(obj, externs={"cbrt"}).address("g")
    refused = {
        "not ELF": b"\x7fELG" + obj[4:],
        "32-bit": _patched(obj, lambda d: d.__setitem__(4, 1)),
        "another machine": _patched(obj, lambda d: struct.pack_into("<H", d, 18, 183)),  # aarch64
        "not relocatable": _patched(obj, lambda d: struct.pack_into("<H", d, 16, 3)),  # a shared object
        "cut short": obj[: len(obj) // 2],
        "empty": b"",
        # a relocation of a kind it does not apply (R_X86_64_GOTPCREL)
        "relocation": _patched(obj, lambda d: struct.pack_into("<I", d, _first_relocation(d) + 8, 9)),
        "thread-local": _patched(obj, lambda d: _set_section(d, ".ltext", flags=0x400)),
        "over-aligned": _patched(obj, lambda d: _set_section(d, ".ltext", align=1 << 16)),
        # relocations in a section of a type it does not read (LLVM 19's compact SHT_CREL)
        "relocation section": _patched(obj, lambda d: _set_section(d, ".rela.ltext", kind=0x40000014)),
        "beyond the file": _patched(obj, lambda d: _set_section(d, ".ltext", offset=len(d) - 8)),
        "huge": _patched(obj, lambda d: _set_section(d, ".ltext", size=2**64 - 1)),
        # an 8-byte relocation at the last 4 bytes of its section (within the page's padding)
        "relocation beyond": _patched(
            obj, lambda d: struct.pack_into("<Q", d, _first_relocation(d), _section(d, ".ltext")[5] - 4)
        ),
    }
    for why, data in refused.items():
        with pytest.raises(_elf.Unsupported):
            _elf.load(data, externs={"cbrt"})
            pytest.fail(why)


def test_a_kernel_the_loader_refuses_is_loaded_by_mcjit_with_the_same_result(monkeypatch):
    def refuse(*args, **kwargs):
        raise _elf.Unsupported("refused for the test")

    x = np.array([0.4, 2.5, 300.0, -1.0, 254.5])
    results = {}
    for route in ("elf", "mcjit"):
        monkeypatch.setattr(_native, "_JIT", None)
        if route == "mcjit":
            monkeypatch.setattr(_elf, "load", refuse)
        out = np.zeros(len(x))
        _native.Kernels("warpcli.raster._kernels").store(x, out, 0.0, 255.0, True)
        assert set(_native._jit().routes.values()) == {route}
        results[route] = out.tobytes()
    assert results["elf"] == results["mcjit"] == np.array([0.0, 2.0, 255.0, 0.0, 254.0]).tobytes()


def test_the_identity_is_llvms_and_is_kept_by_what_can_be_read_without_llvm(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    truth = _native._llvm().identity
    asked = []
    real = _native._llvm

    def counted():
        asked.append(1)
        return real()

    monkeypatch.setattr(_native, "_llvm", counted)
    assert _native._identity() == truth and len(asked) == 1  # asked, then kept
    files = list((tmp_path / "warpcli").glob("identity-*.json"))
    assert len(files) == 1
    assert _native._identity() == truth and len(asked) == 1  # read back
    files[0].write_text("{not json")
    assert _native._identity() == truth and len(asked) == 2  # a damaged file is asked again
    stored = json.loads(files[0].read_text())
    stored["probe"] = stored["probe"][:-1] + ["another interpreter"]
    files[0].write_text(json.dumps(stored))  # the name of one probe, the contents of another
    assert _native._identity() == truth and len(asked) == 3
    probe = _native._machine_probe()
    other_cpu = [probe[1][0] + [[0x7, 0, 0, 0, 0, 0]], probe[1][1]]  # another leaf 7: other features
    monkeypatch.setattr(_native, "_machine_probe", lambda: probe[:1] + [other_cpu] + probe[2:])
    assert _native._identity() == truth and len(asked) == 4  # another CPU: asked, and kept apart
    kept = sorted(f.name for f in (tmp_path / "warpcli").glob("identity-*.json"))
    assert len(kept) == 2 and files[0].name in kept  # each probe's file kept: a shared cache does not thrash
    monkeypatch.setattr(_native, "_machine_probe", lambda: None)
    assert _native._identity() == truth and len(asked) == 5  # nothing to key it by: always asked


def _protection(address: int) -> str:
    with open("/proc/self/maps") as fh:
        for line in fh:
            span, perms = line.split()[:2]
            lo, hi = (int(x, 16) for x in span.split("-"))
            if lo <= address < hi:
                return perms[:3]
    raise AssertionError(f"{address:#x} is not mapped")


def test_constants_are_read_only_and_globals_writable():
    ir = f"""
@k = constant double {_hex(1.5)}
@v = global double 0.0
define ptr @constant() {{
  ret ptr @k
}}
define ptr @variable() {{
  ret ptr @v
}}
"""
    loaded = _elf.load(_object(ir))
    k = _function(loaded.address("constant"), 0, restype=ctypes.c_void_p)()
    v = _function(loaded.address("variable"), 0, restype=ctypes.c_void_p)()
    assert ctypes.c_double.from_address(k).value == 1.5
    assert _protection(k) == "r--" and _protection(v) == "rw-"
    assert _protection(loaded.address("constant")) == "r-x"


def test_an_indirect_function_is_refused():
    ir = """
define internal ptr @resolve() {
  ret ptr @impl
}
define i64 @impl() {
  ret i64 7
}
@pick = ifunc i64 (), ptr @resolve
define i64 @call() {
  %r = call i64 @pick()
  ret i64 %r
}
"""
    with pytest.raises(_elf.Unsupported, match="indirect"):
        _elf.load(_object(ir))


def test_processor_is_what_the_kernel_reads_of_the_cpu():
    """`processor`'s leaves (its own ``cpuid``, run as machine code) against /proc/cpuinfo's
    account of the same CPU: vendor, family, model, stepping and feature flags."""
    leaves, xcr0 = _elf.processor()
    by_leaf = {(n, sub): regs for n, sub, *regs in leaves}
    with open("/proc/cpuinfo") as fh:
        block = fh.read().split("\n\n")[0]
    info = dict((k.strip(), v.strip()) for k, _, v in (line.partition(":") for line in block.splitlines()))
    eax, ebx, ecx, edx = by_leaf[(0, 0)]
    assert struct.pack("<III", ebx, edx, ecx).decode() == info["vendor_id"]
    eax1, _, ecx1, edx1 = by_leaf[(1, 0)]
    family = (eax1 >> 8) & 0xF
    model = (eax1 >> 4) & 0xF
    if family in (6, 15):
        model |= ((eax1 >> 16) & 0xF) << 4
    if family == 15:
        family += (eax1 >> 20) & 0xFF
    assert (family, model, eax1 & 0xF) == (int(info["cpu family"]), int(info["model"]), int(info["stepping"]))
    flags = set(info["flags"].split())
    ebx7 = by_leaf[(7, 0)][1] if (7, 0) in by_leaf else 0
    bits = {"sse2": edx1 >> 26, "sse4_2": ecx1 >> 20, "avx": ecx1 >> 28, "avx2": ebx7 >> 5, "avx512f": ebx7 >> 16}
    for flag, bit in bits.items():
        if flag in flags:  # the kernel prints a feature the CPU has (and it has not turned off)
            assert bit & 1, flag
    assert "sse2" in flags
    if "avx" in flags:  # the OS saves the AVX registers: xgetbv runs and says so
        assert xcr0 is not None and xcr0 & 0b110 == 0b110
    assert _elf.processor() == [leaves, xcr0]
