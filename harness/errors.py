"""One error type for bad input: a single line naming where, what, and the fix."""

from __future__ import annotations


class SpringbenchError(Exception):
    """Bad input. ``str(err)`` is one line: ``file: field: problem (fix)``.

    The CLI prints it and exits with status 2; nothing else in the code base
    should turn user mistakes into tracebacks.
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None,
                 fix: str | None = None):
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
