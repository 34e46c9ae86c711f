"""Load the code of a relocatable x86-64 ELF object into this process, without LLVM.

`warpcli._native` keeps each compiled kernel as the object file LLVM emits for
its JIT (MCJIT's target machine: static relocations, the large code model).
Loading it through llvmlite costs every process about 0.04 s of CPU (the
178 MB library, its bindings, the engine) before the first kernel runs. Such
an object is simple enough to load here: its sections are copied into fresh
pages, its relocations applied (on x86-64 Linux the large code model makes
them absolute 64-bit addresses, ``R_X86_64_64``, of its own sections and of
C library functions), and its code pages made executable. That is the work
MCJIT's runtime linker does for these objects, on the same bytes, so the
kernels run the very machine code MCJIT would run.

Anything outside that (another machine or format, a relocation or section of
another kind, a symbol the C library does not define, memory that cannot be
made executable) raises `Unsupported`, and the caller loads the object with
MCJIT instead. Unwind tables (``.eh_frame``) are not loaded: no exception
unwinds through a kernel, and their relocations are the only ones left out.
"""

from __future__ import annotations

import ctypes
import os
import struct
import sys
from collections.abc import Iterable

__all__ = ["Loaded", "Unsupported", "load", "supported"]


class Unsupported(Exception):
    """This object, or this process, is not for this loader: load it with MCJIT."""


# ELF constants (System V ABI, AMD64 supplement).
_ET_REL, _EM_X86_64 = 1, 62
_SHT_PROGBITS, _SHT_SYMTAB, _SHT_STRTAB, _SHT_RELA, _SHT_NOBITS, _SHT_REL = 1, 2, 3, 4, 8, 9
_SHT_NOTE, _SHT_X86_64_UNWIND = 7, 0x70000001
_SHF_WRITE, _SHF_ALLOC, _SHF_EXECINSTR, _SHF_TLS = 0x1, 0x2, 0x4, 0x400
_SHN_UNDEF, _SHN_LORESERVE, _SHN_ABS = 0, 0xFF00, 0xFFF1
_STT_SECTION = 3
_R_X86_64_64, _R_X86_64_PC32, _R_X86_64_PC64 = 1, 2, 24

_PROT_READ, _PROT_WRITE, _PROT_EXEC = 1, 2, 4
_MAP_PRIVATE, _MAP_ANONYMOUS = 0x02, 0x20
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def supported() -> bool:
    """Whether this process can load objects here (64-bit x86 Linux)."""
    return sys.platform.startswith("linux") and os.uname().machine in ("x86_64", "amd64") and sys.maxsize > 2**32


_LIBC = None


def _libc():
    global _LIBC
    if _LIBC is None:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.mmap.restype = ctypes.c_void_p
        libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_long]
        libc.mprotect.restype = ctypes.c_int
        libc.mprotect.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
        libc.munmap.restype = ctypes.c_int
        libc.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
        _LIBC = libc
    return _LIBC


class Loaded:
    """An object's code in this process's memory: its global functions by name, and where it lies.

    The memory stays mapped for as long as the process lives (kernels are
    loaded once per process and never unloaded).
    """

    def __init__(self, functions: dict[str, int], regions: list[tuple[int, int]]) -> None:
        self.functions = functions
        self.regions = regions

    def address(self, name: str) -> int:
        try:
            return self.functions[name]
        except KeyError:
            raise Unsupported(f"no function {name} in the object") from None


def _round_up(n: int, to: int) -> int:
    return (n + to - 1) // to * to


def load(data: bytes, externs: Iterable[str] = ()) -> Loaded:
    """Load relocatable object ``data``; ``externs`` are the only undefined symbols it may use
    (C library functions, found in this process as a dynamic linker would find them).

    Raises
    ------
    Unsupported
        If the object or this process is not for this loader.
    """
    if not supported():
        raise Unsupported("not 64-bit x86 Linux")
    try:
        return _load(memoryview(data), frozenset(externs))
    except (struct.error, IndexError, ValueError, UnicodeDecodeError) as err:
        raise Unsupported(f"malformed object: {err}") from err


