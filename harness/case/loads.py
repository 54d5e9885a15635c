"""The [loads] table of a case file: the standard set, the user's load cases, the
held-out names and, for a homogeneous set on a body that is not a box or a linear set on
any body, its anchor parts and frame.
Mistakes are CaseErrors naming the file and the field."""

from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from harness import registry
from harness.case.loadsets import (
    ANCHORS,
    AXES,
    Constraint,
    Frame,
    LoadCase,
    Traction,
    anchor_points,
)
from harness.case.moments import box_moments, mesh_moments, polygon_moments
from harness.case.parts import parse_face_name, part_exists
from harness.errors import CaseError, SpringbenchError
from harness.io.meshfile import boundary_facets, read_mesh

if TYPE_CHECKING:
    from harness.case.case import Body

# sets whose loads are held at anchor points (boxes: only linear)
ANCHORED = ("homogeneous", "linear")


def _components(names: tuple[str, ...], dim: int, file: str, where: str) -> tuple[int, ...]:
    if "all" in names:
        return tuple(range(dim))
    comps = sorted({AXES.index(c) for c in names})
    if comps and comps[-1] >= dim:
        raise CaseError(
            f"component '{AXES[comps[-1]]}' does not exist in {dim}-D",
            file=file,
            field=where,
            fix=f"use {', '.join(AXES[:dim])} or all",
        )
    return tuple(comps)


def _standard_set(l: dict, dim: int, body: Body, file: str) -> list[LoadCase]:
    """The load cases of [loads] set (none without one)."""
    if l["set"] is None:
        return []
    want, make = registry.LOAD_SETS.about[l["set"]], registry.LOAD_SETS.load(l["set"])
    if want != dim:
        raise CaseError(
            f"load set '{l['set']}' is {want}-D but dim = {dim}",
            file=file,
            field="loads.set",
            fix=f"use basic{dim}d",
        )
    anchors = None
    if anchored(l["set"], body) and ANCHORS[0] in body.parts:
        anchors = np.array([body.parts[a][0] for a in ANCHORS[:dim]])
    frame = body_frame(body) if l["set"].startswith("linear") else None
    return list(make(l["magnitude"], anchors, frame))


def _traction(t: dict, dim: int, body: Body, file: str, where: str) -> Traction:
    """One [[loads.case.traction]]: its part, and a vector or (3-D) a twist."""
    _check_part(t["part"], dim, body, file, f"{where}.part")
    if t["vector"] is None and t["twist"] is None:
        raise CaseError(
            "a traction needs a vector or a twist",
            file=file,
            field=where,
            fix=f"add vector = [{', '.join(['0.0'] * dim)}] (stress units) or twist = [wx, wy, wz]",
        )
    if t["vector"] is not None and len(t["vector"]) != dim:
        raise CaseError(f"expected {dim} entries", file=file, field=f"{where}.vector")
    if t["twist"] is not None and dim != 3:
        raise CaseError(
            "a twist (torsion) needs dim = 3",
            file=file,
            field=f"{where}.twist",
            fix="use vector in 2-D",
        )
    vector = tuple(t["vector"]) if t["vector"] is not None else (0.0,) * dim
    return Traction(t["part"], vector, None if t["twist"] is None else tuple(t["twist"]))


def _user_case(u: dict, dim: int, body: Body, file: str, where: str) -> LoadCase:
    """One [[loads.case]]: held parts, tractions, gravity or body force, not all zero."""
    cons = []
    for j, c in enumerate(u["constraint"]):
        _check_part(c["part"], dim, body, file, f"{where}.constraint[{j}].part")
        comps = _components(c["components"], dim, file, f"{where}.constraint[{j}].components")
        cons.append(Constraint(c["part"], comps))
    tracs = [
        _traction(t, dim, body, file, f"{where}.traction[{j}]") for j, t in enumerate(u["traction"])
    ]
    for key in ("gravity", "body_force"):
        if u[key] is not None and len(u[key]) != dim:
            raise CaseError(f"expected {dim} entries", file=file, field=f"{where}.{key}")
    if not cons:
        raise CaseError(
            "no constraint: the body can move freely",
            file=file,
            field=where + ".constraint",
            fix="add [[loads.case.constraint]] with a part",
        )
    given = tracs or any(u[key] is not None for key in ("gravity", "body_force"))
    # constraints alone: a modal case
    if (
        given
        and not any(any(t.vector) or any(t.twist or ()) for t in tracs)
        and not any(any(u[key] or ()) for key in ("gravity", "body_force"))
    ):
        raise CaseError(
            f"load '{u['name']}' is zero: nothing moves (G would be 0/0)",
            file=file,
            field=where,
            fix="give a non-zero traction vector, twist, gravity or body_force",
        )
    return LoadCase(u["name"], tuple(cons), tuple(tracs), u["gravity"], u["body_force"])


