"""Maps: harmonic maps of a polygon onto a convex Theta, and their composition.

- `base`: the interface every method implements (`ThetaMap`);
- `theta`: the intermediate polygon Theta and the strategies that choose it;
- `registry`: methods and Theta strategies by name;
- `compose`: `BijectiveMap` (f = phi1^-1 o phi0) and the policy that builds one;
- `fem`: the finite element method (mesh, solve, point location, kernels).
"""
