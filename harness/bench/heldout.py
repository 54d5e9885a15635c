"""springbench bench heldout: does ``springbench calibrate`` beat the best stiffness rule on
bodies, clamps and loads it never saw? The judge is independent of springbench's FEM and
statics: its truth is a P2 solve written here with scikit-fem, its model answer the
linear statics of the exported JSON assembled here.

Bodies (gmsh, none of the test meshes): an L-bracket, a tapered bar with a through-hole,
a 120-degree torus sector (an elbow) and a dumbbell (two blocks and a neck), ~3,000
tetrahedra each, written as gmsh .msh with physical surfaces ``clamp`` and ``load`` unlike
calibrate's own held-out ends (those clamp the low end of the longest axis and load the
high end): the bracket is clamped on the top of its upright and loaded on the end of its
arm, the tapered bar is bolted through its hole, the elbow clamped at its 0-degree end,
the dumbbell held on the underside of one block and loaded on the top of the other.
E = 1e5 Pa, nu = 0.3 and 0.45, density 1000 (quick: the bracket, ~1,000 tets, nu = 0.3).

Models: per (body, nu) ``springbench calibrate`` with its defaults (the fit; ``--max-refine
1``, ``--budget 60``) in its own process with an empty reference cache (``seconds`` is its
wall time), then ``--method rule --rule R`` for every rule, which share that cache (a
rule's constants do not depend on the reference, which only scores them). Only the JSON
exports are read.

Loads (the study's own, clamp group held in every component): tractions on the load group
along two directions across it, a twist about its normal (t = tau n x (x - c)), gravity,
and gravity with the load group held too (a second support). Each is scaled so that the
99th percentile of the truth's strain norm |eps| over its quadrature points is 1e-3.

Truth: P2 on the mesh itself (~16k dofs, a few seconds for all five loads; ``refine=True``:
on the mesh refined once, whose ~100k dofs took SuperLU over ten minutes), isotropic linear
elasticity, tractions through FacetBasis on the group's facets (a refined mesh's sub-facets
found through their parent triangle), all dofs of the clamp's facets held, one sparse LU
per support. Model: K = sum_s k b b^T (unit rest
direction b) plus kv / V0 g g^T per volume element (g = dV/dx at rest) or kn V d^2 h h^T per
kn node (h = d s / du), P1-consistent nodal forces of the same traction on the same
facets (exact for linear tractions), gravity m_i g with the exported masses, the clamp
group's nodes held.

Metric: err = |u_model - u_truth| / |u_truth| over the mesh's vertices. Per (body, nu) the
best rule in hindsight minimises the geometric mean over the loads of err, and
ratio = geomean(err_calibrate) / geomean(err_best_rule); overall the geometric mean of the
ratios. Acceptance: ratio <= 1 for every (body, nu) and <= 0.75 overall.

Rows: one per (body, nu, model, load) (ratio_to_best_rule: err over the best rule's err on
that load), a ``geomean`` row per (body, nu, model) and an overall row (body ``all``).
Columns: body, n_tets, nu, model (calibrate or a rule), choice (the JSON's ``choice``, else
the exported stiffness-optimizer), rule (the exported row's stiffness rule), load, err,
best_rule, ratio_to_best_rule, seconds (that calibrate's wall time), truth_seconds.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.models.stiffness_rules import RULES  # the rule names calibrate's --rule takes
from harness.progress import steps

E, RHO = 1e5, 1000.0
NUS = (0.3, 0.45)
FULL_TETS, QUICK_TETS = 3000, 1000
BUDGET = 60.0
PEAK_STRAIN = 1e-3
ACCEPT_EACH, ACCEPT_ALL = 1.0, 0.75
COLUMNS = ["body", "n_tets", "nu", "model", "choice", "rule", "load", "err", "best_rule", "ratio_to_best_rule",
           "seconds", "truth_seconds", "note"]


# -- bodies --------------------------------------------------------------------------------

def _prism(occ, xy, height):
    """The polygon xy (z = 0) extruded to z = height: the volume's tag."""
    ps = [occ.addPoint(x, y, 0) for x, y in xy]
    ls = [occ.addLine(ps[i], ps[(i + 1) % len(ps)]) for i in range(len(ps))]
    s = occ.addPlaneSurface([occ.addCurveLoop(ls)])
    return next(t for d, t in occ.extrude([(2, s)], 0, 0, height) if d == 3)


