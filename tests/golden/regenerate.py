"""Rewrite the expected outputs of the golden tests from what sppl produces now.

    python tests/golden/regenerate.py

- ``good/NAME.scn``: a model that compiles; ``good/NAME.fmt.scn`` is its canonical form
  (``sppl fmt``).
- ``bad/NAME.scn``: a model with mistakes; ``bad/NAME.err`` is the exact text of its errors,
  with paths relative to the repository root.

Files under ``lib/`` are helpers that cases import or load, not cases. Review the diff
(``git diff tests/golden``) before committing: these files are the specification.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = Path(__file__).resolve().parent


def cases(kind: str) -> list[Path]:
    """The input files of one kind, relative to the repository root."""
    return sorted(
        p.relative_to(ROOT)
        for p in (GOLDEN / kind).glob("*.scn")
        if not p.name.endswith(".fmt.scn")
    )


def expected_error(path: Path) -> str:
    """The text ``sppl`` prints for a bad file (without the ``error: `` prefix)."""
    from sppl.errors import ModelError
    from sppl.lang import load_model

    try:
        load_model(path)
    except ModelError as error:
        return str(error) + "\n"
    raise AssertionError(f"{path} compiles, but is a bad case")


def expected_format(path: Path) -> str:
    from sppl.lang.pretty import format_source

    return format_source(path.read_text(encoding="utf-8"), str(path))


def main() -> int:
    os.chdir(ROOT)  # the paths in messages are relative to the repository root
    for path in cases("good"):
        path.with_suffix(".fmt.scn").write_text(expected_format(path), encoding="utf-8")
    for path in cases("bad"):
        path.with_suffix(".err").write_text(expected_error(path), encoding="utf-8")
    print(f"wrote {len(cases('good'))} canonical forms and {len(cases('bad'))} error files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
