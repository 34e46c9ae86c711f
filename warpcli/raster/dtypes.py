"""Output pixel types by name: the one table behind ``--dtype``, free of numpy so ``warp --help`` stays instant."""

from __future__ import annotations

from types import MappingProxyType

__all__ = ["DTYPES"]

#: Output pixel types for ``--dtype`` and `warpcli.raster.imageio.convert_pixels`:
#: each name and the numpy dtype it stands for (``numpy.dtype(DTYPES[name])``).
DTYPES = MappingProxyType({"uint8": "uint8", "uint16": "uint16", "half": "float16", "float": "float32"})
