"""The sampling plan: where every output pixel comes from, the one seam between a map and the pixels.

A `SamplingPlan` says, for a window of output pixels, the source point of each
pixel centre, the Jacobian of the inverse map there (the pixel's footprint in
the input), the pixels the target polygon's edge crosses (edge coverage) and
what a pixel without a pre-image gets (the background, or with
``outside="input"`` the input itself). It is made from any map that can pull
pixel centres back (`SamplingPlan.from_map`: a `BijectiveMap`, or anything
with its ``pull_back``/``inverse_boundary``/``dst``), or from the points of a
loaded STMap (`SamplingPlan.from_points`), and it is all a run needs of the
map: whole images (`render`), strips of images larger than memory (`crop`,
then `render` of a part), batches and sequences (one plan per output size,
shared by threads), and Dask workers (a plan is plain arrays, shipped once).
How it was made does not matter past this point, as scikit-image's
``warp(image, inverse_map)`` does not care how its map was made.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError
from .maps.compose import PullBack
from .polygon import Polygon
from .raster.pixels import fill, unit
from .raster.resample import EdgeCoverage, edge_coverage, resample, working_copy

if TYPE_CHECKING:
    from .options import WarpOptions

__all__ = ["PlanSource", "SamplingPlan", "as_image", "background_values", "check_paste", "plan_for", "warn_if_outside"]

log = logging.getLogger("warpcli")

OUTSIDE = ("background", "input")
VACATED = ("keep", "background")


class PlanSource(Protocol):
    """What `SamplingPlan.from_map` needs of a map (`warpcli.maps.compose.BijectiveMap` has it)."""

    dst: Polygon

    def pull_back(self, width: int, height: int, *, jacobian: bool = True, rows: tuple[int, int] | None = None) -> PullBack:
        ...  # pragma: no cover

    def inverse_boundary(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        ...  # pragma: no cover


@dataclass(frozen=True, eq=False)
class SamplingPlan:
    """For a window of output pixels: source points, footprints, edge coverage and background.

    Attributes
    ----------
    pull : PullBack
        The source point of every pixel centre of the window (NaN: no
        pre-image), the Jacobian of the inverse map there (or None), the
        window's place (``origin``, row and column) and the whole output's
        ``size`` (width, height).
    coverage : EdgeCoverage or None
        Pixels of the window crossed by the target polygon's edge, their
        share inside it and the source point to sample for them (None: the
        edge is not antialiased).
    interp : {"nearest", "linear", "cubic"}
        The resampling filter.
    footprints : bool
        Resample with the Jacobians: each pixel averaged over its footprint
        where the map shrinks (linear), coverage along the pre-image of the
        input's border (linear and cubic).
    background : tuple of float
        One value, or one per channel, for pixels without a pre-image;
        0..1 spans an integer type's range (`background_values`).
    outside : {"background", "input"}
        What the output holds outside the target: the background, or the
        input with the warp pasted over it (`warpcli.composite`).
    vacated : {"keep", "background"}
        With ``outside="input"``: what the part of the source polygon that the
        target no longer covers holds.
    src : (n, 2) ndarray of float or None
        The source polygon, for ``vacated="background"``.
    feather : float
        With ``outside="input"``: the width in pixels of the band inside the
        target's edge where the warp is blended into the input
        (`warpcli.composite.feather_weights`); 0: none.
    dst : (n, 2) ndarray of float or None
        The target polygon, for ``feather``.
    """

    pull: PullBack
    coverage: EdgeCoverage | None = None
    interp: str = "linear"
    footprints: bool = False
    background: tuple[float, ...] = (0.0,)
    outside: str = "background"
    vacated: str = "keep"
    src: NDArray[np.float64] | None = None
    feather: float = 0.0
    dst: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if self.outside not in OUTSIDE:
            raise InputError(f"outside must be one of {', '.join(OUTSIDE)}, got {self.outside!r}")
        if self.vacated not in VACATED:
            raise InputError(f"vacated must be one of {', '.join(VACATED)}, got {self.vacated!r}")
        if self.outside == "input" and self.vacated == "background" and self.src is None:
            raise InputError("vacated='background' needs the source polygon")
        if self.feather > 0 and (self.outside != "input" or self.dst is None):
            raise InputError("feather blends the warp into the input: it needs outside='input' and the target polygon")

    @classmethod
    def from_map(
        cls,
        fmap: PlanSource,
        width: int,
        height: int,
        *,
        interp: str = "linear",
        antialias: bool = True,
        background: float | ArrayLike = 0.0,
        outside: str = "background",
        vacated: str = "keep",
        jacobian: bool = False,
        rows: tuple[int, int] | None = None,
        feather: float = 0.0,
        edge: bool = True,
    ) -> SamplingPlan:
        """The plan of a map for a ``width`` x ``height`` output.

        Parameters
        ----------
        fmap : BijectiveMap or PlanSource
            The warp: its ``pull_back`` gives the source points (and
            Jacobians), its ``dst`` and ``inverse_boundary`` the edge coverage.
        width, height : int
            The output's size in pixels.
        interp : {"nearest", "linear", "cubic"}
        antialias : bool
            Antialias the target's edge and, with ``linear``, average each
            pixel over its footprint (not with ``nearest``).
        background : float or (C,) array_like of float
            See `SamplingPlan.background`.
        outside, vacated : str
            See `SamplingPlan`.
        jacobian : bool
            Keep the Jacobians even where resampling does not use them (for
            a report or a heatmap of the same run).
        rows : (int, int) or None
            Only output rows ``start <= r < stop`` (a strip): the values are
            those of the whole plan's rows, bit for bit.
        feather : float
            See `SamplingPlan.feather`.
        edge : bool
            Antialias the target's edge (with ``antialias``). False where the
            map is the identity on that edge (a retouch within a fixed
            outline): the warp meets the input there without a step, and a
            pixel whose centre lies outside keeps the input's value exactly.

        Returns
        -------
        SamplingPlan
        """
        footprints = bool(antialias) and interp != "nearest"
        pull = fmap.pull_back(width, height, jacobian=jacobian or footprints, rows=rows)
        coverage = None
        if footprints and edge:
            coverage = _coverage(fmap, np.isfinite(pull.points[..., 0]), pull.origin)
        src = getattr(fmap, "src", None)
        return cls(
            pull, coverage, interp, footprints, _as_background(background), outside, vacated,
            None if src is None else src.points, float(feather), fmap.dst.points if feather > 0 else None,
        )  # fmt: skip

    @classmethod
    def from_points(
        cls, points: ArrayLike, *, interp: str = "linear", background: float | ArrayLike = 0.0
    ) -> SamplingPlan:
        """The plan of a map given as the source point of every output pixel (a loaded STMap).

        Parameters
        ----------
        points : (H, W, 2) array_like of float
            Source point of each output pixel centre; NaN: none.
        interp : {"nearest", "linear", "cubic"}
        background : float or (C,) array_like of float

        Returns
        -------
        SamplingPlan
            Without Jacobians or edge coverage (a map file has neither).
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 3 or pts.shape[2] != 2:
            raise InputError(f"points must be an (H, W, 2) array, got shape {pts.shape}")
        pull = PullBack(pts, None, (0, 0), (pts.shape[1], pts.shape[0]))
        return cls(pull, None, interp, False, _as_background(background))

    @property
    def size(self) -> tuple[int, int]:
        """The whole output's ``(width, height)``."""
        return self.pull.size

    def background_values(self, pixels: NDArray) -> NDArray[np.float64]:
        """`background` in the units of an image of ``pixels``' type, one per channel.

        Raises
        ------
        InputError
            If the background has neither one value nor one per channel.
        """
        return background_values(self.background, pixels)

    def crop(self, rows: tuple[int, int], cols: tuple[int, int]) -> SamplingPlan:
        """The plan of part of the window: its rows ``rows`` and columns ``cols`` (window indices).

        The part's pixels get exactly what they get in the whole plan (their
        source points, Jacobians and edge coverage are the whole plan's).
        """
        a, b = rows
        c, d = cols
        pull = self.pull
        jac = None if pull.jacobian is None else pull.jacobian[a:b, c:d]
        part = PullBack(pull.points[a:b, c:d], jac, (pull.origin[0] + a, pull.origin[1] + c), pull.size)
        coverage = self.coverage
        if coverage is not None:
            width = pull.points.shape[1]
            r, q = np.divmod(coverage.pixels, width)
            keep = (r >= a) & (r < b) & (q >= c) & (q < d)
            coverage = EdgeCoverage(
                (r[keep] - a) * (d - c) + (q[keep] - c), coverage.fraction[keep], coverage.edge[keep],
                coverage.t[keep], None if coverage.source_points is None else coverage.source_points[keep],
            )  # fmt: skip
        return dataclasses.replace(self, pull=part, coverage=coverage)

    def is_empty(self) -> bool:
        """Whether no pixel of the window has a pre-image or touches the target's edge."""
        none_inside = not np.isfinite(self.pull.points[..., 0]).any()
        return none_inside and (self.coverage is None or self.coverage.pixels.size == 0)

    def empty_pixel(
        self, dtype: np.dtype, channels: int, *, alpha_channel: int | None = None, associated_alpha: bool = False
    ) -> NDArray:
        """What a pixel without a pre-image holds in an image of this type and channel count
        (the background, rounded and with the alpha convention as the resampler writes it)."""
        bg = self.background_values(np.zeros((1, 1, channels), dtype=dtype))
        return self._no_pre_image(dtype, channels, bg, alpha_channel, associated_alpha)

    def _no_pre_image(
        self, dtype: np.dtype, channels: int, bg: NDArray, alpha_channel: int | None, associated_alpha: bool
    ) -> NDArray:
        """The pixel the resampler writes where there is no pre-image, with background ``bg``."""
        probe = np.zeros((1, 1, channels), dtype=dtype)
        return resample(
            probe, np.full((1, 1, 2), np.nan), interp=self.interp, background=bg, alpha_channel=alpha_channel,
            associated_alpha=associated_alpha, part=(0, 0, 1, 1),
        )[0, 0]  # fmt: skip

    def sample_window(
        self,
        pixels: NDArray,
        *,
        alpha_channel: int | None = None,
        associated_alpha: bool = False,
        background: NDArray | None = None,
        part: tuple[int, int, int, int] | None = None,
        working: NDArray | None = None,
    ) -> NDArray:
        """The window's pixels resampled from ``pixels``: (h, w, C) in their type.

        Parameters
        ----------
        pixels : (H, W, C) ndarray
            The input image, or with ``part`` the part of it the window reaches.
        alpha_channel : int or None
        associated_alpha : bool
        background : (C,) ndarray or None
            The background in the image's units (default: `background_values`).
        part : (x0, y0, W, H) or None
            ``pixels`` is the part of a W x H image at column x0, row y0
            (see `warpcli.raster.resample.resample`).
        working : ndarray or None
            `warpcli.raster.resample.working_copy` of ``pixels``, made once by a
            caller that samples them window part by window part.
        """
        bg = self.background_values(pixels) if background is None else background
        jac = self.pull.jacobian if self.footprints else None
        return resample(
            pixels, self.pull.points, interp=self.interp, background=bg, alpha_channel=alpha_channel,
            associated_alpha=associated_alpha, jacobian=jac, coverage=self.coverage, part=part, working=working,
        )  # fmt: skip

    def whole_points(self) -> NDArray[np.float64]:
        """The source point of every pixel of the whole output (H, W, 2): the map to save as an STMap.

        NaN where a pixel has no pre-image; with ``outside="input"`` the map
        of the retouch over the whole image (`warpcli.composite.whole_image_map`:
        identity outside the target, NaN where ``vacated="background"``
        shows the background).
        """
        points = self.pull.full_points()
        if self.outside != "input":
            return points
        from .composite import whole_image_map

        return whole_image_map(points, src=self.src, vacated=self.vacated)

    def render(self, pixels: NDArray, *, alpha_channel: int | None = None, associated_alpha: bool = False) -> NDArray:
        """The whole output from the input image ``pixels``: (H, W, C) of their type.

        The window is resampled; the rest is the background, or with
        ``outside="input"`` the input with the window pasted over it
        (`warpcli.composite.paste_over`).

        Parameters
        ----------
        pixels : (H, W, C) or (H, W) array_like
            The input image (an (H, W) one is rendered as (H, W, 1), as
            `warpcli.pipeline.warp_image` does).
        alpha_channel : int or None
            Its alpha channel: colour is resampled premultiplied.
        associated_alpha : bool
            Whether its colour is premultiplied already.

        Returns
        -------
        (H, W, C) ndarray

        Raises
        ------
        InputError
            If the background does not fit the image's channels, or with
            ``outside="input"`` the output's size is not the input's.
        """
        pixels = as_image(pixels)
        bg = self.background_values(pixels)
        if self.outside == "input":
            from .composite import paste_over

            check_paste(self.outside, self.size, (pixels.shape[1], pixels.shape[0]), "the input")

            def warp(px: NDArray, alpha: int) -> NDArray:
                return self._whole(px, np.zeros(px.shape[2]), alpha, True)

            return paste_over(
                pixels, warp, src=self.src, background=bg, alpha_channel=alpha_channel,
                associated_alpha=associated_alpha, vacated=self.vacated, feather=self.feather, dst=self.dst,
            )  # fmt: skip
        return self._whole(pixels, bg, alpha_channel, associated_alpha)

    def render_rows(
        self, pixels: NDArray, out: NDArray, *, alpha_channel: int | None = None, associated_alpha: bool = False,
        band: int = 128,
    ) -> Iterator[tuple[int, int]]:
        """`render` into ``out`` band by band, yielding the rows ``(y0, y1)`` of each band once
        it is done, in order, from row 0 to the last.

        For a writer that encodes the first rows while the next are resampled
        (`warpcli.pipeline.warp_file`). ``out`` ends with the pixels `render`
        returns, bit for bit: each pixel is sampled from its own source point,
        Jacobian and edge coverage, which a band of the plan holds as the whole
        plan does (`crop`). Only with ``outside="background"``.

        Parameters
        ----------
        pixels : (H, W, C) ndarray
            The input image.
        out : (height, width, C) ndarray
            Filled with the output, of ``pixels``' type.
        alpha_channel, associated_alpha
            As for `render`.
        band : int
            Rows of the window resampled at once.
        """
        if self.outside != "background":
            raise ValueError("render_rows pastes nothing: outside must be 'background'")
        pixels = as_image(pixels)
        bg = self.background_values(pixels)
        # Straight colour premultiplied (or an unusual type converted) once, not for every band.
        working = working_copy(pixels, interp=self.interp, alpha_channel=alpha_channel, associated_alpha=associated_alpha)
        width, height = self.size
        r, c = self.pull.origin
        wh, ww = self.pull.points.shape[:2]
        if (wh, ww) != (height, width):
            fill(out, self._no_pre_image(pixels.dtype, pixels.shape[2], bg, alpha_channel, associated_alpha))
            if r > 0:
                yield 0, r
        for a in range(0, wh, band):
            b = min(wh, a + band)
            part = self.crop((a, b), (0, ww))
            out[r + a : r + b, c : c + ww] = part.sample_window(
                pixels, alpha_channel=alpha_channel, associated_alpha=associated_alpha, background=bg, working=working
            )
            yield r + a, r + b
        if r + wh < height:
            yield r + wh, height

    def _whole(self, pixels: NDArray, bg: NDArray, alpha_channel: int | None, associated_alpha: bool) -> NDArray:
        """The window resampled, ``bg`` elsewhere."""
        window = self.sample_window(pixels, alpha_channel=alpha_channel, associated_alpha=associated_alpha, background=bg)
        width, height = self.size
        if window.shape[:2] == (height, width):
            return window
        # Pixels outside the window have no pre-image: the background, exactly as
        # the resampler writes it for such a pixel (rounded, alpha convention).
        out = np.empty((height, width, window.shape[2]), dtype=window.dtype)
        fill(out, self._no_pre_image(pixels.dtype, pixels.shape[2], bg, alpha_channel, associated_alpha))
        r, c = self.pull.origin
        out[r : r + window.shape[0], c : c + window.shape[1]] = window
        return out


