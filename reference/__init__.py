"""The verified scikit-fem reference: ``solve(case) -> ReferenceSolution``.

Linear elasticity on triangles/quads (plane stress or strain) and tets/hexes, P1/Q1 or
P2/Q2, with a per-element Voigt stiffness (isotropic, transversely isotropic with a
per-element fibre, piecewise regions), the standard and user load cases, an error
estimate from the levels of refinement (calibrate's: until tol on the held-out
loads or a dof cap), modal analysis, a KD-tree point locator and an on-disk cache.
See reference/solution.py.
"""

from reference.solution import ReferenceSolution, solve

__all__ = ["solve", "ReferenceSolution"]
