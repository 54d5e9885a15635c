"""The linear answer of a pack load for a stiffness matrix K (node-major dofs), solved
in the tests: the load's held components at zero, its nodal forces on the rest."""

import numpy as np
import scipy.sparse.linalg as spla


def held_solve(K, load, shape) -> np.ndarray:
    """u (n, dim) with K u = f on the free dofs of ``load`` (a PackLoad) and 0 on its held ones."""
    held = np.zeros(shape, bool)
    held[load.held_nodes] = load.held_components
    free = np.flatnonzero(~held.ravel())
    u = np.zeros(held.size)
    u[free] = spla.spsolve(K[free][:, free].tocsc(), np.asarray(load.force, float).ravel()[free])
    return u.reshape(shape)
