"""The map seam in any dimension: points and Jacobians through maps onto Theta, certificates, and their composition.

Polygons (`warpcli.maps`, d = 2) and polyhedra (`warpcli.volume`, d = 3)
are warped the same way: two maps phi0, phi1 of the domains onto one
intermediate Theta, composed as f = phi1^-1 o phi0 (the paper's eq. (2)).
What crosses the seam is the same in both dimensions, and defined here once:
points and their Jacobians (`Mapped`), the evidence that a map is one-to-one
(`Certificate`), and the composition's common surface (`ComposedMap`:
``forward``, ``inverse``, their Jacobians, the certificates). How the maps are
built (meshing, Theta, untangling) stays with each dimension. This module
imports numpy and `warpcli.errors` only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import FoldOverError, InputError

#: What a certificate's elements are (see `Certificate.kind`).
CERTIFICATE_KINDS = ("triangles", "tetrahedra", "samples")


class Mapped(NamedTuple):
    """Points carried through a map, with the map's Jacobian there if asked for.

    Attributes
    ----------
    points : (K, d) ndarray of float
        NaN where the map is not defined (outside its domain).
    jacobian : (K, d, d) ndarray of float or None
        ``jacobian[k, a, b]`` = d out_a / d in_b at point k; NaN where unknown.
    """

    points: NDArray[np.float64]
    jacobian: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class Certificate:
    """Evidence that a map is one-to-one.

    Attributes
    ----------
    flipped : int
        Elements where the map's Jacobian vanishes or has the wrong sign.
    checked : int
        How many elements were checked.
    kind : {"triangles", "tetrahedra", "samples"}
        What an element is: the simplices of a piecewise-linear map
        (``"triangles"`` in 2D, ``"tetrahedra"`` in 3D; the certificate is
        then exact), or sample points of a smooth map (``"samples"``).

    Raises
    ------
    ValueError
        If ``kind`` is none of those.
    """

    flipped: int
    checked: int
    kind: str

    def __post_init__(self) -> None:
        if self.kind not in CERTIFICATE_KINDS:
            raise ValueError(f"a certificate counts one of {', '.join(CERTIFICATE_KINDS)}, not {self.kind!r}")

    @property
    def ok(self) -> bool:
        """True when nothing flipped."""
        return self.flipped == 0


class OntoTheta(Protocol):
    """What the composition needs of a map phi onto Theta, in any dimension.

    `warpcli.maps.base.ThetaMap` (polygons; its ``inverse`` also takes a
    ``coherent`` hint) and `warpcli.volume.compose.VolumeThetaMap`
    (polyhedra) are such maps.
    """

    theta: Any

    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        """phi at points of the domain (NaN outside it)."""

    def inverse(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        """phi^-1 at points of Theta (NaN outside it)."""

    def certify(self) -> Certificate:
        """Count the elements where the map flips."""


def as_points(points: ArrayLike, dim: int = 2, *, contiguous: bool = False) -> NDArray[np.float64]:
    """Points as a (K, dim) float array, or `InputError`.

    Parameters
    ----------
    points : (K, dim) array_like of float
    dim : int
        The dimension, 2 or 3.
    contiguous : bool
        Make the array C-contiguous (for compiled kernels).

    Returns
    -------
    (K, dim) ndarray of float
        ``points`` itself when it already is one.

    Raises
    ------
    InputError
        If the shape is not (K, dim).
    """
    p = np.ascontiguousarray(points, dtype=np.float64) if contiguous else np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != dim:
        raise InputError(f"points must be a (K, {dim}) array, got shape {p.shape}")
    return p


def matmul2(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a @ b`` for stacks of 2x2 matrices, written out (the same rounding everywhere)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for i in range(2):
        for j in range(2):
            out[..., i, j] = a[..., i, 0] * b[..., 0, j] + a[..., i, 1] * b[..., 1, j]
    return out


def chain(outer: NDArray[np.float64], inner: NDArray[np.float64]) -> NDArray[np.float64]:
    """The chain rule for stacks of Jacobians: ``outer @ inner``.

    2x2 products are written out (`matmul2`: the rounding of the compiled
    kernels, whatever BLAS does); larger ones are numpy's ``@``.

    Parameters
    ----------
    outer, inner : (..., d, d) ndarray of float

    Returns
    -------
    (..., d, d) ndarray of float
    """
    if outer.shape[-1] == 2:
        return matmul2(outer, inner)
    return outer @ inner


class ComposedMap:
    """f = phi1^-1 o phi0 between two domains mapped onto one Theta, in any dimension (eq. (2)).

    ``forward`` takes source points to the target, ``inverse`` takes target
    points back to the source: f = phi1^-1 o phi0 and f^-1 = phi0^-1 o
    phi1, for any two maps onto one Theta (`OntoTheta`).
    `warpcli.maps.compose.BijectiveMap` (polygons) and
    `warpcli.volume.compose.VolumeMap` (polyhedra) are this with what only
    their dimension knows (pixel grids, voxel slabs, how they are built).

    Parameters
    ----------
    phi0 : OntoTheta
        The source domain onto Theta.
    phi1 : OntoTheta
        The target domain onto the same Theta (compared by value: two equal
        Thetas are one).

    References
    ----------
    Schneider & Hormann, Smooth bijective maps between arbitrary planar
    polygons, CAGD 2015, eq. (2).
    """

    #: The dimension of the domains.
    dim: ClassVar[int] = 2

    def __init__(self, phi0: OntoTheta, phi1: OntoTheta) -> None:
        self.phi0 = phi0
        self.phi1 = phi1
        self.timings: dict[str, float] = {}

    @property
    def theta(self) -> Any:
        """The intermediate domain both maps go onto."""
        return self.phi0.theta

    def certificates(self) -> tuple[Certificate, Certificate]:
        """The two maps' `Certificate`, (source, target)."""
        return self.phi0.certify(), self.phi1.certify()

    def fold_message(self, source: Certificate, target: Certificate) -> str:
        """What `check_bijective` says when either certificate is not ok."""
        return (
            f"the maps flip {source.flipped} {source.kind} of the source and {target.flipped} {target.kind} "
            "of the target; the warp would fold over itself"
        )

    def check_bijective(self) -> None:
        """Raise `FoldOverError` unless both maps are certified one-to-one."""
        c0, c1 = self.certificates()
        if not (c0.ok and c1.ok):
            raise FoldOverError(self.fold_message(c0, c1))

    def forward(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map source points to the target.

        Parameters
        ----------
        points : (K, d) array_like of float
            Points in the source's coordinates.

        Returns
        -------
        (K, d) ndarray of float
            Their images in the target's coordinates; NaN outside the source domain.
        """
        return self.phi1.inverse(self.phi0.evaluate(as_points(points, self.dim)).points).points

    def inverse(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map target points back to the source.

        Parameters
        ----------
        points : (K, d) array_like of float
            Points in the target's (output's) coordinates.

        Returns
        -------
        (K, d) ndarray of float
            Their pre-images in the source's coordinates; NaN outside the target domain.
        """
        return self.phi0.inverse(self.phi1.evaluate(as_points(points, self.dim)).points).points

    def forward_mapped(self, points: ArrayLike) -> Mapped:
        """f and its Jacobian ``J_phi1(f(x))^-1 J_phi0(x)`` at source points.

        Parameters
        ----------
        points : (K, d) array_like of float

        Returns
        -------
        Mapped
            Points (K, d) and Jacobians (K, d, d); NaN outside the source domain.
        """
        a = self.phi0.evaluate(as_points(points, self.dim), jacobian=True)
        b = self.phi1.inverse(a.points, jacobian=True)
        return Mapped(b.points, chain(b.jacobian, a.jacobian))

    def inverse_mapped(self, points: ArrayLike) -> Mapped:
        """f^-1 and its Jacobian ``J_phi0(x)^-1 J_phi1(y)`` at target points.

        Parameters
        ----------
        points : (K, d) array_like of float

        Returns
        -------
        Mapped
            Points (K, d) and Jacobians (K, d, d); NaN outside the target domain.
        """
        a = self.phi1.evaluate(as_points(points, self.dim), jacobian=True)
        b = self.phi0.inverse(a.points, jacobian=True)
        return Mapped(b.points, chain(b.jacobian, a.jacobian))

    def forward_jacobian(self, points: ArrayLike) -> NDArray[np.float64]:
        """Jacobian of f at source points (`forward_mapped` without the points).

        Parameters
        ----------
        points : (K, d) array_like of float

        Returns
        -------
        (K, d, d) ndarray of float
            NaN outside the source domain.
        """
        return self.forward_mapped(points).jacobian

    def inverse_jacobian(self, points: ArrayLike) -> NDArray[np.float64]:
        """Jacobian of f^-1 at target points (`inverse_mapped` without the points).

        Parameters
        ----------
        points : (K, d) array_like of float

        Returns
        -------
        (K, d, d) ndarray of float
            NaN outside the target domain.
        """
        return self.inverse_mapped(points).jacobian