def _bracket(occ):
    return _prism(occ, [(0, 0), (0.4, 0), (0.4, 0.1), (0.1, 0.1), (0.1, 0.3), (0, 0.3)], 0.1)


def _taper(occ):
    bar = _prism(occ, [(0, -0.08), (0.5, -0.04), (0.5, 0.04), (0, 0.08)], 0.06)
    hole = occ.addCylinder(0.15, 0, -0.01, 0, 0, 0.08, 0.03)
    return occ.cut([(3, bar)], [(3, hole)])[0][0][1]


def _elbow(occ):
    return occ.addTorus(0, 0, 0, 0.25, 0.06, angle=2 * math.pi / 3)


def _dumbbell(occ):
    a, b = occ.addBox(0, 0, 0, 0.15, 0.15, 0.15), occ.addBox(0.45, 0, 0, 0.15, 0.15, 0.15)
    neck = occ.addCylinder(0.1, 0.075, 0.075, 0.4, 0, 0, 0.045)
    return occ.fuse([(3, a)], [(3, b), (3, neck)])[0][0][1]


def _near(*c):
    return lambda x: np.linalg.norm(np.asarray(x) - c) < 1e-3


@dataclass(frozen=True)
class Body:
    """A gmsh solid; clamp and load pick its surfaces by their centre of mass; the two
    traction directions across the load face and gravity's direction."""
    name: str
    build: object
    clamp: object
    load: object
    across: tuple
    gravity: tuple


BODIES = (
    Body("bracket", _bracket, _near(0.05, 0.3, 0.05), _near(0.4, 0.05, 0.05), ((0, -1, 0), (0, 0, 1)), (0, -1, 0)),
    Body("taper", _taper, _near(0.15, 0, 0.03), _near(0.5, 0, 0.03), ((0, -1, 0), (0, 0, -1)), (0, 0, -1)),
    Body("elbow", _elbow, _near(0.25, 0, 0), _near(-0.125, 0.25 * math.sin(2 * math.pi / 3), 0),
         ((0, 0, -1), (-0.5, math.sin(2 * math.pi / 3), 0)), (0, 0, -1)),
    Body("dumbbell", _dumbbell, _near(0.075, 0.075, 0), _near(0.525, 0.075, 0.15), ((0, 0, -1), (0, 1, 0)),
         (0, 0, -1)),
)


def make_body(body: Body, path: Path, n_tets: int) -> int:
    """Mesh ``body`` with about n_tets tetrahedra (one size correction) into the gmsh .msh
    ``path`` with physical surfaces clamp and load and the volume body; the tet count."""
    import gmsh
    h = (8.5 * 0.005 / n_tets) ** (1 / 3)
    for attempt in range(2):
        gmsh.initialize(["-noenv"])
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)   # gmsh's start resets it: a closed pipe would kill us
        try:
            for key, value in (("General.Terminal", 0), ("General.NumThreads", 1), ("Mesh.RandomSeed", 0),
                               ("Mesh.MeshSizeMax", h), ("Mesh.MeshSizeMin", h / 2),
                               ("Mesh.MeshSizeFromCurvature", 12), ("Mesh.MshFileVersion", 4.1)):
                gmsh.option.setNumber(key, value)
            gmsh.model.add(body.name)
            occ_volume = body.build(gmsh.model.occ)
            gmsh.model.occ.synchronize()
            faces = [t for _, t in gmsh.model.getBoundary([(3, occ_volume)], oriented=False)]
            centre = {t: gmsh.model.occ.getCenterOfMass(2, t) for t in faces}
            for group, pick in (("clamp", body.clamp), ("load", body.load)):
                tags = [t for t in faces if pick(centre[t])]
                if len(tags) != 1:
                    raise RuntimeError(f"{body.name}: {len(tags)} faces for group {group}")
                gmsh.model.addPhysicalGroup(2, tags, name=group)
            gmsh.model.addPhysicalGroup(3, [occ_volume], name="body")
            gmsh.model.mesh.generate(3)
            tets = len(gmsh.model.mesh.getElementsByType(4)[0])
            if attempt == 1:
                gmsh.write(str(path))
        finally:
            gmsh.finalize()
        h *= (tets / n_tets) ** (1 / 3)
    return tets


