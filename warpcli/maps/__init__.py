"""Maps: harmonic maps of a polygon onto a convex Theta, and their composition.

- `base`: the interface every method implements (`ThetaMap`);
- `theta`: the intermediate polygon Theta and the strategies that choose it;
- `optimize`: the optimized Theta (§5.1);
- `registry`: the modules that implement each method and Theta strategy, by name;
- `compose`: `BijectiveMap` (f = phi1^-1 o phi0) and the policy that builds one (Theta, both maps);
- `fem`: the finite element method (mesh, solve, point location, kernels).
"""
