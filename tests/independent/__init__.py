"""An independent 3-D reference for the tests (and `springbench bench reference`): the
shear of a box (face z = 0 clamped, traction s along x on z = c) solved on a quarter
of the box with its own Q2 tensor-product assembly, its own graded mesh, its own solver,
point evaluation and Richardson extrapolation. Nothing here goes through reference/ or
harness/.

Symmetry: reflecting y about the middle maps the problem to itself (u_y odd, so u_y = 0
on the plane); reflecting x maps the load to its negative, so the solution is
antisymmetric (u_y = u_z = 0 on the plane x = a/2). The quarter [0, a/2] x [0, b/2] x
[0, c] with those conditions is the whole problem at a quarter of the unknowns.

Assembly (Kronecker). With a(u, v) = int lambda div u div v + 2 mu eps(u) : eps(v) and
2 eps(u) : eps(v) = sum_ij d_i u_j d_i v_j + d_j u_i d_i v_j, the block of test
component a and trial component b is

    K_ab = lambda G(a, b) + mu G(b, a) + delta_ab mu (G(x, x) + G(y, y) + G(z, z)),
    G(p, q)[i, j] = int d_p phi_i d_q phi_j     (i: test node, j: trial node).

On a tensor mesh of boxes with tensor-product Q2 basis phi_i = X_i(x) Y_i(y) Z_i(z),
G(p, q) = S_x (x) S_y (x) S_z (Kronecker), where per axis d S_d is the global 1-D matrix
A_d = int X' X' if d = p = q, B_d = int X'_i X_j if d = p != q, B_d^T if d = q != p, and
M_d = int X X otherwise. The 1-D element matrices of the quadratic Lagrange basis on
[0, h] (nodes 0, h/2, h) are exact rationals (below). Nodes are numbered
lexicographically with x slowest (index = (ix ny + iy) nz + iz) and the three
components are blocked: dof = component * N + node. The traction s e_x on z = c is
s (m_x (x) m_y (x) e_last) in the x block, m_d = int X_i.

Each Dirichlet condition fixes a component on a whole plane, so every component's free
dofs are a tensor product of per-axis sets: K on them is still a sum of Kronecker
products, applied matrix-free; its diagonal blocks K_aa = sum_d (mu + (lambda + mu)
delta_ad) A_d (x) M (x) M (A_d in position d) are inverted exactly by fast
diagonalisation (A_d V = M_d V diag(l_d) per axis): block-Jacobi-preconditioned CG, about
50 iterations for rtol 1e-13 at any size (true residual, checked, near 1e-10 at a million
dofs). tests/reference/test_independent.py checks the assembly against scikit-fem's own
elasticity forms on the same discrete problem.

Mesh: power grading (beta = 2.5) towards the faces x = 0, y = 0, z = 0 and z = c only
(the product grades with beta = 3 towards every face). ``knot = 0.75`` puts the thirds of
the sides on nodes of every level (``extrapolated_shear``): on the sec6 cube's shear the
order is then 2.55-2.57 at n = 12..32 (edges of the loaded face; 3.0-3.1 elsewhere), the
extrapolant of n = 16, 20, 24 within 1e-6 of max |u| of that of n = 24, 28, 32.
``long_axes`` (a 10:1 box): ``quarter_mesh``. ``extrapolate_levels``' change is blind at
the point that fixes the order (both extrapolants agree there by construction).
"""

from .box import BoxProblem, basis_1d, evaluate_grid
from .levels import extrapolate_levels, extrapolated_shear, observed_order, shear_levels
from .q2 import (
    _A,
    _B,
    _M,
    ELEM_A,
    ELEM_B,
    ELEM_M,
    ELEM_m,
    _m,
    axis_matrices,
    face_load,
    lame,
    q2_nodes,
    stiffness,
)
from .quarter import (
    QUARTER_FIXED,
    mirror_points,
    mirror_signs,
    quarter_dofs,
    quarter_mesh,
    quarter_shear,
    quarter_shear_field,
)

__all__ = [
    "BoxProblem",
    "ELEM_A",
    "ELEM_B",
    "ELEM_M",
    "ELEM_m",
    "QUARTER_FIXED",
    "_A",
    "_B",
    "_M",
    "_m",
    "axis_matrices",
    "basis_1d",
    "evaluate_grid",
    "extrapolate_levels",
    "extrapolated_shear",
    "face_load",
    "lame",
    "mirror_points",
    "mirror_signs",
    "observed_order",
    "q2_nodes",
    "quarter_dofs",
    "quarter_mesh",
    "quarter_shear",
    "quarter_shear_field",
    "shear_levels",
    "stiffness",
]
