"""Model arrays -> the block layout of the compiled kernels (kernels.py, see codegen.py).

A model's blocks do not depend on the step except for the damping constants (per step
in the kernel: kd / dt), so the step-independent part is built once per model and kept
on it (models are immutable); each call then only rescales the damping rows and
allocates the per-run scratch buffers.
"""

from __future__ import annotations

import numpy as np

from harness.models.anisotropic import AnisotropicBody
from harness.models.bc2000.codegen import BLOCK, LAYOUT, NV, n_rows, rows
from harness.models.massspring import MassSpring

DAMPING = {"spring": ("kd",), "tet": ("kd",), "hex": ("kd", "kvd")}


def _blocks(columns: np.ndarray) -> np.ndarray:
    """(m, r) per-element columns -> (blocks, r * BLOCK), padded with copies of element 0
    (finite values: padding lanes compute something harmless and are never added)."""
    m, r = columns.shape
    nb = -(-m // BLOCK)
    pad = np.empty((nb * BLOCK, r))
    pad[:m] = columns
    pad[m:] = columns[:1]
    return np.ascontiguousarray(pad.reshape(nb, BLOCK, r).transpose(0, 2, 1)).reshape(nb, r * BLOCK)


def _block_index(idx: np.ndarray) -> np.ndarray:
    """(m, nv) node ids -> (blocks, nv * BLOCK) uint32 of 3 * node (flat x), element b of
    block k at [k, b * nv + i]; padded with copies of element 0."""
    m, nv = idx.shape
    if 3 * (int(idx.max(initial=0)) + 1) >= 2**32:
        raise ValueError("more than 1.4e9 nodes: the kernels index with uint32")
    nb = -(-m // BLOCK)
    out = np.empty((nb * BLOCK, nv), np.uint32)
    out[:m] = 3 * idx
    out[m:] = 3 * idx[:1]
    return out.reshape(nb, nv * BLOCK)


def dense_axis_weights(cells, nodes, weights) -> np.ndarray:
    """W (m, 3, nv): axis k = P_k - P'_k = sum_i W[k, i] x_i, from the ends' faces
    (global node ids (m, 6, w)) and their barycentric / bilinear weights (m, 6, w)."""
    m, nv = cells.shape
    local = np.argmax(cells[:, None, None, :] == nodes[..., None], axis=-1)  # (m, 6, w)
    sign = np.where(np.arange(6) % 2 == 0, 1.0, -1.0)[None, :, None]
    W = np.zeros((m, 3, nv))
    e = np.broadcast_to(np.arange(m)[:, None, None], local.shape)
    axis = np.broadcast_to((np.arange(6) // 2)[None, :, None], local.shape)
    np.add.at(W, (e, axis, local), sign * weights)
    return W


def _columns(kind, model) -> dict:
    if kind == "spring":
        return {"ks": model.ks[:, None], "kd": model.kd[:, None], "L0": model.L0[:, None]}
    m = len(model.cells)
    return {
        "W": dense_axis_weights(model.cells, model.axes.nodes, model.axes.weights).reshape(m, -1),
        "ks": model.ks,
        "kd": model.kd,
        "L0": model.L0,
        "cos0": model.cos0,
        "kvs": model.kvs[:, None],
        "kvd": model.kvd[:, None],
        "D0": model.D0.reshape(m, -1),
    }


def _static(kind, model):
    """(index, S with physical damping, m, vol), cached on the model."""
    cache = getattr(model, "_kernel_blocks", None)
    if cache is None:
        cols = _columns(kind, model)
        C = np.concatenate(
            [
                np.asarray(cols[name], float).reshape(len(cols[name]), -1)
                for name, _ in LAYOUT[kind]
            ],
            axis=1,
        )
        assert C.shape[1] == n_rows(kind)
        index = model.springs if kind == "spring" else model.cells
        cache = (
            _block_index(np.asarray(index, np.int64)),
            _blocks(C),
            len(C),
            bool(getattr(model, "volume", False)),
        )
        object.__setattr__(model, "_kernel_blocks", cache)
    return cache


def _scratch_rows(kind):
    """Rows of the gather buffer P and of the force buffer R."""
    return (6, 3) if kind == "spring" else (6 * NV[kind], 3 * NV[kind])


def empty(kind: str):
    """Arguments of a model part that is absent (no blocks)."""
    p, r = _scratch_rows(kind)
    width = 2 if kind == "spring" else NV[kind]
    return (
        np.zeros((0, width * BLOCK), np.uint32),
        np.zeros((0, n_rows(kind) * BLOCK)),
        np.zeros((1, p * BLOCK)),
        np.zeros((1, r * BLOCK)),
        0,
        False,
    )


def block_arrays(kind: str, model, dt: float, threads: int = 1):
    """(idx, S, P, R, m, vol) for kernels.run: idx the blocks' node indices, S the element
    columns with damping per step (kd / dt), P and R scratch (one block, or one per block
    for two threads)."""
    index, S, m, vol = _static(kind, model)
    S = S.copy()
    r = rows(kind)
    for name in DAMPING[kind]:
        k = dict(LAYOUT[kind])[name]
        S[:, r[name] * BLOCK : (r[name] + k) * BLOCK] /= dt
    p, q = _scratch_rows(kind)
    nb = len(S) if threads >= 2 else 1
    return index, S, np.zeros((nb, p * BLOCK)), np.zeros((nb, q * BLOCK)), m, vol


def kernel_arrays(model, dt: float, threads: int = 1):
    """(springs, tet, hexa) argument tuples of kernels.run; None if the model is neither
    a MassSpring nor an AnisotropicBody. Kept on the model per (dt, threads): a short run
    should not pay for the packing again (the scratch buffers are rewritten before every
    use, so runs can share them)."""
    key = (float(dt), threads >= 2)
    cache = getattr(model, "_kernel_args", None)
    if cache is None:
        cache = {}
        try:
            object.__setattr__(model, "_kernel_args", cache)
        except AttributeError:  # not a model of ours (slots): nothing to cache
            pass
    if key not in cache:
        if len(cache) > 8:
            cache.clear()
        cache[key] = _kernel_arrays(model, dt, threads)
    return cache[key]


def _kernel_arrays(model, dt, threads):
    out = {"spring": empty("spring"), "tet": empty("tet"), "hex": empty("hex")}
    if isinstance(model, MassSpring):
        out["spring"] = block_arrays("spring", model, dt, threads)
    elif isinstance(model, AnisotropicBody):
        kind = "hex" if model.is_hex else "tet"
        out[kind] = block_arrays(kind, model, dt, threads)
    else:
        return None
    return out["spring"], out["tet"], out["hex"]