def parse_loads(l: dict, dim: int, body: Body, file: str):
    cases = _standard_set(l, dim, body, file)
    names = {c.name for c in cases}
    for i, u in enumerate(l["case"]):
        where = f"loads.case[{i}]"
        if u["name"] in names:
            raise CaseError(
                f"duplicate load case name '{u['name']}'",
                file=file,
                field=where + ".name",
                fix="give each load case its own name (the standard set uses stretch-x, "
                "shear-x, ...)",
            )
        names.add(u["name"])
        cases.append(_user_case(u, dim, body, file, where))
    return tuple(cases), l["set"]


def _known(l: dict, names, file: str, keys) -> None:
    """Every name [loads] ``keys`` list is a load case's."""
    for key in keys:
        for n in l[key] or ():
            if n not in names:
                raise CaseError(
                    f"no load case '{n}'",
                    file=file,
                    field=f"loads.{key}",
                    fix=f"one of {', '.join(names)}",
                )


def parse_validation(l: dict, loads, file: str) -> tuple[str, ...]:
    """The validation load names from [loads] validation: never fitted, never held out."""
    names = [c.name for c in loads]
    _known(l, names, file, ("validation",))
    val = set(l["validation"] or ())
    for key in ("fit", "heldout"):
        both = sorted(val & set(l[key] or ()))
        if both:
            raise CaseError(
                f"load case '{both[0]}' is in both validation and {key}",
                file=file,
                field="loads.validation",
                fix=f"a validation load is never fitted nor held out: drop it from {key}",
            )
    return tuple(n for n in names if n in val)


def parse_rank_by(l: dict, loads, file: str, fitted) -> tuple[str, ...]:
    """The [loads] rank_by names as listed: fitted load cases (harness/stages/sms_measures.py
    rank), a name listed n times counting n times in their mean."""
    _known(l, [c.name for c in loads], file, ("rank_by",))
    for n in l["rank_by"] or ():
        if n not in fitted:
            raise CaseError(
                f"load case '{n}' in rank_by is not fitted (held out or for validation)",
                file=file,
                field="loads.rank_by",
                fix="rank the rules by fitted load cases only: the held-out ones never choose",
            )
    return tuple(l["rank_by"] or ())


def parse_heldout(l: dict, loads, file: str, validation=()) -> tuple[str, ...]:
    """The held-out load names from [loads] fit / heldout (either one, or both covering
    every load case but the ``validation`` ones once)."""
    names = [c.name for c in loads if c.name not in set(validation)]
    _known(l, [c.name for c in loads], file, ("fit", "heldout"))
    fit, held = l["fit"], l["heldout"]
    if fit is not None and held is not None:
        both = sorted(set(fit) & set(held))
        rest = [n for n in names if n not in fit and n not in held]
        if both or rest:
            raise CaseError(
                f"load case '{(both or rest)[0]}' is {'in both' if both else 'in neither'} "
                "of fit and heldout",
                file=file,
                field="loads.heldout",
                fix="list every load case in exactly one of them",
            )
    held = (
        tuple(held)
        if held is not None
        else tuple(n for n in names if fit is not None and n not in fit)
    )
    if names and len(held) == len(names):
        raise CaseError(
            "every load case is held out: nothing to fit",
            file=file,
            field="loads.fit",
            fix="fit at least one load case",
        )
    return tuple(n for n in names if n in held)


