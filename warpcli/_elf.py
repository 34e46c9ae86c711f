"""Load the code of a relocatable x86-64 ELF object into this process, without LLVM.

`warpcli._native` keeps each compiled kernel as the object file LLVM emits for
its JIT (MCJIT's target machine: static relocations, the large code model).
Loading it through llvmlite costs every process about 0.04 s of CPU (the
178 MB library, its bindings, the engine) before the first kernel runs. Such
an object is simple enough to load here: its sections are copied into fresh
pages, its relocations applied (on x86-64 Linux the large code model makes
them absolute 64-bit addresses, ``R_X86_64_64``, of its own sections and of
C library functions), its code pages made read-and-execute and its read-only
data read-only. That is the work MCJIT's runtime linker does for these
objects, on the same bytes, so the kernels run the very machine code MCJIT
would run.

Anything outside that (another machine or format, a relocation, section or
symbol of another kind, a symbol the C library does not define, a section or
relocation reaching outside the file or its section, memory that cannot be
made executable) raises `Unsupported`, and the caller loads the object with
MCJIT instead. Unwind tables (``.eh_frame``) are not loaded: no exception
unwinds through a kernel, and their relocations are the only ones left out.

`processor` reads what LLVM reads to name this CPU and its features (the
``cpuid`` instruction and the OS's enabled register state), for
`warpcli._native` to key what it keeps of LLVM's answer.
"""

from __future__ import annotations

import ctypes
import os
import struct
import sys
from collections.abc import Iterable

__all__ = ["Loaded", "Unsupported", "load", "processor", "supported"]


class Unsupported(Exception):
    """This object, or this process, is not for this loader: load it with MCJIT."""


# ELF constants (System V ABI, AMD64 supplement).
_ET_REL, _EM_X86_64 = 1, 62
_SHT_PROGBITS, _SHT_SYMTAB, _SHT_STRTAB, _SHT_RELA, _SHT_NOTE, _SHT_NOBITS = 1, 2, 3, 4, 7, 8
_SHT_GROUP, _SHT_X86_64_UNWIND = 17, 0x70000001
_SHT_LLVM_LO, _SHT_LLVM_HI = 0x6FFF4C00, 0x6FFF4CFF  # LLVM's own annotations (address-significance...)
_SHF_WRITE, _SHF_ALLOC, _SHF_EXECINSTR, _SHF_TLS = 0x1, 0x2, 0x4, 0x400
_SHN_UNDEF, _SHN_LORESERVE, _SHN_ABS = 0, 0xFF00, 0xFFF1
_STT_GNU_IFUNC = 10
_R_X86_64_64, _R_X86_64_PC32, _R_X86_64_PC64 = 1, 2, 24
_WIDTH = {_R_X86_64_64: 8, _R_X86_64_PC32: 4, _R_X86_64_PC64: 8}

_PROT_READ, _PROT_WRITE, _PROT_EXEC = 1, 2, 4
_MAP_PRIVATE, _MAP_ANONYMOUS = 0x02, 0x20
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096

#: Where each loaded section goes, by its flags, and that region's final protection.
_PROTECTION = {"code": _PROT_READ | _PROT_EXEC, "rodata": _PROT_READ, "data": _PROT_READ | _PROT_WRITE}


def supported() -> bool:
    """Whether this process can load objects here (64-bit x86 Linux)."""
    return sys.platform.startswith("linux") and os.uname().machine in ("x86_64", "amd64") and sys.maxsize > 2**32


_C_LIBRARY = None


def _libc():
    global _C_LIBRARY
    if _C_LIBRARY is None:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.mmap.restype = ctypes.c_void_p
        libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_long]
        libc.mprotect.restype = ctypes.c_int
        libc.mprotect.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
        libc.munmap.restype = ctypes.c_int
        libc.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
        _C_LIBRARY = libc
    return _C_LIBRARY


def _pages(size: int) -> int:
    """The address of ``size`` bytes (a whole number of pages) of fresh private read-write memory."""
    address = _libc().mmap(None, size, _PROT_READ | _PROT_WRITE, _MAP_PRIVATE | _MAP_ANONYMOUS, -1, 0)
    if address is None or address == ctypes.c_void_p(-1).value:
        raise Unsupported(f"no memory: {os.strerror(ctypes.get_errno())}")
    return address