def _coverage(fmap: PlanSource, inside: NDArray[np.bool_], origin: tuple[int, int]) -> EdgeCoverage:
    """The target's edge coverage of a window, with the source point of each edge pixel."""
    cov = edge_coverage(fmap.dst.points, inside, origin)
    return dataclasses.replace(cov, source_points=fmap.inverse_boundary(cov.edge, cov.t))


def _as_background(background: float | ArrayLike) -> tuple[float, ...]:
    bg = np.asarray(background, dtype=np.float64).ravel()
    if bg.size == 0:
        raise InputError("background needs at least one value")
    return tuple(float(v) for v in bg)


def as_image(pixels: ArrayLike) -> NDArray:
    """An image as (H, W, C): an (H, W) one gets one channel; anything else of two sides or
    channels, or not numbers, is an `InputError` (what `warpcli.pipeline.warp_image` and
    `SamplingPlan.render` take alike)."""
    px = np.asarray(pixels)
    if px.ndim == 2:
        px = px[:, :, None]
    if px.ndim != 3 or 0 in px.shape:
        raise InputError(f"image must be a non-empty (H, W) or (H, W, C) array, got shape {px.shape}")
    if px.dtype.kind not in "uif":
        raise InputError(f"image must hold numbers, got dtype {px.dtype}")
    return px


