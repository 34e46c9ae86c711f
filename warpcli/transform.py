"""A warpcli map as a scikit-image geometric transform: ``skimage.transform.warp(image, tf.inverse)``.

scikit-image's transforms take and give ``(K, 2)`` arrays of ``(x, y)``
= ``(column, row)`` with pixel centres at whole numbers; warpcli's pixel
centres are at +0.5 (as OpenImageIO's and SVG's). `PolygonTransform` is called
in scikit-image's coordinates and converts at its edges (its polygons may be
given in either), and it answers points outside its polygon with a point far
outside any image, which ``warp`` fills with ``cval`` (its default
``mode="constant"``) rather than NaN.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError
from .maps.compose import BijectiveMap
from .options import MapOptions
from .polygon import Polygon

__all__ = ["FAR", "PolygonTransform"]

#: Where a point without an image goes (``outside="far"``): further from any
#: image than any filter reaches, so `skimage.transform.warp` gives ``cval``.
FAR = -1.0e7

#: What to add to vertices given in each convention to get warpcli's coordinates.
SHIFTS = {"skimage": 0.5, "warpcli": 0.0}
OUTSIDE = ("far", "nan")


class PolygonTransform:
    """The bijective map taking polygon ``src`` onto polygon ``dst``, as scikit-image transforms are called.

    ``tf(points)`` maps source points to the target (forward), and
    ``tf.inverse(points)`` target points back to the source, so that
    ``skimage.transform.warp(image, tf.inverse)`` warps ``image`` as
    ``warp IN --src SRC --dst DST OUT`` does (to interpolation accuracy:
    scikit-image resamples with ``scipy.ndimage``, warpcli with its own
    filters and antialiasing).

    Parameters
    ----------
    src, dst : Polygon or (n, 2) array_like of float
        Corresponding polygons (vertex i onto vertex i), in the coordinates
        ``vertices`` says.
    vertices : {"skimage", "warpcli"}
        How the polygons' vertices are expressed: ``"skimage"``, pixel
        centres at whole numbers (scikit-image's ``(column, row)``, as
        points found by ``skimage.feature``); ``"warpcli"``, pixel centres
        at +0.5 (warpcli's polygon files, OpenImageIO, SVG). The points
        given to and returned by the transform are always scikit-image's.
    outside : {"far", "nan"}
        What a point outside the polygon maps to: `FAR` in both
        coordinates (``warp`` then fills the pixel with ``cval``), or NaN.
    options : MapOptions or None
        How the map is built (method, Theta, ...); ``**changes`` change its
        fields, e.g. ``method="bem"``.

    Attributes
    ----------
    map : BijectiveMap
        The map, in warpcli's coordinates.

    Examples
    --------
    >>> tri = [[10, 10], [90, 15], [20, 80]]
    >>> tf = PolygonTransform(tri, [[12, 8], [95, 20], [15, 85]])
    >>> np.round(tf([[10, 10], [90, 15]]), 6)
    array([[12.,  8.],
           [95., 20.]])
    >>> np.round(tf.inverse(tf([[40.0, 30.0]])), 9)
    array([[40., 30.]])
    """

    def __init__(
        self,
        src: Polygon | ArrayLike,
        dst: Polygon | ArrayLike,
        *,
        vertices: str = "skimage",
        outside: str = "far",
        options: MapOptions | None = None,
        **changes: Any,
    ) -> None:
        if vertices not in SHIFTS:
            raise InputError(f"vertices must be one of {', '.join(SHIFTS)}, got {vertices!r}")
        s = _polygon(src, "src", SHIFTS[vertices])
        d = _polygon(dst, "dst", SHIFTS[vertices])
        self._init(BijectiveMap.between(s, d, options, **changes), outside)

    def _init(self, fmap: BijectiveMap, outside: str) -> None:
        if outside not in OUTSIDE:
            raise InputError(f"outside must be one of {', '.join(OUTSIDE)}, got {outside!r}")
        self.map, self.outside = fmap, outside

    @classmethod
    def from_map(cls, fmap: BijectiveMap, *, outside: str = "far") -> PolygonTransform:
        """A transform of a map already built (a `BijectiveMap`, in warpcli's coordinates).

        Parameters
        ----------
        fmap : BijectiveMap
        outside : {"far", "nan"}
            As for `PolygonTransform`.

        Returns
        -------
        PolygonTransform
        """
        tf = cls.__new__(cls)
        tf._init(fmap, outside)
        return tf

    def _through(self, fn, coords: ArrayLike) -> NDArray[np.float64]:
        pts = np.asarray(coords, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise InputError(f"coordinates must be a (K, 2) array of (x, y), got shape {pts.shape}")
        # scikit-image's pixel centres are whole numbers, warpcli's at +0.5.
        out = fn(pts + 0.5) - 0.5
        if self.outside == "far":
            out[~np.isfinite(out).all(axis=1)] = FAR
        return out

    def __call__(self, coords: ArrayLike) -> NDArray[np.float64]:
        """Source points to the target.

        Parameters
        ----------
        coords : (K, 2) array_like of float
            ``(x, y)`` points of the source image.

        Returns
        -------
        (K, 2) ndarray of float
            Their images; outside the source polygon `FAR` (or NaN).
        """
        return self._through(self.map.forward, coords)

    @property
    def inverse(self) -> _Inverse:
        """The inverse transform (target points to the source): pass it to ``skimage.transform.warp``."""
        return _Inverse(self)

    def residuals(self, src: ArrayLike, dst: ArrayLike) -> NDArray[np.float64]:
        """Distance from the transformed ``src`` points to the ``dst`` points.

        Parameters
        ----------
        src, dst : (K, 2) array_like of float

        Returns
        -------
        (K,) ndarray of float
            NaN for a source point outside the polygon (with ``outside="nan"``)
            or the distance to `FAR`.
        """
        return np.hypot(*(self(src) - np.asarray(dst, dtype=np.float64)).T)

    def __repr__(self) -> str:
        return f"PolygonTransform({self.map.src.name} -> {self.map.dst.name}, {self.map.src.n} vertices)"


def _polygon(poly: Polygon | ArrayLike, name: str, shift: float) -> Polygon:
    if isinstance(poly, Polygon):
        return Polygon(poly.points + shift, name=poly.name) if shift else poly
    return Polygon(np.asarray(poly, dtype=np.float64) + shift, name=name)


class _Inverse:
    """The inverse of a `PolygonTransform`: target points to the source."""

    def __init__(self, forward: PolygonTransform) -> None:
        self._forward = forward

    def __call__(self, coords: ArrayLike) -> NDArray[np.float64]:
        """Target points to the source: (K, 2) -> (K, 2); outside the target `FAR` (or NaN)."""
        return self._forward._through(self._forward.map.inverse, coords)

    @property
    def inverse(self) -> PolygonTransform:
        """The forward transform."""
        return self._forward

    def residuals(self, src: ArrayLike, dst: ArrayLike) -> NDArray[np.float64]:
        """Distance from the inversely transformed ``src`` points to the ``dst`` points."""
        return np.hypot(*(self(src) - np.asarray(dst, dtype=np.float64)).T)