def read_body(path: Path):
    """(points (n, 3), tets (m, 4), {group: triangles (k, 3)}) of a body's .msh (meshio)."""
    import meshio
    m = meshio.read(path)
    tets = m.cells_dict["tetra"]
    used = np.unique(tets)
    index = np.full(len(m.points), -1)
    index[used] = np.arange(len(used))
    tris = m.cells_dict["triangle"]
    groups = {g: index[tris[s["triangle"]]] for g, s in m.cell_sets_dict.items()
              if "triangle" in s and not g.startswith("gmsh:")}
    return np.asarray(m.points[used], float), index[tets], groups


# -- loads ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class Load:
    """traction(x) (3, ...) -> (3, ...) on the load group, or a gravity vector; held: the
    groups whose nodes are held."""
    name: str
    held: tuple
    traction: object = None
    gravity: tuple | None = None


def face_frame(points, tris):
    """(area-weighted centroid (3,), unit normal (3,), area) of a planar group."""
    x = points[tris]
    a = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]) / 2
    area = np.linalg.norm(a, axis=1)
    c = (x.mean(axis=1) * area[:, None]).sum(0) / area.sum()
    n = a.sum(0)
    return c, n / np.linalg.norm(n), area.sum()


def constant(d):
    """The traction field t(x) = d (x: (3, ...) -> (3, ...))."""
    d = np.asarray(d, float)
    return lambda x: np.broadcast_to(d.reshape((3,) + (1,) * (x.ndim - 1)), x.shape)


def twisting(axis, centre):
    """The traction field t(x) = axis x (x - centre)."""
    a, c = np.asarray(axis, float), np.asarray(centre, float)
    return lambda x: np.cross(a, x - c.reshape((3,) + (1,) * (x.ndim - 1)), axis=0)


def study_loads(body: Body, points, groups) -> list[Load]:
    """The study's loads of a body (unit magnitudes; scaled by the truth later)."""
    c, n, _ = face_frame(points, groups["load"])
    return [Load("shear_a", ("clamp",), constant(body.across[0])),
            Load("shear_b", ("clamp",), constant(body.across[1])),
            Load("twist", ("clamp",), twisting(n, c)),
            Load("gravity", ("clamp",), gravity=body.gravity),
            Load("gravity_2", ("clamp", "load"), gravity=body.gravity)]


# -- truth: P2, scikit-fem -----------------------------------------------------------------

def _key(tri: np.ndarray, n: int) -> np.ndarray:
    s = np.sort(np.asarray(tri, np.int64), axis=1)
    return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]


def truth(points, tets, groups, loads, nu, rho=RHO, refine=False):
    """{load: (u at the vertices (n, 3), strain peak)} of the P2 solution, each load at unit
    magnitude; the P2 mesh is ``tets`` refined once (refine) or itself."""
    from skfem import Basis, ElementTetP2, ElementVector, FacetBasis, LinearForm, MeshTet, asm
    from skfem.helpers import dot, sym_grad
    from skfem.models.elasticity import lame_parameters, linear_elasticity
    n = len(points)
    coarse = MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))
    mesh = coarse.refined() if refine else coarse
    parents = np.repeat(np.arange(n)[:, None], 2, axis=1)
    if refine:                                   # vertex n + j is the midpoint of coarse edge j
        assert np.allclose(mesh.p[:, n:], coarse.p[:, coarse.edges].mean(axis=1))
        parents = np.vstack([parents, coarse.edges.T])
    bf = mesh.boundary_facets()
    fv = parents[mesh.facets[:, bf].T].reshape(len(bf), -1)       # each boundary facet's parents
    fv = np.sort(fv, axis=1)
    distinct = np.c_[fv[:, :1], np.where(np.diff(fv, axis=1) > 0, fv[:, 1:], -1)]
    tri = np.sort(distinct, axis=1)[:, -3:]                         # its parent triangle's vertices
    keys = _key(tri, n)

    def facets(group):
        return bf[np.isin(keys, _key(groups[group], n))]
    lam, mu = lame_parameters(E, nu)
    e = ElementVector(ElementTetP2())
    basis = Basis(mesh, e, intorder=4)
    K = asm(linear_elasticity(lam, mu), basis).tocsc()
    out, lus = {}, {}
    for load in loads:
        if load.held not in lus:
            held = np.unique(np.concatenate([basis.get_dofs(facets=facets(g)).all() for g in load.held]))
            free = np.setdiff1d(np.arange(basis.N), held)
            lus[load.held] = (free, spla.splu(K[free][:, free], permc_spec="MMD_AT_PLUS_A"))
        free, lu = lus[load.held]
        if load.traction is not None:
            fb = FacetBasis(mesh, e, facets=facets("load"), intorder=4)
            b = asm(LinearForm(lambda v, w: dot(load.traction(w.x), v)), fb)
        else:
            g = rho * np.asarray(load.gravity, float)
            b = asm(LinearForm(lambda v, w: g[0] * v[0] + g[1] * v[1] + g[2] * v[2]), basis)
        u = np.zeros(basis.N)
        u[free] = lu.solve(b[free])
        eps = sym_grad(basis.interpolate(u))
        peak = np.percentile(np.sqrt(np.einsum("ij...,ij...->...", eps, eps)), 99)
        out[load.name] = (u[basis.nodal_dofs[:, :n]].T.copy(), float(peak))
    return out


