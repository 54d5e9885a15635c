"""The columns every row of the sms stage shares, built by typed helpers: a fitted row's
(:class:`FitColumns`) and a stiffness rule's (:class:`RuleColumns`).

Each field is a column documented in harness/report/columns.py under its own name
(tests/stages/test_row_columns.py checks it), so a stage names no shared column itself: it
fills the fields and adds only its own columns. The fields are in the order a row holds
them; ``None`` leaves a column out (a row without it)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields


@dataclass(frozen=True, kw_only=True)
class FitColumns:
    """One fitted row's shared columns: its model and start rule, the fit, the wall time
    (``seconds``; a validated fit's split of it), G on the fitted loads at the start and
    after the fit, what the optimiser reported, the objective, the budget and the number of
    fitted constants."""

    model: str
    stiffness: str
    optimizer: str
    grouped: bool | None = None
    seconds: float
    seconds_validation: float | None = None
    seconds_final: float | None = None
    G_initial: float
    G_norm_initial: float
    G_s_initial: float
    G_final: float
    G_norm_final: float
    G_s_final: float
    G_final_optimizer: float | None = None
    G_initial_optimizer: float | None = None
    objective: str
    budget: str | None = None
    n_params: int

    @classmethod
    def of(cls, label: str, stiffness: str, optimizer: str, first: dict, sc, **fit) -> FitColumns:
        """The columns of a fit from rule ``stiffness`` of the model ``label``: G at the start
        from the rule's row ``first``, after the fit from its score ``sc``; ``fit``: the
        other fields (seconds, objective, n_params, ...)."""
        return cls(
            model=f"{label}[{stiffness}]",
            stiffness=stiffness,
            optimizer=optimizer,
            G_initial=first["G_initial"],
            G_norm_initial=first["G_norm_initial"],
            G_s_initial=first.get("G_s_initial", math.nan),
            G_final=sc.G,
            G_norm_final=sc.G_norm,
            G_s_final=sc.G_s,
            **fit,
        )

    def row(self, common: dict, scored: dict | None = None, chosen: dict | None = None) -> dict:
        """The row: ``common`` (the class's shared columns), then the fields in order, with
        ``scored`` (the score columns) just before ``objective`` and ``chosen`` (a choice's
        columns) just after it; a later key overrides an earlier one's value in place."""
        out = dict(common)
        for f in fields(self):
            if f.name == "objective":
                out.update(scored or {})
            value = getattr(self, f.name)
            if value is not None:
                out[f.name] = value
            if f.name == "objective":
                out.update(chosen or {})
        return out


FIT_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(FitColumns))


@dataclass(frozen=True, kw_only=True)
class RuleColumns:
    """One stiffness rule's shared columns: its model and rule (no fit: ``optimizer`` none),
    its build's and score's wall time (``seconds``), G of its network, at once the start's
    and the end's, and for a rule left unsolved under the clamps its G_fit_score's lower
    bound; ``note``: why a row has no G."""

    model: str
    stiffness: str
    optimizer: str = "none"
    seconds: float
    G_initial: float | None = None
    G_final: float | None = None
    G_norm_initial: float | None = None
    G_norm_final: float | None = None
    G_s_initial: float | None = None
    G_s_final: float | None = None
    G_fit_score_bound: float | None = None
    note: str | None = None

    @classmethod
    def scored(cls, label: str, rule: str, seconds: float, sc) -> RuleColumns:
        """Rule ``rule`` of the model ``label`` scored ``sc``: G, G_norm, G_s at the start and
        the end (a rule is not fitted)."""
        return cls(
            model=f"{label}[{rule}]",
            stiffness=rule,
            seconds=seconds,
            G_initial=sc.G,
            G_final=sc.G,
            G_norm_initial=sc.G_norm,
            G_norm_final=sc.G_norm,
            G_s_initial=sc.G_s,
            G_s_final=sc.G_s,
        )

    @classmethod
    def unscored(cls, label: str, rule: str, seconds: float, note: str) -> RuleColumns:
        """Rule ``rule`` without a reference to score it: G and G_norm NaN, ``note`` why."""
        nan = math.nan
        return cls(
            model=f"{label}[{rule}]",
            stiffness=rule,
            seconds=seconds,
            G_initial=nan,
            G_final=nan,
            G_norm_initial=nan,
            G_norm_final=nan,
            note=note,
        )

    @classmethod
    def unsolved(
        cls, label: str, rule: str, seconds: float, bound: float, note: str
    ) -> RuleColumns:
        """Rule ``rule`` left unsolved under the clamps: no G, its G_fit_score's lower
        ``bound`` and ``note`` why."""
        return cls(
            model=f"{label}[{rule}]",
            stiffness=rule,
            seconds=seconds,
            G_fit_score_bound=bound,
            note=note,
        )

    def row(self, common: dict, constants: dict | None = None, scored: dict | None = None) -> dict:
        """The row: ``common`` (the class's shared columns), then the fields in order, with
        ``constants`` (the network's own constants) just after ``seconds`` and ``scored``
        (the score columns) just after ``G_s_final``; a later key overrides an earlier
        one's value in place."""
        out = dict(common)
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                out[f.name] = value
            if f.name == "seconds":
                out.update(constants or {})
            if f.name == "G_s_final":
                out.update(scored or {})
        return out


RULE_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(RuleColumns))
