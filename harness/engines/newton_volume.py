"""A springbench export's volume term per node (``node_volume_*`` keys, harness/models/volume.py
NodeVolumeTerm) as Warp kernels beside Newton's solver: Newton has per-element volume terms
(tetrahedra) but none per node, so each step adds this term's forces to the particle forces
before ``solver.step``.

Node a owns V0_a and stores E_a = kv_a/2 dV_a^2 / V0_a, dV_a = sum over its tetrahedra e of
(V_e - V0_e) / 4; f = -dE/dx gives each tetrahedron's nodes its volume gradient dV_e/dx times
s_e = -(1/4) sum over its nodes a of kv_a dV_a / V0_a. Two kernels: the tetrahedra's volume
changes shared to their nodes, then their forces (atomic adds, float32 like the engine).
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.kernel
def node_changes(
    q: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.int32, ndim=2),
    V0: wp.array(dtype=wp.float32),
    dV: wp.array(dtype=wp.float32),
):
    e = wp.tid()
    i, j, k, m = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    x0 = q[i]
    share = (wp.dot(q[j] - x0, wp.cross(q[k] - x0, q[m] - x0)) / 6.0 - V0[e]) * 0.25
    wp.atomic_add(dV, i, share)
    wp.atomic_add(dV, j, share)
    wp.atomic_add(dV, k, share)
    wp.atomic_add(dV, m, share)


@wp.kernel
def element_forces(
    q: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.int32, ndim=2),
    stiff: wp.array(dtype=wp.float32),
    dV: wp.array(dtype=wp.float32),
    f: wp.array(dtype=wp.vec3),
):
    e = wp.tid()
    i, j, k, m = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    s = -0.25 * (stiff[i] * dV[i] + stiff[j] * dV[j] + stiff[k] * dV[k] + stiff[m] * dV[m])
    x0 = q[i]
    a, b, c = q[j] - x0, q[k] - x0, q[m] - x0
    gj, gk, gm = wp.cross(b, c) / 6.0, wp.cross(c, a) / 6.0, wp.cross(a, b) / 6.0
    wp.atomic_add(f, i, -s * (gj + gk + gm))
    wp.atomic_add(f, j, s * gj)
    wp.atomic_add(f, k, s * gk)
    wp.atomic_add(f, m, s * gm)


class NodeVolumeForces:
    """The term of one export on ``n`` particles: ``apply(q, f)`` adds its forces at positions
    q (a Warp vec3 array) into f (one)."""

    def __init__(self, n: int, data: dict):
        tets = np.asarray(data["node_volume_elements"], np.int32)
        stiff = np.zeros(n)
        nodes = np.asarray(data["node_volume_nodes"], int)
        stiff[nodes] = np.asarray(data["node_volume_stiffness"], float) / np.asarray(
            data["node_volume_rest"], float
        )
        self.tets = wp.array(tets, dtype=wp.int32, device="cpu")
        self.V0 = wp.array(
            np.asarray(data["node_volume_element_rest"], np.float32), dtype=wp.float32, device="cpu"
        )
        self.stiff = wp.array(stiff.astype(np.float32), dtype=wp.float32, device="cpu")
        self.dV = wp.zeros(n, dtype=wp.float32, device="cpu")

    def apply(self, q, f):
        self.dV.zero_()
        wp.launch(
            node_changes,
            dim=self.tets.shape[0],
            inputs=[q, self.tets, self.V0, self.dV],
            device="cpu",
        )
        wp.launch(
            element_forces,
            dim=self.tets.shape[0],
            inputs=[q, self.tets, self.stiff, self.dV, f],
            device="cpu",
        )
