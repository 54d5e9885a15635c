"""One error type for bad input: a single line naming where, what, and the fix."""

from __future__ import annotations

from contextlib import contextmanager


class SpringbenchError(Exception):
    """Bad input. ``str(err)`` is one line: ``file: field: problem (fix)``.

    The CLI prints it and exits with status 2; nothing else in the code base
    should turn user mistakes into tracebacks.
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | None = None,
        field: str | None = None,
        fix: str | None = None,
    ):
        self.message, self.file, self.field, self.fix = message, file, field, fix
        super().__init__(str(self))

    def __str__(self) -> str:
        parts = [p for p in (self.file, self.field) if p]
        text = ": ".join(parts + [self.message])
        if self.fix:
            text += f" ({self.fix})"
        return text.replace("\n", " ")


class CaseError(SpringbenchError):
    """A case file does not match the schema."""


class ModelError(SpringbenchError):
    """A model cannot be built or solved (mechanism, floating node, bad mesh)."""


class SimulationError(SpringbenchError):
    """A time integration failed (unstable step, NaN)."""


class CaseErrors(CaseError):
    """Several mistakes found in one pass: ``errors`` holds one error each; ``str`` is the
    first and how many more (``springbench validate`` and the CLI print one line each)."""

    def __init__(self, errors):
        self.errors = [e for err in errors for e in getattr(err, "errors", [err])]
        first = self.errors[0]
        super().__init__(first.message, file=first.file, field=first.field, fix=first.fix)

    def __reduce__(self):  # picklable (worker processes)
        return CaseErrors, (self.errors,)

    def __str__(self) -> str:
        more = len(self.errors) - 1
        return super().__str__() + (
            f" [and {more} more mistake{'s' if more > 1 else ''}: springbench validate lists each]"
        )


def raise_all(errors) -> None:
    """Raise the collected errors, if any: one as itself, several as CaseErrors."""
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise CaseErrors(errors)


def error_lines(exc: SpringbenchError) -> list[str]:
    """One line per mistake of ``exc``."""
    return [SpringbenchError.__str__(e) for e in getattr(exc, "errors", [exc])]


@contextmanager
def naming(case):
    """Within it, a ModelError that names no file gets the case's file (``case.path``):
    the user's file, never an internal one."""
    try:
        yield
    except ModelError as exc:
        if exc.file is None and getattr(case, "path", None) is not None:
            exc.file = str(case.path)
            exc.args = (str(exc),)
        raise
