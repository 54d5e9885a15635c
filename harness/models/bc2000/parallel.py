"""Classic spring forces for large networks on several threads (numba prange).

``spring_plan`` + ``spring_forces`` (the fast path): the nodes are cut into one
contiguous range per thread; each thread computes the springs with both ends in its range
and adds their forces straight into f (no other thread writes there), and the few
springs between ranges follow on one thread (few when the nodes are numbered with
locality, as a lattice or a mesh renumbered by reverse Cuthill-McKee). Within a thread,
springs sorted by first node go in blocks of SB: gathered into contiguous buffers, their
forces computed four at a time (AVX2), added back. Memory traffic is the springs' data
once plus the nodes: no atomics, no per-thread copies of f, no per-spring force array.

``spring_forces_parallel`` (kept as the reference two-pass form): pass 1 computes every
spring's force, pass 2 sums each node's incident springs through a node -> spring CSR
index.
"""

from dataclasses import dataclass

import numpy as np
from numba import get_num_threads, njit, prange


@dataclass(frozen=True)
class SpringPlan:
    """Springs ordered for ``spring_forces``: p3, q3 (s,) = 3 * node (uint32); ks, kd, L0
    (s,) in that order; ``order`` (s,) the original index of each (-1: padding, a
    zero-force copy); thread t owns the nodes [nodes[t], nodes[t+1]) and the springs
    bounds[t]:bounds[t+1] with both ends among them (sorted by p); the springs
    bounds[T]: (ends of different threads) come last; scratch (T, 9 SB)."""

    p3: np.ndarray
    q3: np.ndarray
    ks: np.ndarray
    kd: np.ndarray
    L0: np.ndarray
    order: np.ndarray
    bounds: np.ndarray
    nodes: np.ndarray
    scratch: np.ndarray


