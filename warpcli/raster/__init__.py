"""Raster work: resampling kernels, image I/O, pixel types, STMaps. Knows nothing of how maps are made."""