def anchored(load_set: str | None, body: Body) -> bool:
    """Whether the set's loads are held at anchor points: a homogeneous set on a body
    that is not a box (a box gets face tractions and corner constraints), a linear set
    on any body."""
    name = load_set or ""
    boxed = body.shape in ("rectangle", "box")
    return any(name.startswith(a) for a in ANCHORED) and not (
        boxed and name.startswith("homogeneous")
    )


def body_frame(body: Body) -> Frame:
    """The body's volume (2-D: area) centroid and its largest bounding-box extent."""
    lo, hi = body.bbox()
    if body.shape in ("rectangle", "box"):
        m = box_moments(lo, hi)
    elif body.shape == "polygon":
        m = polygon_moments(np.asarray(body.vertices, float))
    else:
        mesh = read_mesh(body.file, body.format)
        m = mesh_moments(mesh.points, mesh.cells)
    dim = len(lo)
    return Frame(tuple(float(v) for v in m[1 : 1 + dim] / m[0]), float(np.max(hi - lo)))


def with_anchors(l: dict, body: Body, file: str) -> Body:
    """The body gets the parts anchor-a, -b, -c (points on its boundary,
    harness.case.loadsets.anchor_points; a box's corners) when its load set holds its
    loads there (:func:`anchored`)."""
    if not anchored(l["set"], body):
        return body
    if body.shape in ("rectangle", "box"):
        lo, hi = body.bbox()
        boundary = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(len(lo), -1).T
    elif body.shape == "polygon":
        boundary = np.asarray(body.vertices, float)
    else:
        try:
            m = read_mesh(body.file, body.format)
        except SpringbenchError as exc:
            raise CaseError(
                exc.message, file=str(body.file), field="body.file", fix=exc.fix
            ) from None
        boundary = m.points[
            np.unique(np.concatenate([f.ravel() for f in boundary_facets(m.cells)]))
        ]
    taken = [a for a in ANCHORS if a in body.parts]
    if taken:
        raise CaseError(
            f"part name '{taken[0]}' is reserved for the {l['set']} loads' constraints",
            file=file,
            field=f"body.parts.{taken[0]}",
            fix="rename that part",
        )
    if len(boundary) < 3:  # a closed surface has no boundary facets
        raise CaseError(
            "the body has no boundary to anchor its loads on",
            file=file,
            field="body",
            fix="give a volume mesh (tetrahedra or hexahedra; 2-D: triangles or quads)",
        )
    pts = anchor_points(boundary)
    parts = dict(body.parts, **{a: (tuple(p), tuple(p)) for a, p in zip(ANCHORS, pts)})
    return replace(body, parts=MappingProxyType(parts))


def _check_part(name: str, dim: int, body: Body, file: str, where: str):
    if not part_exists(name, dim, body.parts):
        user = ", ".join(body.parts) or "none defined"
        raise CaseError(
            f"boundary part '{name}' does not exist",
            file=file,
            field=where,
            fix=f"use a face name like x0, x1, x0y0 or a part from [body.parts] ({user})",
        )


def modal_load(case):
    """The load case whose constraints the natural frequencies are computed with: the
    first held-out, else the first fitted, load that clamps a face, a user part or a
    mesh group (all components), else the first load. Not a load held only at corner or
    anchor points (the basic sets' stretches, the homogeneous states): a continuum does
    not resist a point support, so its lowest frequencies under one fall with every
    refinement (cube_333 held by the stretch-x corners: 0.47, 0.27, 0.18 Hz; clamped:
    1.136, 1.125, 1.122 Hz)."""

    def clamps(load):
        for c in load.constraints:
            faces = parse_face_name(c.part, case.dim)  # None: a user part or a group
            if (
                len(set(c.components)) == case.dim
                and (faces is None or len(faces) == 1)
                and c.part not in ANCHORS
            ):
                return True
        return False

    held = [l for l in case.loads if l.name in set(case.heldout)]
    fitted = [l for l in case.loads if l.name not in set(case.heldout)]
    return next((l for l in held + fitted if clamps(l)), case.loads[0])
