"""Which solver a system gets: one pure function, :func:`choose_plan`, from what the
system is (size, dimension, what the caller can hand the solver) to the steps tried in
turn. Both the problem's solve (reference/problem.py: the linear-field shortcut, the
matrix-free CG, the P1/Q1 subspace, the preconditioner to build) and the sparse solve
(reference/solvers/sparse.py: the steps on the assembled matrix) ask it, so every
crossover lives here. The solvers a case or a command may name are
``harness.registry.SOLVERS``; a step is one of ``reference.solvers.sparse.STEPS``.

Crossovers (``springbench bench reference`` measures them in one process,
results/bench/reference.csv; the measurements behind these numbers are in CHANGELOG.md):
the Cholesky wins up to ~300 Gflop (the 70k-dof cube: 23.5 s vs 25.9 s) and always in
2-D and on thin or nearly incompressible bodies (where AMG needs its strong setup);
'auto' therefore builds the Cholesky's symbolic factorisation (1-4 s at 50-150k dofs,
reused by the factorisation) and factorises when it predicts <= 300 Gflop and <= 2.5 GB,
else starts with AMG (a 150k-dof 3-D cube: AMG, 0.9 GB). Without coordinates SuperLU is
the direct solver, up to 15k dofs in 3-D (150k in 2-D). P2/Q2 systems handed their P1/Q1
subspace (reference/solvers/twolevel.py) take 'two-level' where 'auto' would take AMG
(the 50k-tet cylinder of ``bench calibrate``: 23 iterations, a third of AMG's CPU
time)."""

from __future__ import annotations

from dataclasses import dataclass

from harness.registry import SOLVERS

# 'auto' factorises when the Cholesky's symbolic estimate is below both of these (else
# AMG, falling back to the Cholesky): the measured break-even with AMG is ~300 Gflop;
# the estimate's memory (factor + 3 largest fronts) is within 10% of the measured peak
# minus the assembled system, so a solve stays under ~3 GB
CHOLESKY_GFLOP = 300.0
CHOLESKY_GBYTES = 2.5
# above these free dofs 'auto' goes to AMG without the symbolic estimate (3-D: a cube of
# 300k dofs needs ~2e3 Gflop, a 10:1 bar 140k dofs 300 Gflop)
SYMBOLIC_MAX = {2: 2_000_000, 3: 300_000}
# the same choice for SuperLU (no coordinates for the Cholesky's nested dissection):
# measured 3-D P2 SuperLU 9.4 s vs AMG 8.7 s at 14k dofs
SUPERLU_MAX = {2: 150_000, 3: 15_000}
# the fast-diagonalisation PCG on the assembled system (reference/solvers/tensorpre.py) from
# these many dofs (the 10:1 box's quarters at nu = 0.49, s, tensor / Cholesky: 17k dofs
# 1.7 / 1.3, 55k 6.1 / 11.5, 129k 7.7 / -); in 2-D the Cholesky stays
TENSOR_MIN = {2: 10**12, 3: 20_000}
# ... and without assembling it (one elastic tensor, reference/solvers/tensorsolve.py) from
# these many free dofs (s, matrix-free CG / Cholesky: 7k dofs 1.0 / 0.8, 17k 1.3 / 2.5)
MATRIX_FREE_MIN = {2: 10**12, 3: 10_000}
# a P2/Q2 system of at least these many dofs gets its P1/Q1 subspace (two-level); below,
# 'auto' always factorises
TWO_LEVEL_MIN = 20_000
# with the subspace, 'auto' factorises only while the Cholesky's estimate is at most this
# many Gflop per nonzero of A: the two-level takes ~7e-8 s per nonzero and iteration for
# three loads and 25-45 iterations, the Cholesky ~0.1 s per Gflop (P2 cubes nu = 0.45
# 13.9k dofs 1.8 / 1.4 s two-level / Cholesky, 45k 6.8 / 11.8, 70.6k 9.6 / 25.7, 104.5k
# 14 / 47; 10:1 bars nu = 0.49 61k 13.2 / 7.9, 139k 27 / 35: the rule picks the faster)
TWO_LEVEL_GFLOP_PER_NONZERO = 2.8e-5
# ... and from these many free dofs it takes the two-level without the symbolic estimate
# (9 s at 203k dofs, where the Cholesky needs 1,730 Gflop)
TWO_LEVEL_FIRST = {2: 10**12, 3: 150_000}