class Loaded:
    """An object's code in this process's memory: its global functions by name.

    The memory stays mapped for as long as the process lives (kernels are
    loaded once per process and never unloaded).
    """

    def __init__(self, functions: dict[str, int]) -> None:
        self.functions = functions

    def address(self, name: str) -> int:
        try:
            return self.functions[name]
        except KeyError:
            raise Unsupported(f"no function {name} in the object") from None


def _round_up(n: int, to: int) -> int:
    return (n + to - 1) // to * to


def load(data: bytes, externs: Iterable[str] = (), entries: Iterable[str] = ()) -> Loaded:
    """Load relocatable object ``data``; ``externs`` are the only undefined symbols it may use
    (C library functions, found in this process as a dynamic linker would find them), and
    ``entries`` the global functions it must define.

    Raises
    ------
    Unsupported
        If the object or this process is not for this loader (nothing stays mapped then).
    """
    if not supported():
        raise Unsupported("not 64-bit x86 Linux")
    try:
        return _load(memoryview(data), frozenset(externs), tuple(entries))
    except Unsupported:
        raise
    except (struct.error, IndexError, KeyError, ValueError, UnicodeDecodeError, OverflowError, MemoryError,
            ctypes.ArgumentError) as err:  # fmt: skip
        raise Unsupported(f"malformed object: {type(err).__name__}: {err}") from err


def _region_of(flags: int) -> str:
    return "code" if flags & _SHF_EXECINSTR else "data" if flags & _SHF_WRITE else "rodata"


def _load(data: memoryview, externs: frozenset[str], entries: tuple[str, ...]) -> Loaded:
    if len(data) < 64 or bytes(data[:4]) != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise Unsupported("not a 64-bit little-endian ELF object")
    (_, e_type, e_machine, _, _, _, e_shoff, _, _, _, _, e_shentsize, e_shnum, _) = struct.unpack_from(
        "<16sHHIQQQIHHHHHH", data, 0
    )
    if e_type != _ET_REL or e_machine != _EM_X86_64 or e_shentsize != 64:
        raise Unsupported("not a relocatable x86-64 object")
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, e_shoff + 64 * i) for i in range(e_shnum)]
    # (name, type, flags, addr, offset, size, link, info, addralign, entsize)

    # Which sections are loaded, where: every allocated one but the unwind tables, in three
    # regions (code, read-only data, writable data) that each start on a page.
    loaded: dict[int, tuple[str, int]] = {}  # section index: (region, offset in it)
    ends = dict.fromkeys(_PROTECTION, 0)
    for i, (_, kind, flags, _, offset, size, _, _, align, _) in enumerate(sections):
        known = kind in (0, _SHT_PROGBITS, _SHT_SYMTAB, _SHT_STRTAB, _SHT_RELA, _SHT_NOTE, _SHT_NOBITS,
                         _SHT_GROUP, _SHT_X86_64_UNWIND)  # fmt: skip
        if not known and not (_SHT_LLVM_LO <= kind <= _SHT_LLVM_HI and not flags & _SHF_ALLOC):
            raise Unsupported(f"section {i} of type {kind:#x}")
        if kind != _SHT_NOBITS and offset + size > len(data):
            raise Unsupported(f"section {i} reaches beyond the file")
        if not flags & _SHF_ALLOC or kind == _SHT_X86_64_UNWIND:
            continue
        if kind not in (_SHT_PROGBITS, _SHT_NOBITS, _SHT_NOTE):
            raise Unsupported(f"allocated section {i} of type {kind:#x}")
        if flags & _SHF_EXECINSTR and flags & _SHF_WRITE:
            raise Unsupported("writable code")
        if flags & _SHF_TLS:
            raise Unsupported("thread-local storage")
        if align > _PAGE:  # the regions start on a page
            raise Unsupported(f"section {i} aligned to {align} bytes")
        region = _region_of(flags)
        at = _round_up(ends[region], max(int(align), 1))
        loaded[i] = (region, at)
        ends[region] = at + size

    libc = _libc()
    sizes = {region: _round_up(end, _PAGE) for region, end in ends.items() if end}
    bases: dict[str, int] = {}
    try:
        for region, size in sizes.items():
            bases[region] = _pages(size)
        out = _place(data, sections, loaded, sizes, bases, externs)
        for name in entries:
            out.address(name)
        return out
    except BaseException:
        for region, address in bases.items():
            libc.munmap(address, sizes[region])
        raise


