"""Output encodings by name: the tables behind ``--dtype`` and ``--compression``, free of numpy so ``warp --help`` stays instant."""

from __future__ import annotations

from types import MappingProxyType

__all__ = ["COMPRESSION_LEVELS", "DTYPES", "PNG_COMPRESSION"]

#: Output pixel types for ``--dtype`` and `warpcli.raster.imageio.convert_pixels`:
#: each name and the numpy dtype it stands for (``numpy.dtype(DTYPES[name])``).
DTYPES = MappingProxyType({"uint8": "uint8", "uint16": "uint16", "half": "float16", "float": "float32"})

#: zlib levels of PNG outputs (``--compression``): 0 (stored: fastest, largest) to 9 (smallest, slowest).
COMPRESSION_LEVELS = range(10)
#: The level of a PNG output when none is asked for: 1, as OpenCV writes. Measured
#: for issue 24 (bench/README.md): against OpenImageIO's default, zlib's 6, 3 to 7
#: times faster to write (a 4 MP photograph: 0.2 s against 0.9-1.6 s) for files
#: 12-15 % larger; the pixels are the same at every level.
PNG_COMPRESSION = 1
