"""Classic spring forces for large networks on several threads (numba prange).

``spring_plan`` + ``spring_forces`` (the fast path): springs sorted by their first node
and cut into one contiguous chunk per thread; each thread adds its springs' forces into
its own buffer covering only the node window its chunk touches (a band when the nodes
are numbered with locality, as a lattice or a mesh renumbered by reverse Cuthill-McKee);
the windows are then summed per node. Within a thread, blocks of SB springs are gathered
into contiguous buffers, their forces computed four at a time (AVX2), and added back.
Memory traffic is the springs' data once plus the node windows: no atomics, no
per-spring force array.

``spring_forces_parallel`` (kept as the reference two-pass form): pass 1 computes every
spring's force, pass 2 sums each node's incident springs through a node -> spring CSR
index.
"""

from dataclasses import dataclass

import numpy as np
from numba import get_num_threads, njit, prange


@dataclass(frozen=True)
class SpringPlan:
    """Springs ordered for ``spring_forces``: p3, q3 (s,) = 3 * node (uint32), sorted by
    p; ks, kd, L0 (s,) in that order; ``order`` (s,) the original index of each (the last
    block padded with zero-force copies); bounds (T+1,) the thread chunks; lo, hi (T,) the
    node window of each chunk; buf (T, 3 W) and scratch (T, 9 SB) per-thread buffers."""
    p3: np.ndarray
    q3: np.ndarray
    ks: np.ndarray
    kd: np.ndarray
    L0: np.ndarray
    order: np.ndarray
    bounds: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    buf: np.ndarray
    scratch: np.ndarray


def spring_plan(springs, ks, kd, L0, n_nodes: int, threads: int | None = None) -> SpringPlan:
    """Sort the springs (s, 2) by first node and cut them into ``threads`` chunks of whole
    blocks (default: numba's thread count). The last block is padded with copies of the
    last spring with ks = kd = 0 (an exact zero force)."""
    springs = np.asarray(springs)
    T = max(1, int(threads or get_num_threads()))
    s = len(springs)
    order = np.lexsort((springs[:, 1], springs[:, 0]))
    blocks = -(-s // SB)
    pad = blocks * SB - s
    idx = np.concatenate([order, np.full(pad, order[-1] if s else 0, order.dtype)])
    p = np.ascontiguousarray(springs[idx, 0], np.int64)
    q = np.ascontiguousarray(springs[idx, 1], np.int64)
    k = [np.concatenate([np.asarray(a, float)[order], np.zeros(pad)]) for a in (ks, kd, L0)]
    k[2][s:] = 1.0
    bounds = SB * np.linspace(0, blocks, T + 1).round().astype(np.int64)
    lo = np.zeros(T, np.int64)
    hi = np.zeros(T, np.int64)
    for t in range(T):
        a, b = bounds[t], bounds[t + 1]
        if b > a:
            lo[t] = min(p[a:b].min(), q[a:b].min())
            hi[t] = max(p[a:b].max(), q[a:b].max()) + 1
    width = int((hi - lo).max()) if s else 0
    if 3 * n_nodes >= 2 ** 32:
        raise ValueError("more than 1.4e9 nodes: the spring kernel indexes with uint32")
    return SpringPlan((3 * p).astype(np.uint32), (3 * q).astype(np.uint32), *k, order, bounds, lo, hi,
                      np.zeros((T, 3 * width)), np.zeros((T, 9 * SB)))


def spring_forces(plan: SpringPlan, x, v, f):
    """f (n, 3) C-contiguous = the springs' forces F = -[ks (L - L0) + kd (dv . n)] n at p,
    -F at q."""
    _spring_forces(np.ascontiguousarray(x).reshape(-1), np.ascontiguousarray(v).reshape(-1), plan.p3, plan.q3,
                   plan.ks, plan.kd, plan.L0, plan.bounds, plan.lo, plan.hi, plan.buf, plan.scratch, f.reshape(-1))


SB = 64     # springs per block: gathered, then computed 4 at a time (AVX2), then added
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
def _scatter(b, p3, q3, o3, R):
    # springs come sorted by p: sum a run of equal p in registers (no store-to-load chain)
    ip = p3[0] - o3
    ax = 0.0
    ay = 0.0
    az = 0.0
    for k in range(SB):
        i = p3[k] - o3
        j = q3[k] - o3
        fx = R[k]
        fy = R[SB + k]
        fz = R[2 * SB + k]
        if i != ip:
            b[ip] += ax
            b[ip + ONE] += ay
            b[ip + TWO] += az
            ax = 0.0
            ay = 0.0
            az = 0.0
            ip = i
        ax += fx
        ay += fy
        az += fz
        b[j] -= fx
        b[j + ONE] -= fy
        b[j + TWO] -= fz
    b[ip] += ax
    b[ip + ONE] += ay
    b[ip + TWO] += az


@njit(parallel=True, cache=True, error_model="numpy")
def _spring_forces(x, v, p3, q3, ks, kd, L0, bounds, lo, hi, buf, scratch, f):
    """x, v, f flat (3n,); p3, q3 = 3 * node (uint32); buf (T, 3 W) flat windows, zero on
    entry and on return."""
    T = bounds.shape[0] - 1
    for t in prange(T):
        b = buf[t]
        P = scratch[t, :6 * SB]
        R = scratch[t, 6 * SB:]
        o3 = np.uint32(3 * lo[t])
        for k0 in range(bounds[t], bounds[t + 1], SB):
            k1 = k0 + SB
            _gather(x, v, p3[k0:k1], q3[k0:k1], P)
            _spring_block(P, R, ks[k0:k1], kd[k0:k1], L0[k0:k1])
            _scatter(b, p3[k0:k1], q3[k0:k1], o3, R)
    for i in prange(f.shape[0] // 3):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for t in range(T):
            if lo[t] <= i < hi[t]:
                r = 3 * (i - lo[t])
                a0 += buf[t, r]
                a1 += buf[t, r + 1]
                a2 += buf[t, r + 2]
                buf[t, r] = 0.0             # the buffers are left zero for the next call
                buf[t, r + 1] = 0.0
                buf[t, r + 2] = 0.0
        f[3 * i] = a0
        f[3 * i + 1] = a1
        f[3 * i + 2] = a2


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
