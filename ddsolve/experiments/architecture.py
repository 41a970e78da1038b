"""The package's stages and the imports between them, read from the source (``ddsolve architecture``
draws docs/architecture.png; tests/test_architecture.py checks the rules on the same graph)."""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]
#: The stages from the bottom up: a module may import from its own stage and the stages before it.
STAGES = ("errors", "environment", "problem", "mesh", "fem", "dd", "post", "io", "parallel", "solve", "api", "cli",
          "experiments")
#: The one import against the stages' direction, deferred into a method: ``Result.save`` writes the
#: result through the io stage, as meshio's ``Mesh.write`` does; io imports nothing at load time that
#: would need it, so the cycle exists only in a call.
DEFERRED = {("ddsolve.post.result", "ddsolve.io.hdf5")}
#: Stages that never import PETSc or MPI (testable without them).
SERIAL = ("problem", "mesh", "fem", "dd", "post", "io")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    """Every importable module of the package (a file with a hyphen is package data)."""
    return {module_name(path): path for path in PACKAGE.rglob("*.py") if "-" not in path.name}


def imports(path: Path) -> set[str]:
    """Absolute names of every module (or module attribute) ``path`` imports, at any depth."""
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
            found.add(base)
            found |= {f"{base}.{alias.name}" for alias in node.names}
    return found


def import_graph(deferred: bool = False) -> dict[str, set[str]]:
    """ddsolve module -> the ddsolve modules it imports (``deferred``: with the allowed deferred one)."""
    known = modules()
    edges = {}
    for name, path in known.items():
        targets = set()
        for imported in imports(path):
            while imported and imported not in known:
                imported = imported.rpartition(".")[0]
            if imported and imported not in (name, "ddsolve") and (deferred or (name, imported) not in DEFERRED):
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
    for module, targets in import_graph(deferred=True).items():
        for target in targets:
            key = (stage(module), stage(target))
            if key[0] != key[1]:
                counts[key] = counts.get(key, 0) + 1
    return counts


def architecture() -> None:
    """Draw docs/architecture.png: the stages bottom-up, an arrow per stage that imports another."""
    from ..post.plots import _pyplot

    plt = _pyplot()
    counts = stage_graph()
    sizes = {name: 0 for name in STAGES}
    for module, path in modules().items():
        sizes[stage(module)] += sum(1 for _ in path.open(encoding="utf-8"))
    fig, ax = plt.subplots(figsize=(11, 9))
    rows = {name: i for i, name in enumerate(STAGES)}
    x = {name: (0.0 if name not in ("errors", "environment") else (-0.9 if name == "errors" else 0.9)) for name in STAGES}
    y = {name: rows[name] - (1 if name == "environment" else 0) for name in STAGES}
    for (source, target), count in sorted(counts.items()):
        against = STAGES.index(target) > STAGES.index(source)
        ax.annotate("", xy=(x[target], y[target]), xytext=(x[source], y[source]),
                    arrowprops=dict(arrowstyle="->", color="crimson" if against else "0.55", lw=0.6 + 0.15 * count ** 0.5,
                                    connectionstyle=f"arc3,rad={0.35 if (rows[source] - rows[target]) % 2 else -0.35}",
                                    shrinkA=14, shrinkB=14, linestyle="--" if against else "-"))
    for name in STAGES:
        serial = name in SERIAL
        ax.text(x[name], y[name], f"{name}\n{sizes[name]} lines", ha="center", va="center", fontsize=10, zorder=3,
                bbox=dict(boxstyle="round,pad=0.4", fc="#dbe9f6" if serial else "#fde2c8", ec="0.3"))
    ax.set_xlim(-2.2, 2.2)
    ax.set_ylim(-1.6, len(STAGES) - 1.2)
    ax.axis("off")
    deferred = ", ".join(f"{a.split('.')[-1]} → {b.split('.')[-1]}" for a, b in sorted(DEFERRED))
    ax.set_title("ddsolve's stages, bottom up (blue: no PETSc or MPI); an arrow per stage imported,\n"
                 f"width ∝ √(module imports); dashed red: the one deferred import against the direction ({deferred})",
                 fontsize=10)
    out = Path("docs") / "architecture.png"
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    print(f"wrote {out}: {len(counts)} arrows between {len(STAGES)} stages")
