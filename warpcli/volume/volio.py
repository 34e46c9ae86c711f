"""Volume I/O: NIfTI through nibabel (keeping the affine, header and data type) and multi-page TIFF through tifffile."""

from __future__ import annotations

import contextlib
import gzip
import io
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..budget import MAX_COMPRESSION, check_declared_size, max_image_bytes
from ..errors import ImageInputError, ImageIOError
from ..files import check_regular_file
from ..outputs import atomic_path, check_output_path, write_checked
from .compose import VoxelGrid

#: Extensions by format.
NIFTI_EXTENSIONS = (".nii", ".nii.gz")
TIFF_EXTENSIONS = (".tif", ".tiff")


@dataclass(frozen=True, eq=False)
class Volume:
    """Voxels with the grid they sit on and what their file says about them.

    Attributes
    ----------
    data : (nz, ny, nx, C) ndarray
        In the file's own data type (for NIfTI, the stored values before
        the header's scaling, which is written back unchanged). Voxel
        (i, j, k) is ``data[k, j, i]``.
    grid : VoxelGrid
        Voxel index to world coordinates: NIfTI's affine (mm); for TIFF, voxel
        (i, j, k) has its centre at (i + 0.5, j + 0.5, k + 0.5).
    format : {"nifti", "tiff"}
    header : object
        The NIfTI image the volume came from (its header is written back), or
        None.
    """

    data: NDArray
    grid: VoxelGrid
    format: str = "tiff"
    header: object = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.data.ndim != 4:
            raise ValueError(f"data must be (nz, ny, nx, C), got shape {self.data.shape}")
        nz, ny, nx, _ = self.data.shape
        if tuple(self.grid.shape) != (nx, ny, nz):
            raise ValueError(f"grid shape {self.grid.shape} does not match data {self.data.shape}")


def volume_format(path: str | os.PathLike[str]) -> str:
    """``"nifti"`` or ``"tiff"`` from a file name, or `ImageInputError`."""
    name = os.fspath(path).lower()
    if name.endswith(NIFTI_EXTENSIONS):
        return "nifti"
    if name.endswith(TIFF_EXTENSIONS):
        return "tiff"
    raise ImageInputError(
        f"{os.fspath(path)}: unknown volume format; use NIfTI (.nii, .nii.gz) or a multi-page TIFF (.tif, .tiff)"
    )


def tiff_grid(shape: tuple[int, int, int]) -> VoxelGrid:
    """The grid of a TIFF stack: voxel (i, j, k) centred at (i + 0.5, j + 0.5, k + 0.5)."""
    a = np.eye(4)
    a[:3, 3] = 0.5
    return VoxelGrid(tuple(int(s) for s in shape), a)  # type: ignore[arg-type]


def read_volume(path: str | os.PathLike[str]) -> Volume:
    """Read a NIfTI volume or a multi-page TIFF stack.

    Raises
    ------
    ImageInputError
        If the file is missing, unreadable, not a 3D volume (NIfTI with
        more than 4 dimensions, a single-page TIFF), or too large for memory.
    """
    name = os.fspath(path)
    kind = volume_format(name)
    check_regular_file(name, "volume", ImageInputError)
    if kind == "nifti":
        return _read_nifti(name)
    with tifffile_log() as said:
        check_pages(name)
        volume = _read_tiff(name)
    if said:
        # tifffile skipped what it could not read (a page past the end of a
        # file cut short): the volume would lack pages without a word.
        raise ImageInputError(f"{name}: cannot read TIFF: the file is damaged: {said[0]}")
    return volume


@contextlib.contextmanager
def tifffile_log() -> Iterator[list[str]]:
    """tifffile's log lines during the block, kept from stderr and collected.

    tifffile logs what it skips in a damaged file ("invalid page offset")
    through the logging module, which would print it before warpcli's own
    message; here each line is one item of the yielded list, for the caller
    to turn into its message.
    """
    import logging

    said: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            said.append(" ".join(record.getMessage().split()))

    logger = logging.getLogger("tifffile")
    handler = Collect(logging.WARNING)
    old = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield said
    finally:
        logger.removeHandler(handler)
        logger.propagate = old


def _check_memory(name: str, nbytes: int) -> None:
    limit = max_image_bytes()
    if nbytes > limit:
        raise ImageInputError(
            f"{name}: the volume needs {nbytes / 2**20:.0f} MiB of memory, more than the {limit / 2**20:.0f} MiB "
            "warpcli may use (WARPCLI_MAX_IMAGE_BYTES)"
        )