# -- the exported network's statics --------------------------------------------------------

def network_stiffness(data: dict) -> sp.csr_matrix:
    """K (3n, 3n) of an exported model at rest: springs, volume terms (per element or per node),
    kn terms."""
    x = np.asarray(data["particle_q"], float)
    n = len(x)
    s = np.asarray(data["spring_indices"], int)
    d = x[s[:, 1]] - x[s[:, 0]]
    L = np.linalg.norm(d, axis=1)
    b = d / L[:, None]
    G = _rows(np.c_[-b, b], s, n)                                  # (springs, 3n): dl/du
    K = G.T @ sp.diags(np.asarray(data["spring_stiffness"], float)) @ G
    if "volume_indices" in data:                                   # kv/2 (V - V0)^2 / V0 per element
        kv = np.asarray(data["volume_stiffness"], float) / np.asarray(data["volume_rest"], float)
        Gv = _volume_rows(x, np.asarray(data["volume_indices"], int))
        K = K + Gv.T @ sp.diags(kv) @ Gv
    if "node_volume_elements" in data:                             # kv_a/2 dV_a^2 / V0_a per node
        t = np.asarray(data["node_volume_elements"], int)
        a = np.asarray(data["node_volume_nodes"], int)
        where = np.full(n, -1)
        where[a] = np.arange(len(a))
        share = sp.csr_matrix((np.full(t.size, 0.25), (where[t.ravel()], np.repeat(np.arange(len(t)), 4))),
                              shape=(len(a), len(t)))
        Gn = share @ _volume_rows(x, t)                            # dV_a/du
        kv = np.asarray(data["node_volume_stiffness"], float) / np.asarray(data["node_volume_rest"], float)
        K = K + Gn.T @ sp.diags(kv) @ Gn
    if "kn_nodes" in data:                                         # kn_a/2 V_a d^2 s_a^2 per node
        a = np.asarray(data["kn_nodes"], int)
        where = np.full(n, -1)
        where[a] = np.arange(len(a))
        ends, spring = s.T.ravel(), np.tile(np.arange(len(s)), 2)
        on = where[ends] >= 0
        S = sp.csr_matrix((np.ones(on.sum()), (where[ends[on]], spring[on])), shape=(len(a), len(s)))
        H = sp.diags(1 / np.asarray(data["kn_spring_count"], float)) @ S @ sp.diags(1 / L) @ G    # ds_a/du
        c = np.asarray(data["kn_stiffness"], float) * np.asarray(data["kn_node_volume"], float) * 9.0
        K = K + H.T @ sp.diags(c) @ H
    return sp.csr_matrix(K)


def _volume_rows(x: np.ndarray, t: np.ndarray) -> sp.csr_matrix:
    """(m, 3n): dV_e/du of the tetrahedra t at positions x."""
    e = x[t[:, 1:]] - x[t[:, :1]]
    g = np.stack([np.cross(e[:, 1], e[:, 2]), np.cross(e[:, 2], e[:, 0]), np.cross(e[:, 0], e[:, 1])], 1) / 6
    return _rows(np.c_[-g.sum(1), g.reshape(len(t), 9)], t, len(x))


def _rows(blocks: np.ndarray, nodes: np.ndarray, n: int) -> sp.csr_matrix:
    """(m, 3n) sparse rows: row r holds blocks[r, 3j:3j+3] at the dofs of node nodes[r, j]."""
    m, k = nodes.shape
    cols = (3 * nodes[:, :, None] + np.arange(3)).reshape(m, 3 * k)
    return sp.csr_matrix((blocks.ravel(), (np.repeat(np.arange(m), 3 * k), cols.ravel())), shape=(m, 3 * n))