def _place(data, sections, loaded, sizes, bases, externs) -> Loaded:
    """Copy the sections ``loaded`` into the pages at ``bases``, relocate them, protect them."""
    libc = _libc()
    images = {region: bytearray(size) for region, size in sizes.items()}  # NOBITS sections stay zero
    for i, (region, at) in loaded.items():
        _, kind, _, _, offset, size, _, _, _, _ = sections[i]
        if kind != _SHT_NOBITS:
            images[region][at : at + size] = data[offset : offset + size]

    # The symbols: each one's address, or None where it lies in a section not loaded.
    symtabs = [s for s in sections if s[1] == _SHT_SYMTAB]
    if len(symtabs) != 1:
        raise Unsupported("not one symbol table")
    _, _, _, _, sym_off, sym_size, strtab, _, _, sym_ent = symtabs[0]
    if sym_ent != 24 or sections[strtab][1] != _SHT_STRTAB:
        raise Unsupported("unexpected symbol table")
    str_off, str_size = sections[strtab][4], sections[strtab][5]

    def name_at(offset: int) -> str:
        if offset >= str_size:
            raise Unsupported("a symbol name beyond the string table")
        start = str_off + offset
        end = bytes(data[start : str_off + str_size]).index(b"\0")
        return bytes(data[start : start + end]).decode()

    process = ctypes.CDLL(None)
    addresses: list[int | None] = []
    functions: dict[str, int] = {}
    for k in range(sym_size // 24):
        st_name, st_info, _, st_shndx, st_value, _ = struct.unpack_from("<IBBHQQ", data, sym_off + 24 * k)
        binding, kind = st_info >> 4, st_info & 0xF
        if kind == _STT_GNU_IFUNC:
            raise Unsupported("an indirect function (its resolver is not the function)")
        if st_shndx == _SHN_UNDEF:
            name = name_at(st_name) if st_name else ""
            if not name:
                addresses.append(0)
                continue
            if name not in externs:
                raise Unsupported(f"undefined symbol {name}")
            try:
                addresses.append(ctypes.cast(getattr(process, name), ctypes.c_void_p).value)
            except AttributeError:
                raise Unsupported(f"{name} is not in this process") from None
        elif st_shndx == _SHN_ABS:
            addresses.append(st_value)
        elif st_shndx >= _SHN_LORESERVE:
            raise Unsupported(f"symbol in special section {st_shndx:#x}")
        elif st_shndx in loaded:
            if st_value > sections[st_shndx][5]:
                raise Unsupported("a symbol beyond its section")
            region, at = loaded[st_shndx]
            addresses.append(bases[region] + at + st_value)
            if binding == 1 and kind == 2 and region == "code":  # a global function, in code
                functions[name_at(st_name)] = addresses[-1]
        else:
            addresses.append(None)

    for _, kind, _, _, rel_off, rel_size, link, target, _, ent in sections:
        if kind != _SHT_RELA or target not in loaded:
            continue  # the unwind tables' relocations
        if ent != 24 or sections[link] is not symtabs[0]:
            raise Unsupported("unexpected relocation section")
        region, at = loaded[target]
        image, base, limit = images[region], bases[region], sections[target][5]
        for k in range(rel_size // 24):
            r_offset, r_info, r_addend = struct.unpack_from("<QQq", data, rel_off + 24 * k)
            symbol, kind = r_info >> 32, r_info & 0xFFFFFFFF
            if kind not in _WIDTH:
                raise Unsupported(f"relocation type {kind}")
            if r_offset + _WIDTH[kind] > limit:
                raise Unsupported("a relocation beyond its section")
            s = addresses[symbol]
            if s is None:
                raise Unsupported("a relocation against a section not loaded")
            place = at + r_offset
            if kind == _R_X86_64_64:
                struct.pack_into("<Q", image, place, (s + r_addend) & 0xFFFFFFFFFFFFFFFF)
            elif kind == _R_X86_64_PC64:
                struct.pack_into("<Q", image, place, (s + r_addend - (base + place)) & 0xFFFFFFFFFFFFFFFF)
            else:
                value = s + r_addend - (base + place)
                if not -(2**31) <= value < 2**31:
                    raise Unsupported("a 32-bit relative relocation out of range")
                struct.pack_into("<i", image, place, value)

    for region, image in images.items():
        ctypes.memmove(bases[region], bytes(image), len(image))
        if libc.mprotect(bases[region], len(image), _PROTECTION[region]) != 0:
            raise Unsupported(f"memory cannot be protected for {region}: {os.strerror(ctypes.get_errno())}")
    return Loaded(functions)


# The processor, as LLVM reads it.

# cpuid(leaf, subleaf, uint32 out[4]) and xgetbv(0), System V AMD64 calling convention.
_CPUID = bytes.fromhex(
    "53"  # push rbx (cpuid writes it; callee-saved)
    "89f8" "89f1" "4989d0"  # mov eax, edi; mov ecx, esi; mov r8, rdx
    "0fa2"  # cpuid
    "418900" "41895804" "41894808" "4189500c"  # mov [r8], eax; [r8+4], ebx; [r8+8], ecx; [r8+12], edx
    "5b" "c3"  # pop rbx; ret
)
_XGETBV = bytes.fromhex("31c9" "0f01d0" "48c1e220" "4809d0" "c3")  # ecx = 0; xgetbv; rax |= rdx << 32; ret

#: The ``cpuid`` leaves (leaf, subleaf) LLVM reads to name this CPU and its features (llvm's
#: Host.cpp: vendor, family and model, the feature leaves, the extended ones and the brand).
_LEAVES = (
    (0, 0), (1, 0), (7, 0), (7, 1), (0xD, 0), (0xD, 1), (0x14, 0), (0x19, 0), (0x24, 0),
    (0x80000000, 0), (0x80000001, 0), (0x80000002, 0), (0x80000003, 0), (0x80000004, 0), (0x80000008, 0),
)  # fmt: skip

_PROCESSOR: list | None = None


def _machine_code(code: bytes, restype, *argtypes):
    """``code`` as a function in fresh read-and-execute pages (never unmapped)."""
    libc = _libc()
    size = _round_up(len(code), _PAGE)
    address = _pages(size)
    ctypes.memmove(address, code, len(code))
    if libc.mprotect(address, size, _PROT_READ | _PROT_EXEC) != 0:
        libc.munmap(address, size)
        raise Unsupported(f"memory cannot be made executable: {os.strerror(ctypes.get_errno())}")
    return ctypes.CFUNCTYPE(restype, *argtypes)(address)


def processor() -> list:
    """What LLVM reads to name this CPU and its features: the ``cpuid`` leaves it reads (up to
    the CPU's highest, basic and extended) as ``[leaf, subleaf, eax, ebx, ecx, edx]``, leaf 1's
    ebx cleared (which core ran it), and the OS's enabled register state (``xgetbv``, where
    the OS enables it).

    Raises
    ------
    Unsupported
        Where this process cannot run it (`supported`).
    """
    global _PROCESSOR
    if _PROCESSOR is None:
        if not supported():
            raise Unsupported("not 64-bit x86 Linux")
        cpuid = _machine_code(_CPUID, None, ctypes.c_uint32, ctypes.c_uint32, ctypes.POINTER(ctypes.c_uint32))
        regs = (ctypes.c_uint32 * 4)()

        def leaf(n: int, sub: int) -> list[int]:
            cpuid(n, sub, regs)
            return list(regs)

        highest = {0: leaf(0, 0)[0], 0x80000000: leaf(0x80000000, 0)[0]}
        leaves = []
        for n, sub in _LEAVES:
            if n <= highest[n & 0x80000000]:
                eax, ebx, ecx, edx = leaf(n, sub)
                leaves.append([n, sub, eax, 0 if n == 1 else ebx, ecx, edx])
        osxsave = leaves[1][4] >> 27 & 1  # leaf 1, ecx bit 27: the OS enabled xgetbv
        xcr0 = _machine_code(_XGETBV, ctypes.c_uint64)() if osxsave else None
        _PROCESSOR = [leaves, xcr0]
    return _PROCESSOR