def _check_declared(name: str, shape: tuple, dtype: np.dtype, *, header_bytes: int = 0, compressed: bool = True) -> None:
    """Refuse from the header, before reading any voxel: an empty shape, a data type
    the warp cannot carry, data more than memory or more than the file holds."""
    if any(int(s) <= 0 for s in shape):
        raise ImageInputError(f"{name}: the volume has no voxels (shape {tuple(int(s) for s in shape)})")
    if dtype.kind == "c":
        raise ImageInputError(
            f"{name}: complex data ({dtype.name}) cannot be warped; warp the real and imaginary parts as two volumes"
        )
    if dtype.kind not in "biuf" or dtype.fields is not None:
        raise ImageInputError(f"{name}: data of type {dtype} cannot be warped; use integers or floating point")
    nbytes = math.prod(int(s) for s in shape) * dtype.itemsize
    _check_memory(name, nbytes)
    what = f"{' x '.join(str(int(s)) for s in shape)} voxels of {dtype.newbyteorder('=').name}"
    check_declared_size(name, header_bytes + nbytes, what, ratio=MAX_COMPRESSION if compressed else 1)


def _refused(name: str, shape: tuple, dtype: np.dtype) -> ImageInputError | None:
    try:
        _check_declared(name, shape, dtype)
    except ImageInputError as err:
        return err
    return None


def _native(data: NDArray) -> NDArray:
    """``data`` in this machine's byte order (the warp's kernels read no other): the same values and type."""
    return data if data.dtype.isnative else data.astype(data.dtype.newbyteorder("="))


def _read_nifti(name: str) -> Volume:
    try:
        import nibabel as nib
    except ImportError:
        raise ImageInputError(f"{name}: reading NIfTI needs nibabel (pip install 'warpcli[volume]')") from None
    try:
        img = nib.load(name)
        shape = img.shape
        dtype = img.get_data_dtype()
    except Exception as err:  # nibabel raises many kinds (ImageFileError, EOFError, zlib.error)
        raise ImageInputError(f"{name}: cannot read NIfTI: {err}") from None
    if len(shape) not in (3, 4):
        raise ImageInputError(f"{name}: a volume needs 3 dimensions (or 4, the last one channels), got shape {shape}")
    gz = name.lower().endswith(".gz")
    offset = 0 if gz else int(getattr(img.header, "get_data_offset", lambda: 0)())
    _check_declared(name, shape, dtype, header_bytes=offset, compressed=gz)
    try:
        proxy = img.dataobj
        raw = proxy.get_unscaled() if hasattr(proxy, "get_unscaled") else np.asanyarray(proxy)
    except Exception as err:
        raise ImageInputError(f"{name}: cannot read NIfTI data: {err}") from None
    raw = _native(np.asarray(raw))
    if raw.ndim == 3:
        raw = raw[..., None]
    data = np.ascontiguousarray(np.transpose(raw, (2, 1, 0, 3)))  # (i, j, k, c) -> (k, j, i, c)
    affine = np.asarray(img.affine, dtype=np.float64)
    check_affine(name, affine)
    return Volume(data, VoxelGrid(tuple(int(s) for s in shape[:3]), affine), "nifti", img)  # type: ignore[arg-type]


def _read_tiff(name: str) -> Volume:
    import tifffile

    try:
        with tifffile.TiffFile(name) as tif:
            series = tif.series[0]
            axes = series.axes
            shape = series.shape
            dtype = np.dtype(series.dtype)
            # tifffile's own writer, page by page, makes each page a series of its own
            # (a shape in each page's description): its pages, alike (`check_pages`),
            # are the stack. Other files put their pages in one series.
            stacked = len(tif.series) > 1 and len(series.pages) == 1 and axes in ("YX", "YXS")
            if stacked:
                axes, shape = "Z" + axes, (len(tif.pages), *shape)
            # Checked from the header, before any page is decoded.
            refused = _refused(name, shape, dtype)
            if refused:
                data = None
            else:
                data = _native(tif.asarray(key=range(len(tif.pages))) if stacked else series.asarray())
    except (tifffile.TiffFileError, OSError, ValueError) as err:
        raise ImageInputError(f"{name}: cannot read TIFF: {err}") from None
    if refused is not None:
        raise refused
    if data.ndim == 3 and axes[-1] != "S":
        data = data[..., None]
    elif not (data.ndim == 4 and axes[-1] == "S"):
        raise ImageInputError(
            f"{name}: a volume needs several pages of one size (axes like ZYX or ZYXS), got axes {axes} shape {shape}"
        )
    nz, ny, nx, _ = data.shape
    return Volume(np.ascontiguousarray(data), tiff_grid((nx, ny, nz)), "tiff", None)


