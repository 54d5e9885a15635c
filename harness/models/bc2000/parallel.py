"""Classic spring forces for large networks, parallel over springs then over nodes
(numba prange, no write conflicts): pass 1 computes every spring's force, pass 2 sums
each node's incident springs through a node -> spring CSR index."""

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, error_model="numpy", fastmath=True)
def spring_forces_parallel(x, v, p, q, ks, kd, L0, F, ptr, idx, sign, f):
    """f (n, 3) = sum of damped spring forces F_s = -[ks (L - L0) + kd (dv . n)] n at p,
    -F_s at q. F (s, 3) is scratch; (ptr, idx, sign) from :func:`node_index`."""
    for s in prange(p.shape[0]):
        i = p[s]
        j = q[s]
        lx = x[i, 0] - x[j, 0]
        ly = x[i, 1] - x[j, 1]
        lz = x[i, 2] - x[j, 2]
        L = np.sqrt(lx * lx + ly * ly + lz * lz)
        inv = 1.0 / L
        nx = lx * inv
        ny = ly * inv
        nz = lz * inv
        dv = (v[i, 0] - v[j, 0]) * nx + (v[i, 1] - v[j, 1]) * ny + (v[i, 2] - v[j, 2]) * nz
        c = -(ks[s] * (L - L0[s]) + kd[s] * dv)
        F[s, 0] = c * nx
        F[s, 1] = c * ny
        F[s, 2] = c * nz
    for i in prange(f.shape[0]):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for k in range(ptr[i], ptr[i + 1]):
            s = idx[k]
            g = sign[k]
            a0 += g * F[s, 0]
            a1 += g * F[s, 1]
            a2 += g * F[s, 2]
        f[i, 0] = a0
        f[i, 1] = a1
        f[i, 2] = a2


def node_index(p, q, n):
    """CSR (ptr, spring ids, signs) of the springs incident to each node."""
    nodes = np.concatenate([p, q])
    springs = np.concatenate([np.arange(len(p)), np.arange(len(q))])
    signs = np.concatenate([np.ones(len(p)), -np.ones(len(q))])
    order = np.argsort(nodes, kind="stable")
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(nodes, minlength=n), out=ptr[1:])
    return ptr, springs[order].astype(np.int64), signs[order]