def _load(data: memoryview, externs: frozenset[str]) -> Loaded:
    if bytes(data[:4]) != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise Unsupported("not a 64-bit little-endian ELF object")
    (_, e_type, e_machine, _, _, _, e_shoff, _, _, _, _, e_shentsize, e_shnum, _) = struct.unpack_from(
        "<16sHHIQQQIHHHHHH", data, 0
    )
    if e_type != _ET_REL or e_machine != _EM_X86_64 or e_shentsize != 64:
        raise Unsupported("not a relocatable x86-64 object")
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, e_shoff + 64 * i) for i in range(e_shnum)]
    # (name, type, flags, addr, offset, size, link, info, addralign, entsize)

    # Which sections are loaded: every allocated one but the unwind tables, code apart from data.
    loaded: dict[int, tuple[bool, int]] = {}  # section index: (executable, offset in its region)
    ends = {True: 0, False: 0}
    for i, (_, kind, flags, _, _, size, _, _, align, _) in enumerate(sections):
        if kind in (_SHT_REL,) or (kind == _SHT_RELA and flags & _SHF_ALLOC):
            raise Unsupported(f"section {i} of type {kind}")
        if not flags & _SHF_ALLOC or kind == _SHT_X86_64_UNWIND:
            continue
        if kind not in (_SHT_PROGBITS, _SHT_NOBITS, _SHT_NOTE):
            raise Unsupported(f"allocated section {i} of type {kind:#x}")
        code = bool(flags & _SHF_EXECINSTR)
        if code and flags & _SHF_WRITE:
            raise Unsupported("writable code")
        if flags & _SHF_TLS:
            raise Unsupported("thread-local storage")
        if align > _PAGE:  # the regions start on a page
            raise Unsupported(f"section {i} aligned to {align} bytes")
        at = _round_up(ends[code], max(int(align), 1))
        loaded[i] = (code, at)
        ends[code] = at + size

    libc = _libc()
    sizes = {code: _round_up(max(end, 1), _PAGE) for code, end in ends.items()}
    bases: dict[bool, int] = {}
    try:
        for code, size in sizes.items():
            address = libc.mmap(None, size, _PROT_READ | _PROT_WRITE, _MAP_PRIVATE | _MAP_ANONYMOUS, -1, 0)
            if address is None or address == ctypes.c_void_p(-1).value:
                raise Unsupported(f"no memory: {os.strerror(ctypes.get_errno())}")
            bases[code] = address
        return _place(data, sections, loaded, sizes, bases, externs)
    except BaseException:
        for code, address in bases.items():
            libc.munmap(ctypes.c_void_p(address), ctypes.c_size_t(sizes[code]))
        raise


def _place(data, sections, loaded, sizes, bases, externs) -> Loaded:
    """Copy the sections ``loaded`` into the pages at ``bases``, relocate them, protect the code."""
    libc = _libc()
    images = {code: bytearray(size) for code, size in sizes.items()}  # NOBITS sections stay zero
    for i, (code, at) in loaded.items():
        _, kind, _, _, offset, size, _, _, _, _ = sections[i]
        if kind != _SHT_NOBITS:
            images[code][at : at + size] = data[offset : offset + size]

    def section_address(i: int) -> int:
        code, at = loaded[i]
        return bases[code] + at

    # The symbols: each one's address, or None where it lies in a section not loaded.
    symtabs = [s for s in sections if s[1] == _SHT_SYMTAB]
    if len(symtabs) != 1:
        raise Unsupported("not one symbol table")
    _, _, _, _, sym_off, sym_size, strtab, _, _, sym_ent = symtabs[0]
    if sym_ent != 24 or sections[strtab][1] != _SHT_STRTAB:
        raise Unsupported("unexpected symbol table")
    str_off = sections[strtab][4]

    def name_at(offset: int) -> str:
        start = str_off + offset
        end = bytes(data[start : start + 4096]).index(b"\0")
        return bytes(data[start : start + end]).decode()

    process = ctypes.CDLL(None)
    addresses: list[int | None] = []
    functions: dict[str, int] = {}
    for k in range(sym_size // 24):
        st_name, st_info, _, st_shndx, st_value, _ = struct.unpack_from("<IBBHQQ", data, sym_off + 24 * k)
        binding, kind = st_info >> 4, st_info & 0xF
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
            addresses.append(section_address(st_shndx) + st_value)
            if binding == 1 and kind == 2 and loaded[st_shndx][0]:  # a global function, in code
                functions[name_at(st_name)] = addresses[-1]
        else:
            addresses.append(None)

    for _, kind, _, _, rel_off, rel_size, link, target, _, ent in sections:
        if kind != _SHT_RELA or target not in loaded:
            continue  # the unwind tables' relocations
        if ent != 24 or sections[link] is not symtabs[0]:
            raise Unsupported("unexpected relocation section")
        code, at = loaded[target]
        image, base = images[code], bases[code]
        for k in range(rel_size // 24):
            r_offset, r_info, r_addend = struct.unpack_from("<QQq", data, rel_off + 24 * k)
            symbol, kind = r_info >> 32, r_info & 0xFFFFFFFF
            s = addresses[symbol]
            if s is None:
                raise Unsupported("a relocation against a section not loaded")
            place = at + r_offset
            if kind == _R_X86_64_64:
                struct.pack_into("<Q", image, place, (s + r_addend) & 0xFFFFFFFFFFFFFFFF)
            elif kind == _R_X86_64_PC64:
                struct.pack_into("<q", image, place, s + r_addend - (base + place))
            elif kind == _R_X86_64_PC32:
                value = s + r_addend - (base + place)
                if not -(2**31) <= value < 2**31:
                    raise Unsupported("a 32-bit relative relocation out of range")
                struct.pack_into("<i", image, place, value)
            else:
                raise Unsupported(f"relocation type {kind}")

    for code, image in images.items():
        ctypes.memmove(bases[code], bytes(image), len(image))
        if code and libc.mprotect(bases[code], len(image), _PROT_READ | _PROT_EXEC) != 0:
            raise Unsupported(f"code cannot be made executable: {os.strerror(ctypes.get_errno())}")
    return Loaded(functions, [(bases[c], sizes[c]) for c in sorted(sizes)])