# what each first step falls back to when it is not accepted
_CHAINS = {
    "cholesky": ("cholesky",),
    "superlu": ("superlu",),
    "cg": ("cg", "amg", "amg-strong", "cholesky"),
    "amg": ("amg", "amg-strong", "cholesky"),
    "two-level": ("two-level", "amg-strong", "cholesky"),
}


@dataclass(frozen=True)
class System:
    """What the choice depends on. ``n``: free dofs; ``ndof``: all dofs; ``solver``: the
    case's ``[reference] solver`` (a name of SOLVERS); ``coords``: the free dofs' locations
    are known (the Cholesky's nested dissection; without them SuperLU is the direct
    solver); ``coarse``: a P2/Q2 system's P1/Q1 subspace is at hand (two-level);
    ``tensor``: the Q2 lattice's fast-diagonalisation preconditioner is at hand;
    ``matrix_free``: the stiffness is one elastic tensor on that lattice (K need not be
    assembled); ``nnz``: A's nonzeros; ``estimate``: the Cholesky's symbolic estimate
    {gflop, gbytes} once made."""

    n: int
    dim: int
    solver: str = "auto"
    ndof: int = 0
    coords: bool = True
    coarse: bool = False
    tensor: bool = False
    matrix_free: bool = False
    nnz: int = 0
    estimate: dict | None = None


@dataclass(frozen=True)
class Plan:
    """``steps``: the steps tried on the assembled system, in turn, until one is
    accepted; ``matrix_free``: try the matrix-free CG first; ``coarse``: build the P1/Q1
    subspace; ``needs_estimate``: 'auto' decides by the Cholesky's symbolic estimate:
    make it and ask again."""

    steps: tuple[str, ...] = ()
    matrix_free: bool = False
    coarse: bool = False
    needs_estimate: bool = False


def choose_plan(s: System) -> Plan:
    """The plan of system ``s`` (pure: the same system, the same plan)."""
    if s.solver not in SOLVERS:
        raise ValueError(f"unknown solver {s.solver!r} (one of {', '.join(SOLVERS)})")
    matrix_free = s.matrix_free and (s.solver == "tensor" or s.n >= MATRIX_FREE_MIN[s.dim])
    coarse = s.ndof >= TWO_LEVEL_MIN or s.solver == "two-level"
    two = s.coarse and s.coords
    if s.solver == "auto":
        if s.tensor and s.n >= TENSOR_MIN[s.dim]:
            first = "tensor"
        elif not s.coords:
            first = "superlu" if s.n <= SUPERLU_MAX[s.dim] else "amg"
        elif s.n > SYMBOLIC_MAX[s.dim] or (two and s.n >= TWO_LEVEL_FIRST[s.dim]):
            first = "amg"
        elif s.estimate is None:
            return Plan(matrix_free=matrix_free, coarse=coarse, needs_estimate=True)
        else:
            limit = (
                min(CHOLESKY_GFLOP, TWO_LEVEL_GFLOP_PER_NONZERO * s.nnz) if two else CHOLESKY_GFLOP
            )
            ok = s.estimate["gflop"] <= limit and s.estimate["gbytes"] <= CHOLESKY_GBYTES
            first = "cholesky" if ok else "amg"
    else:
        first = {"direct": "cholesky"}.get(s.solver, s.solver)
    if first == "cholesky" and not s.coords:
        first = "superlu"
    if s.solver == "auto" and first == "amg" and two:
        first = "two-level"
    if first == "two-level" and not two:
        first = "amg"
    steps: tuple[str, ...] = ()
    if first == "tensor":  # then what 'auto' would do without it
        first = "two-level" if two else "amg"
        steps = ("tensor",) if s.tensor else ()
    steps += _CHAINS[first]
    if steps[-1] == "cholesky" and not s.coords:
        steps = steps[:-1] + ("superlu",)
    return Plan(steps, matrix_free, coarse)


def choose(solver: str, n: int, dim: int) -> str:
    """For callers that pass neither coordinates nor rigid-body modes to a direct solve:
    'direct' or 'amg' for 'auto' by the SuperLU crossover :data:`SUPERLU_MAX` (every
    solver falls back by itself)."""
    if solver != "auto":
        return solver
    return "direct" if n <= SUPERLU_MAX[dim] else "amg"