def spring_plan(springs, ks, kd, L0, n_nodes: int, threads: int | None = None) -> SpringPlan:
    """Cut the nodes into ``threads`` ranges (default: numba's thread count) with about
    equal numbers of springs; each range's inner springs sorted by first node and padded
    to whole blocks with copies with ks = kd = 0 (an exact zero force), then the springs
    between ranges."""
    springs = np.asarray(springs, np.int64)
    if 3 * n_nodes >= 2**32:
        raise ValueError("more than 1.4e9 nodes: the spring kernel indexes with uint32")
    T = max(1, int(threads or get_num_threads()))
    s = len(springs)
    p_sorted = np.sort(springs[:, 0])
    cuts = (
        [0] + [int(p_sorted[min(s - 1, (t * s) // T)]) if s else 0 for t in range(1, T)] + [n_nodes]
    )
    nodes = np.maximum.accumulate(np.asarray(cuts, np.int64))
    owner_p = np.searchsorted(nodes, springs[:, 0], side="right") - 1
    owner_q = np.searchsorted(nodes, springs[:, 1], side="right") - 1
    group = np.where(owner_p == owner_q, owner_p, T)  # T: between ranges
    order = np.lexsort((springs[:, 1], springs[:, 0], group))
    parts, bounds = [], [0]
    for t in range(T + 1):
        g = order[group[order] == t]
        if len(g):
            g = np.concatenate([g, np.full(-len(g) % SB, -1 - g[-1])])  # -1 - i: padding copy of i
        parts.append(g)
        bounds.append(bounds[-1] + len(g))
    idx = np.concatenate(parts) if s else np.zeros(0, np.int64)
    real = idx >= 0
    src = np.where(real, idx, -1 - idx)
    k = [np.where(real, np.asarray(a, float)[src], z) for a, z in ((ks, 0.0), (kd, 0.0), (L0, 1.0))]
    return SpringPlan(
        (3 * springs[src, 0]).astype(np.uint32),
        (3 * springs[src, 1]).astype(np.uint32),
        *k,
        np.where(real, idx, -1),
        np.asarray(bounds, np.int64),
        nodes,
        np.zeros((T, 9 * SB)),
    )


def spring_forces(plan: SpringPlan, x, v, f):
    """f (n, 3) C-contiguous = the springs' forces F = -[ks (L - L0) + kd (dv . n)] n at p,
    -F at q. f is written in place: a copy (non-contiguous or not float64) would be lost."""
    if not (
        isinstance(f, np.ndarray)
        and f.dtype == np.float64
        and f.flags.c_contiguous
        and f.size == 3 * int(plan.nodes[-1])
    ):
        raise ValueError(
            f"f must be a C-contiguous float64 array of {3 * int(plan.nodes[-1])} values"
        )
    _spring_forces(
        np.ascontiguousarray(x).reshape(-1),
        np.ascontiguousarray(v).reshape(-1),
        plan.p3,
        plan.q3,
        plan.ks,
        plan.kd,
        plan.L0,
        plan.bounds,
        plan.nodes,
        plan.scratch,
        f.reshape(-1),
    )


SB = 64  # springs per block: gathered, then computed 4 at a time (AVX2), then added
ONE = np.uint32(1)
TWO = np.uint32(2)


@njit(cache=True, error_model="numpy", fastmath=True)
def _spring_block(P, R, ks, kd, L0):
    """R rows 0-2: the force on p of SB springs from P rows 0-2 (l = x_p - x_q) and 3-5
    (v_p - v_q)."""
    for k in range(SB):
        lx = P[k]
        ly = P[SB + k]
        lz = P[2 * SB + k]
        L = np.sqrt(lx * lx + ly * ly + lz * lz)
        inv = 1.0 / L
        dv = P[3 * SB + k] * lx + P[4 * SB + k] * ly + P[5 * SB + k] * lz
        c = -(ks[k] * (L - L0[k]) + kd[k] * dv * inv) * inv
        R[k] = c * lx
        R[SB + k] = c * ly
        R[2 * SB + k] = c * lz


@njit(cache=True, error_model="numpy")
def _gather(x, v, p3, q3, P):
    # flat arrays and unsigned, premultiplied indices: no negative-index wraparound code
    for k in range(SB):
        i = p3[k]
        j = q3[k]
        P[k] = x[i] - x[j]
        P[SB + k] = x[i + ONE] - x[j + ONE]
        P[2 * SB + k] = x[i + TWO] - x[j + TWO]
        P[3 * SB + k] = v[i] - v[j]
        P[4 * SB + k] = v[i + ONE] - v[j + ONE]
        P[5 * SB + k] = v[i + TWO] - v[j + TWO]


@njit(cache=True, error_model="numpy")
def _scatter(f, p3, q3, R):
    # springs come sorted by p: sum a run of equal p in registers (no store-to-load chain)
    ip = p3[0]
    ax = 0.0
    ay = 0.0
    az = 0.0
    for k in range(SB):
        i = p3[k]
        j = q3[k]
        fx = R[k]
        fy = R[SB + k]
        fz = R[2 * SB + k]
        if i != ip:
            f[ip] += ax
            f[ip + ONE] += ay
            f[ip + TWO] += az
            ax = 0.0
            ay = 0.0
            az = 0.0
            ip = i
        ax += fx
        ay += fy
        az += fz
        f[j] -= fx
        f[j + ONE] -= fy
        f[j + TWO] -= fz
    f[ip] += ax
    f[ip + ONE] += ay
    f[ip + TWO] += az


@njit(cache=True, error_model="numpy")
def _spring_chunk(x, v, p3, q3, ks, kd, L0, k0, k1, P, R, f):
    for k in range(k0, k1, SB):
        _gather(x, v, p3[k : k + SB], q3[k : k + SB], P)
        _spring_block(P, R, ks[k : k + SB], kd[k : k + SB], L0[k : k + SB])
        _scatter(f, p3[k : k + SB], q3[k : k + SB], R)


@njit(parallel=True, cache=True, error_model="numpy")
def _spring_forces(x, v, p3, q3, ks, kd, L0, bounds, nodes, scratch, f):
    """x, v, f flat (3n,); p3, q3 = 3 * node (uint32). Thread t clears its nodes and adds
    its inner springs (no other thread touches those nodes); the springs between ranges
    follow on one thread."""
    T = nodes.shape[0] - 1
    for t in prange(T):
        for i in range(3 * nodes[t], 3 * nodes[t + 1]):
            f[i] = 0.0
        _spring_chunk(
            x,
            v,
            p3,
            q3,
            ks,
            kd,
            L0,
            bounds[t],
            bounds[t + 1],
            scratch[t, : 6 * SB],
            scratch[t, 6 * SB :],
            f,
        )
    _spring_chunk(
        x,
        v,
        p3,
        q3,
        ks,
        kd,
        L0,
        bounds[T],
        bounds[T + 1],
        scratch[0, : 6 * SB],
        scratch[0, 6 * SB :],
        f,
    )


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