def background_values(background: float | ArrayLike, pixels: NDArray) -> NDArray[np.float64]:
    """Background values (0..1 spans an integer type) in the units of an image of ``pixels``' type.

    Parameters
    ----------
    background : float or (C,) array_like of float
        One value for every channel, or one per channel.
    pixels : (H, W, C) ndarray
        An image (only its type and channel count are used).

    Returns
    -------
    ndarray of float
        The values, clipped to what the type holds.

    Raises
    ------
    InputError
        If the count fits neither one value nor one per channel.
    """
    nc = pixels.shape[2]
    bg = np.asarray(background, dtype=np.float64).ravel()
    if bg.size not in (1, nc):
        raise InputError(f"background has {bg.size} values but the image has {nc} channels")
    # Values beyond what the output type holds are clipped there anyway; clip
    # them first, so that they blend as the value written and cannot overflow.
    if np.issubdtype(pixels.dtype, np.integer):
        bg = np.clip(bg, 0.0, 1.0)
    else:
        top = float(np.finfo(np.float32 if pixels.dtype != np.float64 else np.float64).max)
        bg = np.clip(bg, -top, top)
    return bg * unit(pixels.dtype)


def check_paste(outside: str, size: tuple[int, int], input_size: tuple[int, int], name: str) -> None:
    """``outside="input"`` pastes the warp over its input: the sizes must agree.

    Raises
    ------
    InputError
        Naming ``name`` (the input) and both sizes.
    """
    if outside == "input" and tuple(size) != tuple(input_size):
        raise InputError(
            f"--outside input pastes the warp over {name}, so the output must have its size "
            f"{input_size[0]}x{input_size[1]}, not {size[0]}x{size[1]}"
        )