def traction_forces(points, tris, traction) -> np.ndarray:
    """(n, 3) P1-consistent nodal forces of a traction linear over each triangle:
    f_i = A/3 (t_c + (t_i - t_c)/4), t_i its value at vertex i, t_c their mean."""
    x = points[tris]
    area = np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1) / 2
    t = np.moveaxis(traction(np.moveaxis(x, 2, 0)), 0, 2)           # (m, 3 vertices, 3)
    tc = t.mean(axis=1, keepdims=True)
    f = np.zeros(points.shape)
    np.add.at(f, tris.ravel(), ((area / 3)[:, None, None] * (tc + (t - tc) / 4)).reshape(-1, 3))
    return f


def model_solve(K, held: np.ndarray, f: np.ndarray) -> np.ndarray:
    """u (n, 3) of K u = f with the nodes ``held`` (indices) fixed."""
    n = len(f)
    fixed = np.zeros((n, 3), bool)
    fixed[held] = True
    free = np.flatnonzero(~fixed.ravel())
    u = np.zeros(3 * n)
    u[free] = spla.spsolve(sp.csc_matrix(K[free][:, free]), f.ravel()[free])
    return u.reshape(n, 3)


def model_answers(data: dict, points, groups, loads, scale: dict) -> dict:
    """{load: u (n, 3) at the mesh's vertices} of an exported model under the study's
    loads (each times scale[load]); its particles are matched to the vertices."""
    from scipy.spatial import cKDTree
    q = np.asarray(data["particle_q"], float)
    dist, order = cKDTree(q).query(points)
    if len(q) != len(points) or len(np.unique(order)) != len(q) or np.max(dist) > 1e-9 * np.ptp(points, 0).max():
        raise ValueError("the model's particles are not the mesh's vertices")
    K = network_stiffness(data)
    m = np.asarray(data["particle_mass"], float)
    out = {}
    for load in loads:
        if load.traction is not None:
            f = traction_forces(points, groups["load"], load.traction)
        else:
            f = m[order][:, None] * np.asarray(load.gravity, float)[None]
        held = order[np.unique(np.concatenate([groups[g].ravel() for g in load.held]))]
        f_model = np.zeros_like(f)
        f_model[order] = f
        out[load.name] = scale[load.name] * model_solve(K, held, f_model)[order]
    return out


# -- the study -----------------------------------------------------------------------------

def calibrate(mesh: Path, out: Path, nu: float, cache: Path, *extra: str, budget: float = BUDGET):
    """(the JSON export, its choice (the JSON's, else stiffness-optimizer of the CSV's exported
    row), that row's rule, wall seconds) of one ``springbench calibrate`` in its own process
    with the reference cache ``cache``."""
    cmd = [sys.executable, "-m", "harness", "calibrate", str(mesh), "--E", repr(E), "--nu", repr(nu),
           "--density", repr(RHO), "--max-refine", "1", "--budget", repr(budget), "--out", str(out), *extra]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, SPRINGBENCH_CACHE=str(cache)))
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[3:])}: {(proc.stderr.strip().splitlines() or ['failed'])[-1]}")
    data = json.loads(out.with_suffix(".json").read_text())
    row = pd.read_csv(out.with_suffix(".csv")).query("exported").iloc[0]
    choice = data.get("choice") or (row.stiffness if row.get("optimizer", "none") == "none" else
                                    f"{row.stiffness}-{row.optimizer}")
    return data, str(choice), str(row.stiffness), seconds


def geomean(x) -> float:
    return float(np.exp(np.mean(np.log(np.asarray(x, float)))))


