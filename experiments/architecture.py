"""The package's stages and the imports between them, read from the source (``ddsolve architecture``
draws docs/architecture.png; tests/test_architecture.py checks the rules on the same graph)."""
from __future__ import annotations

import ast
from pathlib import Path

from experiments import ROOT

PACKAGE = ROOT / "ddsolve"
#: The stages from the bottom up: a module may import from its own stage and the stages before it.
#: (The experiments, beside the package in experiments/, come after them all: nothing in it imports them.)
STAGES = ("errors", "environment", "problem", "mesh", "fem", "dd", "post", "io", "parallel", "solvers", "api", "cli")
#: The stages that may import PETSc or MPI (petsc4py, mpi4py).
PETSC = ("parallel", "solvers", "api", "cli")
#: Stages that never import PETSc or MPI (testable without them).
SERIAL = tuple(name for name in STAGES if name not in PETSC)


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    """Every importable module of the package (a file with a hyphen is package data)."""
    return {module_name(path): path for path in PACKAGE.rglob("*.py") if "-" not in path.name}


def imports(path: Path) -> set[str]:
    """Absolute names of every module (or module attribute) ``path`` imports, at any depth.  ``from package
    import module`` names the module, not the package whose ``__init__`` Python runs on the way (every
    submodule's import does that)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module_name(path) if path.name == "__init__.py" else module_name(path).rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([node.module] if node.module else []))
            found |= {base if alias.name == "*" else f"{base}.{alias.name}" for alias in node.names}
    return found


def import_graph() -> dict[str, set[str]]:
    """ddsolve module -> the ddsolve modules it imports (at module level or deferred into a function)."""
    known = modules()
    edges = {}
    for name, path in known.items():
        targets = set()
        for imported in imports(path):
            while imported and imported not in known:
                imported = imported.rpartition(".")[0]
            if imported and imported not in (name, "ddsolve"):
                targets.add(imported)
        edges[name] = targets
    return edges


def stage(module: str) -> str:
    """The stage of a module: its subpackage, or errors, environment, cli (and ``__main__``), api."""
    parts = module.split(".")
    if len(parts) == 1 or parts[1] == "api":
        return "api"
    return "cli" if parts[1] == "__main__" else parts[1]


def stage_graph() -> dict[tuple[str, str], int]:
    """(stage, stage it imports) -> how many module imports make that arrow."""
    counts: dict[tuple[str, str], int] = {}
    for module, targets in import_graph().items():
        for target in targets:
            key = (stage(module), stage(target))
            if key[0] != key[1]:
                counts[key] = counts.get(key, 0) + 1
    return counts


def architecture() -> None:
    """Draw docs/architecture.png: which stage imports which, as a matrix of module-import counts.  The
    stages run top-down in both directions, so every import that points the right way lies above the
    diagonal; one below it would point against the layering."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    counts = stage_graph()
    lines = {name: 0 for name in STAGES}
    files = {name: 0 for name in STAGES}
    for module, path in modules().items():
        lines[stage(module)] += sum(1 for _ in path.open(encoding="utf-8"))
        files[stage(module)] += 1
    order = STAGES[::-1]  # the top stage first
    n = len(order)
    fig, ax = plt.subplots(figsize=(10.5, 8.5))
    ax.imshow([[0] * n] * n, cmap="Greys", vmin=0, vmax=1)
    for i, source in enumerate(order):
        for j, target in enumerate(order):
            if (source, target) in counts:
                against = STAGES.index(target) > STAGES.index(source)
                ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, color="#e8a0a0" if against else "#9ec5e8"))
                ax.text(j, i, str(counts[source, target]), ha="center", va="center", fontsize=9)
            elif i == j:
                ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, color="0.85"))
    labels = [f"{name} ({files[name]} module{'s' if files[name] > 1 else ''}, {lines[name]} lines)" + (" *" if name in SERIAL else "")
              for name in order]
    ax.set_yticks(range(n), labels, fontsize=9)
    ax.set_xticks(range(n), order, rotation=45, ha="right", fontsize=9)
    ax.set_xlim(-0.5, n - 0.5)
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_xlabel("is imported by the stage on the left (number of module imports)")
    ax.set_title("ddsolve's stages: who imports whom (every import, deferred ones too)\n"
                 "blue: down the layers; red: against them; * a stage without PETSc or MPI", fontsize=10)
    out = Path("docs") / "architecture.png"
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    print(f"wrote {out}: {len(counts)} stage pairs, {sum(counts.values())} module imports between stages")