def warn_if_outside(poly: Polygon, size: tuple[int, int], image_name: str, consequence: str) -> None:
    """Warn when a polygon misses an image of ``size`` (width, height) entirely, or is
    in normalised 0..1 coordinates on an image of `NORMALISED_MIN_SIDE` pixels or more
    (a speck in its top-left pixel: nearly all the output would be background)."""
    xmin, ymin, xmax, ymax = poly.bounds
    width, height = size
    if xmax <= 0 or ymax <= 0 or xmin >= width or ymin >= height:
        log.warning(
            "%s lies entirely outside %s (%dx%d): the output will be %s", poly.name, image_name, width, height,
            consequence,
        )  # fmt: skip
    elif xmin >= 0 and ymin >= 0 and xmax <= 1 and ymax <= 1 and min(width, height) >= NORMALISED_MIN_SIDE:
        log.warning(
            "%s lies within 0..1 but %s is %dx%d pixels: polygon coordinates are pixels (x right, y down), "
            "not normalised; multiply them by the image's width and height", poly.name, image_name, width, height,
        )  # fmt: skip


#: The least side of an image on which a polygon within 0..1 is taken for normalised coordinates.
NORMALISED_MIN_SIDE = 32


def plan_for(
    fmap: PlanSource, width: int, height: int, opts: WarpOptions, *, jacobian: bool = False,
    rows: tuple[int, int] | None = None,
) -> SamplingPlan:
    """`SamplingPlan.from_map` with a `WarpOptions`' resampling and output choices."""
    return SamplingPlan.from_map(
        fmap, width, height, interp=opts.interp, antialias=opts.antialias, background=opts.background,
        outside=opts.outside, vacated=opts.vacated, jacobian=jacobian, rows=rows, feather=opts.feather,
        edge=opts.within is None,
    )  # fmt: skip
