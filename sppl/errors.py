"""sppl's error types.

Every error a user can cause (a bad model file, a bad observation folder, a bad option) is an
``SpplError``. The command line prints ``str(error)`` and exits 1; nothing else reaches the user
as a traceback unless ``--debug`` is given.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Span:
    """A position in a source file: 1-based line and column, as editors show them."""

    line: int
    column: int
    end_line: int | None = None
    end_column: int | None = None


class SpplError(Exception):
    """An error caused by the user's input, reported as one clear message.

    ``path`` and ``span`` locate it where there is a location; ``source`` is the text of the
    file, so that the offending line can be shown with a caret under the column.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        span: Span | None = None,
        source: str | None = None,
        hint: str | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.path = None if path is None else str(path)
        self.span = span
        self.source = source
        self.hint = hint

    def location(self) -> str:
        if self.path is None:
            return ""
        if self.span is None:
            return f"{self.path}: "
        return f"{self.path}:{self.span.line}:{self.span.column}: "

    def __str__(self) -> str:
        head = f"{self.location()}{self.message}"
        if self.hint:
            head += f" ({self.hint})"
        excerpt = self.excerpt()
        return head if not excerpt else f"{head}\n{excerpt}"

    def excerpt(self) -> str:
        """The offending source line with a caret under the error's column, or ''."""
        if self.source is None or self.span is None:
            return ""
        lines = self.source.splitlines()
        if not 1 <= self.span.line <= len(lines):
            return ""
        text = lines[self.span.line - 1].expandtabs(1)
        gutter = f"{self.span.line:4d} | "
        caret = " " * (len(gutter) - 2) + "| " + " " * (self.span.column - 1) + "^"
        return f"{gutter}{text}\n{caret}"


class ModelError(SpplError):
    """A syntax or semantic error in a ``.scn`` model file."""


class ModelErrors(ModelError):
    """Several errors found in one model file, reported together, sorted by position."""

    def __init__(self, errors: list[ModelError]) -> None:
        # Sorted by position within each file, the files in the order they first appear (a
        # model's own errors first, then those of a file it imports).
        files: dict[str | None, int] = {}
        for e in errors:
            files.setdefault(e.path, len(files))
        errors = sorted(
            errors,
            key=lambda e: (files[e.path], (e.span.line, e.span.column) if e.span else (0, 0)),
        )
        first = errors[0]
        super().__init__(
            first.message, path=first.path, span=first.span, source=first.source, hint=first.hint
        )
        self.errors = errors

    def __str__(self) -> str:
        return "\n".join(SpplError.__str__(e) for e in self.errors)


class ObservationError(SpplError):
    """An observation folder, camera file or image that cannot be used as it is."""


class RenderError(SpplError):
    """No rendering context could be made, or the renderer was used wrongly."""


class UsageError(SpplError):
    """A command-line option or output folder that cannot be used."""


class RunError(SpplError):
    """A run folder that cannot be resumed: no checkpoint, a damaged one, or changed inputs."""
