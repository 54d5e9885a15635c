"""Shared spring/mass test inputs: the tiny rectangle case (TINY, case_file), a closed-form
stand-in for the FEM reference (ClosedFormRef) and an independent dense assembly and solve
written spring by spring (dense_K, dense_solve)."""

import numpy as np

from harness.case.loadsets import stretch_closed_form

TINY = """
name = "tiny"
dim = 2
[body]
shape = "rectangle"
size = [2.0, 2.0]
[material]
E = 100.0
nu = 0.3
[loads]
set = "basic2d"
magnitude = 1.0
[model]
kind = "sms"
placement = "{placement}"
{extra}
stiffness = ["deussen", "vangelder", "lloyd", "uniform"]
[score]
weights = [1.0, 3.0, 15.0]
[optimizer]
method = "none"
[reference]
modes = 0
"""


def case_file(tmp_path, placement="grid", extra='grid = [3, 3]\nstructure = "structure1"'):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY.format(placement=placement, extra=extra))
    return f


class ClosedFormRef:
    """Stand-in for ReferenceSolution: stretch closed form, zero for other loads."""

    def __init__(self, case):
        self.case = case

    def displacement(self, points, load):
        lc = next(l for l in self.case.loads if l.name == load)
        if load.startswith("stretch"):
            return stretch_closed_form(
                lc, points, self.case.material.E, self.case.material.nu, self.case.body.bbox()[0]
            )
        return np.zeros_like(np.asarray(points, float))

    def frequencies(self, k, load=None):
        raise NotImplementedError


def dense_K(points, springs, k):
    """Independent assembly: K = sum k d d^T blocks, written out spring by spring."""
    n, dim = points.shape
    K = np.zeros((n * dim, n * dim))
    for (i, j), ke in zip(springs, k):
        d = points[j] - points[i]
        d /= np.linalg.norm(d)
        blk = ke * np.outer(d, d)
        for a, b, sgn in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[a * dim : (a + 1) * dim, b * dim : (b + 1) * dim] += sgn * blk
    return K


def dense_solve(points, springs, k, free, f):
    """Linear statics with the dense K of dense_K, numpy solve on the free dofs."""
    K = dense_K(points, springs, k)
    u = np.zeros(K.shape[0])
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    return u