def study_one(body: Body, mesh: Path, nu: float, folder: Path, rules=RULES, budget: float = BUDGET) -> list[dict]:
    """The rows of one (body, nu): every model under every study load, and their geomeans."""
    points, tets, groups = read_body(mesh)
    loads = study_loads(body, points, groups)
    t0 = time.perf_counter()
    fem = truth(points, tets, groups, loads, nu)
    truth_seconds = time.perf_counter() - t0
    scale = {name: PEAK_STRAIN / peak for name, (_, peak) in fem.items()}
    cache = folder / f"cache-{body.name}-{nu:g}"                   # empty: the calibrate run is cold
    runs = [("calibrate", ())] + [(r, ("--method", "rule", "--rule", r)) for r in rules]
    rows = []
    for model, extra in runs:
        row = dict(body=body.name, n_tets=len(tets), nu=nu, model=model, choice=None, rule=None, seconds=math.nan,
                   truth_seconds=truth_seconds, note="")
        try:
            data, row["choice"], row["rule"], row["seconds"] = calibrate(
                mesh, folder / f"{body.name}-{nu:g}-{model}.vtu", nu, cache, *extra, budget=budget)
            u = model_answers(data, points, groups, loads, scale)
        except (RuntimeError, ValueError) as exc:      # a failed run: its rows say why, the study goes on
            u, row["note"] = None, str(exc)
        for load in loads:
            ut = scale[load.name] * fem[load.name][0]
            err = math.nan if u is None else float(np.linalg.norm(u[load.name] - ut) / np.linalg.norm(ut))
            rows.append(dict(row, load=load.name, err=err))
    return rows


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """The per-load rows plus a geomean row per (body, nu, model) with its ratio to the best
    rule of that (body, nu), and an overall row (body 'all')."""
    out = []
    for (body, nu), g in df.groupby(["body", "nu"], sort=False):
        gm = g.groupby("model", sort=False)["err"].apply(geomean)
        rules = gm.drop("calibrate", errors="ignore")
        best = rules.idxmin() if rules.notna().any() else None
        per_load = g[g.model == best].set_index("load").err
        g = g.assign(best_rule=best, ratio_to_best_rule=g.err.values / g.load.map(per_load).values)
        first = g.groupby("model", sort=False).first()
        summary = first[["n_tets", "choice", "rule", "seconds", "truth_seconds", "note"]].reset_index().assign(
            body=body, nu=nu, load="geomean", err=gm.values, best_rule=best,
            ratio_to_best_rule=gm.values / (rules[best] if best else math.nan))
        out += [g, summary]
    df = pd.concat(out, ignore_index=True)
    mine = df[(df.load == "geomean") & (df.model == "calibrate")]
    if len(mine):
        df = pd.concat([df, pd.DataFrame([dict(body="all", model="calibrate", load="geomean",
                                               ratio_to_best_rule=geomean(mine.ratio_to_best_rule),
                                               seconds=float(mine.seconds.sum()))])], ignore_index=True)
    return df.astype({"n_tets": "Int64"})[COLUMNS]


def summary_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per (body, nu): calibrate's geomean err and choice, the best rule's, the ratio."""
    g = df[(df.load == "geomean") & (df.body != "all")]
    mine = g[g.model == "calibrate"].set_index(["body", "nu"])
    best = g[g.model == g.best_rule].set_index(["body", "nu"])
    return pd.DataFrame(dict(calibrate=mine.err, choice=mine.choice, rule=mine.rule, best_rule=best.model,
                             best_rule_err=best.err, ratio=mine.ratio_to_best_rule, seconds=mine.seconds)).reset_index()


def verdict(df: pd.DataFrame) -> str:
    mine = df[(df.load == "geomean") & (df.model == "calibrate") & (df.body != "all")]
    overall = float(df[df.body == "all"].ratio_to_best_rule.iloc[0])
    worst = mine.loc[mine.ratio_to_best_rule.idxmax()]
    ok = bool((mine.ratio_to_best_rule <= ACCEPT_EACH).all() and overall <= ACCEPT_ALL)
    return (f"{'PASS' if ok else 'FAIL'}: calibrate / best rule in hindsight = {overall:.3g} overall (accept "
            f"<= {ACCEPT_ALL:g}), worst {worst.ratio_to_best_rule:.3g} on {worst.body} nu={worst.nu:g} "
            f"(accept <= {ACCEPT_EACH:g} each); {len(mine)} (body, nu)")


def run(quick: bool = False) -> pd.DataFrame:
    try:
        import gmsh  # noqa: F401
    except ImportError:
        return pd.DataFrame([dict(body="all", note="skipped: gmsh not installed (pip install 'springbench[bench]')")])
    bodies, nus, n_tets = (BODIES[:1], NUS[:1], QUICK_TETS) if quick else (BODIES, NUS, FULL_TETS)
    rows = []
    with tempfile.TemporaryDirectory(prefix="springbench-heldout-") as tmp:
        tmp = Path(tmp)
        for body in steps(bodies, "bench heldout", "body"):
            mesh = tmp / f"{body.name}.msh"
            make_body(body, mesh, n_tets)
            for nu in nus:
                rows += study_one(body, mesh, nu, tmp)
    df = summarise(pd.DataFrame(rows))
    print(summary_table(df).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(verdict(df))
    return df
