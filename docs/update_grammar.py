"""Copy the grammar, ``sppl/lang/scn.lark``, into the Grammar section of docs/language.md.

    python docs/update_grammar.py          # rewrite docs/language.md if its copy is stale
    python docs/update_grammar.py --check  # exit 1 if it is stale, changing nothing

The section is the one fenced ``lark`` block of the page; everything around it is left as it
is. ``tests/test_language_docs.py`` fails when the copy differs from the file.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "language.md"
GRAMMAR = ROOT / "sppl" / "lang" / "scn.lark"
OPEN, CLOSE = "```lark\n", "\n```\n"


def with_grammar(doc: str, grammar: str) -> str:
    """``doc`` with the body of its one ```lark block replaced by ``grammar``."""
    if doc.count(OPEN) != 1:
        raise ValueError(f"{DOC.name} must have exactly one ```lark block, "
                         f"found {doc.count(OPEN)}")
    start = doc.index(OPEN) + len(OPEN)
    end = doc.index(CLOSE, start - 1)
    return doc[:start] + grammar.rstrip("\n") + doc[end:]


def main(argv: list[str]) -> int:
    doc = DOC.read_text(encoding="utf-8")
    new = with_grammar(doc, GRAMMAR.read_text(encoding="utf-8"))
    if new == doc:
        return 0
    if "--check" in argv:
        print(f"{DOC.relative_to(ROOT)}: the grammar is stale; run python docs/update_grammar.py",
              file=sys.stderr)
        return 1
    DOC.write_text(new, encoding="utf-8")
    print(f"updated the grammar in {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
