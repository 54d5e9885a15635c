"""Inputs the bad-output and bad-command tests share: a tiny plate case and a cube of
tetrahedra."""

import numpy as np

from tests.plate_case import plate_case

CASE = plate_case(
    "tiny",
    """
    [reference]
    cell = "tri"
    divisions = 2
    max_refine = 1
    tol = 0.1
    modes = 0
    [model]
    kind = "sms"
    placement = "grid"
    grid = [3, 3]
    structure = "edges+diagonal"
    """,
)


def cube_tets(n: int = 2):
    """A unit cube split into 6 n^3 positively oriented tetrahedra (Kuhn)."""
    import itertools

    g = np.linspace(0.0, 1.0, n + 1)
    pts = np.array([[x, y, z] for z in g for y in g for x in g])
    idx = lambda i, j, k: i + (n + 1) * (j + (n + 1) * k)  # noqa: E731
    tets = []
    for i, j, k in itertools.product(range(n), repeat=3):
        v = [idx(i + a, j + b, k + c) for c in (0, 1) for b in (0, 1) for a in (0, 1)]
        for perm in itertools.permutations(range(3)):
            cur, path = [0, 0, 0], [0]
            for ax in perm:
                cur[ax] = 1
                path.append(cur[0] + 2 * cur[1] + 4 * cur[2])
            tets.append([v[q] for q in path])
    tets = np.array(tets)
    p = pts[tets]
    vol = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return pts, tets
