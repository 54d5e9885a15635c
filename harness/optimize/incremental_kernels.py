"""The compiled loops of harness/optimize/incremental.py: the G^2 change of a one-spring
proposal and the update of the held Woodbury state on an accept, for every stacked load
set at once (numba when installed, plain Python otherwise); see that module's docstring
for the algebra."""

from __future__ import annotations

import numpy as np


def _propose(
    m,
    j,
    delta,
    gf,
    gv,
    U0f,
    Ytf,
    q,
    nmax,
    acc_i,
    acc_v,
    T,
    Hz,
    sig,
    Cv,
    PV,
    AV,
    YY,
    YR,
    bY,
    ct,
    Hct,
    bz,
    sv,
    zWz,
    zR0,
    d2s,
):
    """G^2 change of a proposal, for every stacked set s (compiled by numba; plain
    Python otherwise). Work O(m^2) per set, reading only the upper triangles of T and
    Hz; fills the scratch arrays ct, Hct, bz, sv, zWz, zR0, d2s that an accept uses."""
    S, L, P = T.shape[0], Cv.shape[1], gf.shape[1]
    g = np.empty(m)
    gt = np.empty(m)
    bu = np.empty(L)
    total = 0.0
    for s in range(S):
        for l in range(L):
            acc = 0.0
            for p in range(P):
                acc += gv[s, p] * U0f[gf[s, p], l]
            bu[l] = acc
        row = (s * q + j) * nmax
        for i in range(m):  # g = Bm^T y (= Z^T b)
            acc = 0.0
            for p in range(P):
                acc += acc_v[s, i, p] * Ytf[row + acc_i[s, i, p]]
            g[i] = acc
            gt[i] = 0.0
        for i in range(m):  # gt = T^T g (= V^T b), T unit upper
            gi = g[i]
            if gi != 0.0:
                Ti = T[s, i]
                for k in range(i, m):
                    gt[k] += gi * Ti[k]
        cs = ct[s]
        hs = Hct[s]
        btz = 0.0
        for i in range(m):
            cs[i] = gt[i] / sig[s, i]
            btz += gt[i] * cs[i]
            hs[i] = 0.0
        for i in range(m):  # Hct = Hz ct, Hz symmetric (upper read)
            ci = cs[i]
            Hi = Hz[s, i]
            acc = Hi[i] * ci
            for k in range(i + 1, m):
                acc += Hi[k] * cs[k]
                hs[k] += Hi[k] * ci
            hs[i] += acc
        bz[s] = bY[s, j] - btz
        w = YY[s, j, j]
        for i in range(m):
            w += ct[s, i] * (Hct[s, i] - 2.0 * AV[s, i, j])
        zWz[s] = w
        d2 = 0.0
        for l in range(L):
            a1 = YR[s, j, l]
            a2 = 0.0
            for i in range(m):
                a1 -= ct[s, i] * PV[s, l, i]
                a2 += (AV[s, i, j] - Hct[s, i]) * Cv[s, l, i]
                bu[l] -= gt[i] * Cv[s, l, i]
            zR0[s, l] = a1
            sl = delta * bu[l] / (1.0 + delta * bz[s])
            sv[s, l] = sl
            d2 += sl * (2.0 * (a1 + a2) + sl * w)
        d2s[s] = d2
        total += d2
    return total


def _accept(
    m,
    j,
    delta,
    gi_e,
    gv_e,
    T,
    Hz,
    sig,
    Cv,
    PV,
    AV,
    YY,
    Yt,
    Zt,
    acc_i,
    acc_v,
    ct,
    Hct,
    bz,
    sv,
    zWz,
    zR0,
):
    """Append the proposed z = y - V ct as basis column m (compiled by numba)."""
    S, L, q = T.shape[0], Cv.shape[1], AV.shape[2]
    for s in range(S):
        cs = ct[s]
        for i in range(m):  # T column m = [-T ct; 1]
            Ti = T[s, i]
            acc = 0.0
            for k in range(i, m):
                acc += Ti[k] * cs[k]
            Ti[m] = -acc
        T[s, m, m] = 1.0
        for i in range(m):  # Hz border: V^T W z = av - Hz ct
            h = AV[s, i, j] - Hct[s, i]
            Hz[s, i, m] = h
            Hz[s, m, i] = h
        Hz[s, m, m] = zWz[s]
        sig[s, m] = 1.0 / delta + bz[s]
        for l in range(L):
            Cv[s, l, m] = sv[s, l]
            PV[s, l, m] = zR0[s, l]
        for jj in range(q):  # AV row m: z^T W Y = YY[j] - ct^T AV
            AV[s, m, jj] = YY[s, j, jj]
        Am = AV[s, m]
        for i in range(m):
            ci = cs[i]
            Ai = AV[s, i]
            for jj in range(q):
                Am[jj] -= ci * Ai[jj]
        Zt[s, m, :] = Yt[s, j, :]
        for p in range(gi_e.shape[1]):
            acc_i[s, m, p] = gi_e[s, p]
            acc_v[s, m, p] = gv_e[s, p]


_KERNELS: dict = {}


def _kernels():
    """(propose, accept), compiled by numba (a declared dependency; cached on disk)."""
    if not _KERNELS:
        import numba

        jit = numba.njit(
            cache=True, nogil=True, fastmath={"reassoc", "contract"}
        )  # vectorised sums
        _KERNELS.update(propose=jit(_propose), accept=jit(_accept))
    return _KERNELS["propose"], _KERNELS["accept"]
