"""calibrate ``--engine``: the export restricted to the terms an engine runs natively
(harness/registry.py EXPORT_TERMS), so the model written is the model that engine runs. The
validated fit chooses only among the candidates whose volume term the engine runs; a
``--model`` with a term it cannot run is refused before any work."""

from __future__ import annotations

from harness import registry
from harness.errors import SpringbenchError


def check(s) -> None:
    """A one-line refusal of a ``--model`` whose term ``--engine`` cannot run (none without
    --engine)."""
    if s.engine is None:
        return
    runs = registry.EXPORT_TERMS[s.engine]
    if s.model not in registry.CLASS_TERMS:  # a fitted material (p1-global, p1): no springs
        own = [e for e in registry.ENGINES if e not in registry.EXPORT_ENGINES]
        keys = "E_effective and nu_effective" if s.model == "p1-global" else "tet_E and tet_nu"
        raise SpringbenchError(
            f"{s.engine} runs a springs export; --model {s.model} exports a material "
            f"({keys}) for an engine's own elements",
            field="--engine",
            fix=f"drop --engine; give the JSON's {keys} to {', '.join(own)}",
        )
    term = registry.CLASS_TERMS[s.model]
    if term in runs:
        return
    models = [m for m, t in registry.CLASS_TERMS.items() if t in runs]
    others = [e for e, terms in registry.EXPORT_TERMS.items() if term in terms]
    elsewhere = (
        f"--engine {' or '.join(others)}" if others else "drop --engine (no engine here runs it)"
    )
    fix = f"--model {' or '.join(models)}, or {elsewhere}"
    raise SpringbenchError(
        f"{s.engine} cannot run --model {s.model} ({registry.TERMS[term]}: "
        f"{registry.EXPORT_TERMS_WHY[s.engine]})",
        field="--engine",
        fix=fix,
    )


def candidates(engine: str) -> list[str]:
    """The validated fit's default candidates (harness/case/sections.py SELECT_DEFAULT)
    whose volume term ``engine`` runs natively, in their order."""
    from harness.case.sections import SELECT_DEFAULT
    from harness.optimize.select import CANDIDATES

    volume = {c.name: c.volume for c in CANDIDATES}
    return [n for n in SELECT_DEFAULT if volume[n] in registry.EXPORT_TERMS[engine]]


def engine_line(s, validated: bool) -> str | None:
    """What --engine restricted, printed first (None without --engine): the candidates'
    terms and names for a validated fit, else the --model it runs."""
    if s.engine is None:
        return None
    runs = registry.EXPORT_TERMS[s.engine]
    why = registry.EXPORT_TERMS_WHY[s.engine]
    if not validated:
        return f"--engine {s.engine}: --model {s.model}, which it runs natively ({why})"
    if runs == ("",):
        what = "candidates without a volume term"
    else:
        words = [registry.TERMS[t] for t in runs]
        what = f"candidates with {', '.join(words[:-1])} or {words[-1]}"
    return f"--engine {s.engine}: {what} ({why}): {', '.join(candidates(s.engine))}"
