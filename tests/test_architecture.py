"""The package follows the data flow: each subpackage imports only those below it
(docs/architecture.md), and no module imports another that imports it back."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "sppl"

# What each part of sppl may import, besides itself. The order is the data flow: a model file
# becomes a model (lang, model), hypotheses are drawn and scored against the cameras'
# observations (data, render, scoring), the sampler moves among them (infer), runs drive
# samplers and keep what they drew (runs, output), and the checks test the sampler (verify).
ALLOWED = {
    "errors": set(),
    "_version": set(),
    "data": {"errors"},
    "model": {"errors", "data"},
    "lang": {"errors", "model"},
    "render": {"errors", "data", "model"},
    "scoring": {"errors", "data", "model", "render"},
    "infer": {"errors", "data", "model", "render", "scoring"},
    "output": {"errors", "_version", "data", "model", "lang", "render", "scoring"},
    "runs": {"errors", "_version", "data", "model", "lang", "render", "scoring", "infer",
             "output"},
    "verify": {"errors", "data", "model", "lang", "render", "scoring", "infer"},
    "cli": {"errors", "_version", "data", "model", "lang", "render", "scoring", "infer",
            "output", "runs", "verify"},
    "__main__": {"cli"},
    "__init__": {"errors", "_version", "data", "model", "lang", "render", "scoring", "infer",
                 "output", "runs", "verify"},
}


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """The sppl modules ``path`` imports, at its top or inside a function."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    tree = ast.parse(path.read_text())
    # Imports for type annotations only are never run.
    typing_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If)
                   and getattr(block.test, "id", None) == "TYPE_CHECKING"
                   for stmt in block.body for n in ast.walk(stmt)}
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("sppl"):
                continue
            # `from package import module` imports the module.
            for alias in node.names:
                if (PACKAGE.parent / (target + "." + alias.name).replace(".", "/")).with_suffix(
                        ".py").exists():
                    found.add(target + "." + alias.name)
                else:
                    found.add(target)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("sppl")}
    return found - {name}


def graph() -> dict[str, set[str]]:
    return {module_name(p): imports(p) for p in PACKAGE.rglob("*.py")}


def part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_part_of_sppl_is_placed():
    assert {part(m) for m in graph()} <= set(ALLOWED)


def test_imports_follow_the_data_flow():
    wrong = sorted(f"{m} imports {t}" for m, targets in graph().items() for t in targets
                   if part(t) != part(m) and part(t) not in ALLOWED[part(m)])
    assert not wrong, "\n".join(wrong)


def test_no_module_imports_one_that_imports_it_back():
    g = graph()
    # A package's __init__ re-exports its modules; only module-to-module imports can cycle.
    edges = {m: {t for t in ts if t in g and not g.get(t) is None} for m, ts in g.items()}
    cycles = []
    state: dict[str, int] = {}

    def visit(m, path):
        state[m] = 1
        for t in sorted(edges[m]):
            if state.get(t) == 1:
                cycles.append(" -> ".join(path[path.index(t):] + [t]))
            elif t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [m])
    assert not cycles, "\n".join(cycles)


def test_examples_use_only_the_public_api():
    """The examples are written as a user would: ``sppl``'s exports, and the command line."""
    wrong = []
    for path in sorted((PACKAGE.parent / "examples").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([node.module] if isinstance(node, ast.ImportFrom) and node.module
                     else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            wrong += [f"{path.relative_to(PACKAGE.parent)}: {n}" for n in names
                      if n.startswith("sppl.") and n != "sppl.cli"]
    assert not wrong, "\n".join(wrong)