def check_affine(name: str, affine: NDArray[np.float64]) -> None:
    """Refuse a voxel-to-world affine that is not finite or not invertible (the
    cages would be blamed for what is the volume's header).

    Raises
    ------
    ImageInputError
        Naming the volume file.
    """
    if affine.shape != (4, 4) or not np.isfinite(affine).all():
        raise ImageInputError(f"{name}: the header's voxel-to-world affine is not finite: {np.round(affine, 6).tolist()}")
    det = float(np.linalg.det(affine[:3, :3]))
    if not (np.isfinite(det) and abs(det) > 0):
        raise ImageInputError(f"{name}: the header's voxel-to-world affine is singular (voxels of zero volume)")


def check_pages(name: str) -> None:
    """Refuse a TIFF stack whose pages differ in pixel type, size or samples.

    tifffile reads such a file as several series, and the first would be a
    volume with pages missing (the others dropped, or their bytes read as
    another type): a wrong result without a word. Only the pages' headers are
    read; a file tifffile cannot parse is left to `read_volume` to report.

    Parameters
    ----------
    name : str
        The TIFF file.

    Raises
    ------
    ImageInputError
        Naming the first page that differs from page 1, and how.
    """
    import tifffile

    try:
        with tifffile.TiffFile(name) as tif:
            kinds = [(np.dtype(p.dtype) if p.dtype is not None else None, tuple(p.shape)) for p in tif.pages]
    except (tifffile.TiffFileError, OSError, ValueError, TypeError):
        return
    for k, kind in enumerate(kinds[1:], start=2):
        if kind != kinds[0]:
            raise ImageInputError(
                f"{name}: page {k} holds {_page_kind(kind)}, page 1 {_page_kind(kinds[0])}; "
                "a volume's pages must all have one pixel type and size"
            )


def _page_kind(kind) -> str:
    return f"{kind[0]} pixels of shape {' x '.join(map(str, kind[1]))}"


def check_volume_output(path: str | os.PathLike[str], inputs: tuple = ()) -> None:
    """Check before any work that a volume can be written at ``path`` (format known, not an input)."""
    volume_format(path)
    check_output_path(path, inputs)


def encode_volume(volume: Volume, path: str | os.PathLike[str]) -> bytes:
    """The bytes of ``volume`` in the format ``path``'s extension names (deterministic: no time stamps)."""
    kind = volume_format(path)
    if kind == "nifti":
        return _encode_nifti(volume, os.fspath(path).lower().endswith(".gz"))
    return _encode_tiff(volume)


def write_volume(path: str | os.PathLike[str], volume: Volume) -> None:
    """Write a volume atomically (a temporary file beside ``path``, renamed over it when complete).

    Raises
    ------
    ImageInputError
        If ``path`` cannot be written.
    ImageIOError
        If writing fails.
    """
    name = os.fspath(path)
    data = encode_volume(volume, name)
    check_volume_output(name)
    with atomic_path(name) as tmp:
        write_checked(tmp, data, name)


def _encode_nifti(volume: Volume, compressed: bool) -> bytes:
    import nibabel as nib

    raw = np.transpose(volume.data, (2, 1, 0, 3))
    if raw.shape[3] == 1:
        raw = raw[..., 0]
    like = volume.header
    if like is not None:
        header = like.header.copy()
        header.set_data_dtype(volume.data.dtype)
        img = type(like)(np.asfortranarray(raw), volume.grid.affine, header=header)
        # Keep the input's scaling: the data are its stored values.
        slope, inter = like.header.get_slope_inter()
        if slope is not None:
            img.header.set_slope_inter(slope, inter)
    else:
        img = nib.Nifti1Image(np.asfortranarray(raw), volume.grid.affine)
        img.header.set_data_dtype(volume.data.dtype)
    try:
        body = img.to_bytes()
    except Exception as err:
        raise ImageIOError(f"cannot encode NIfTI: {err}") from err
    if not compressed:
        return body
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=0, compresslevel=6) as gz:
        gz.write(body)
    return buf.getvalue()


def _encode_tiff(volume: Volume) -> bytes:
    import tifffile

    data = volume.data
    buf = io.BytesIO()
    if data.shape[3] in (3, 4):
        tifffile.imwrite(buf, data, photometric="rgb", extrasamples=("unassalpha",) if data.shape[3] == 4 else None)
    else:
        tifffile.imwrite(buf, data[..., 0] if data.shape[3] == 1 else data, photometric="minisblack")
    return buf.getvalue()
