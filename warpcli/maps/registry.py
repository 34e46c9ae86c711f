"""The registry of map methods and Theta strategies, by name.

Light on purpose: the CLI builds its choices from it without importing numpy.
Each entry names the module (and attribute) that implements it; the module is
imported only when the method is used. To add a method, add its name to
`warpcli.options.METHODS`, an entry here and a module under ``warpcli/maps/``
with a ``build`` function (see `warpcli.maps.base.ThetaMap`).

The registry sits above what it names: ``compose`` reads it to build a map,
and the modules it names never import it (tests/test_layers.py treats the
names as imports).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Entry:
    """A registered implementation: ``module:attribute`` and one line of help."""

    target: str
    help: str

    def load(self) -> Any:
        module, _, attr = self.target.partition(":")
        loaded = importlib.import_module(module)
        return getattr(loaded, attr) if attr else loaded


#: Methods that approximate a harmonic map onto Theta (the paper's §3.1).
#: Each target is a module with ``build(polygon, theta, options, role, region)``,
#: which returns a `warpcli.maps.base.ThetaMap`, and ``prepare()``, which
#: loads what the method needs later (compiled kernels) while maps are solved.
METHODS = {
    "fem": Entry("warpcli.maps.fem", "finite elements on a graded Delaunay mesh (§3.1.1): fast, exact on the boundary"),
    "bem": Entry("warpcli.maps.meshless:BEM", "boundary elements (§3.1.2): smooth, analytic derivatives, slower"),
    "mfs": Entry("warpcli.maps.meshless:MFS", "fundamental solutions (§3.1.3): smooth, analytic derivatives, fast to evaluate"),
}

#: Strategies that choose the convex intermediate polygon Theta (§2, §5.1).
#: Each target is a function ``(src, dst, options) -> Theta``; ``none`` returns the
#: target itself (`warpcli.maps.theta.TargetTheta`), which FEM maps straight onto.
THETAS = {
    "regular": Entry("warpcli.maps.theta:regular", "the regular n-gon"),
    "cyclic": Entry("warpcli.maps.theta:cyclic", "inscribed in a circle, edges as long as the mean of the polygons' edges"),
    "optimized": Entry("warpcli.maps.optimize:optimized", "all vertices moved jointly to lower the distortion (--energy), the best of regular, cyclic and that kept"),
    "none": Entry("warpcli.maps.straight:none", "no Theta: the plain harmonic map straight onto DST (FEM only; piecewise linear, not symmetric; refused where it folds)"),
}
