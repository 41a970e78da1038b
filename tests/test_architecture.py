"""The package layout is the architecture: stages that point one way, no import cycles, PETSc and MPI
only in the parallel, solvers, api and cli stages, and docs/architecture.md's table listing every module
in its stage's row, the stages in the order the imports follow.  The graph is built from the source
(every import statement, at module level or inside a function), so a deferred import counts as much as
any other."""
from __future__ import annotations

import ast
import re
from pathlib import Path

from experiments import ROOT
from experiments.architecture import PACKAGE, SERIAL, STAGES, import_graph, imports, modules, stage


def test_the_graph_sees_every_module_and_the_known_imports():
    edges = import_graph()
    assert len(edges) == len(modules()) > 40
    assert "ddsolve.mesh.mesh" in edges["ddsolve.fem.assembly"]
    assert "ddsolve.dd.constraints" in edges["ddsolve.dd.final_check"]


def test_imports_deferred_into_functions_are_in_the_graph():
    edges = import_graph()
    assert "ddsolve.io.hdf5" in edges["ddsolve.io"]  # io.save's import, inside the function
    assert "ddsolve.solvers.run" in edges["ddsolve.api"]
    assert "ddsolve.io" not in edges["ddsolve.io.hdf5"], "from ddsolve.io import viewer names the module alone"


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle a depth-first search closes (empty for an acyclic graph)."""
    state: dict[str, int] = {}
    found = []

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for target in sorted(edges.get(node, ())):
            if state.get(target) == 1:
                found.append(trail[trail.index(target):] + [target])
            elif target not in state:
                visit(target, trail + [target])
        state[node] = 2

    for node in sorted(edges):
        if node not in state:
            visit(node, [node])
    return found


def test_the_cycle_search_finds_cycles():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]
    assert cycles({"a": {"b", "c"}, "b": {"c"}, "c": set()}) == []


def test_no_import_cycle():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" -> ".join(cycle) for cycle in found)


def test_every_module_is_in_a_known_stage():
    unknown = sorted(f"{module}: stage {stage(module)!r}" for module in modules() if stage(module) not in STAGES)
    assert not unknown, "new stages go into experiments.architecture.STAGES and docs/architecture.md's table:\n" + \
        "\n".join(unknown)


def test_stages_point_one_way():
    wrong = [f"{module} ({stage(module)}) imports {target} ({stage(target)})"
             for module, targets in import_graph().items() for target in targets
             if STAGES.index(stage(target)) > STAGES.index(stage(module))]
    assert not wrong, "\n".join(wrong)


def test_petsc_and_mpi_only_in_the_parallel_solvers_api_and_cli_stages():
    offenders = [f"{name} imports {imported}" for name, path in modules().items() if stage(name) in SERIAL
                 for imported in imports(path) if imported.split(".")[0] in ("petsc4py", "mpi4py")]
    assert not offenders, "\n".join(offenders)


#: docs/architecture.md, whose table has one row per stage listing the stage's modules.
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def table_rows(text: str) -> list[tuple[list[str], str]]:
    """The table's rows as (the stages of the first cell, the whole row), in the page's order; a row whose
    first cell names no stage of the package (the experiments') is left out."""
    rows = []
    for line in text.splitlines():
        cells = line.split("|")
        if line.startswith("|") and len(cells) > 2:
            named = [name for name in re.findall(r"`([^`]+)`", cells[1]) if name in STAGES]
            if named:
                rows.append((named, line))
    return rows


def unlisted(text: str) -> list[str]:
    """Every module of ddsolve/ that its stage's row of the table ``text`` does not name in backquotes (as
    `name` or `name.attribute`; a subpackage's ``__init__`` is its stage's row itself)."""
    rows = {name: line for names, line in table_rows(text) for name in names}
    missing = []
    for module, path in sorted(modules().items()):
        if path.name == "__init__.py":
            continue
        name = module.rpartition(".")[2]
        row = rows.get(stage(module))
        if row is None:
            missing.append(f"{module}: docs/architecture.md's table has no row for its stage {stage(module)!r}")
        elif not re.search(rf"`(?:ddsolve\.)?{re.escape(name)}(?:\.[\w.]+)?(?:\(\))?`", row):
            missing.append(f"{module} ({path.relative_to(ROOT)}): not listed in the {stage(module)!r} row of "
                           f"docs/architecture.md's table: name it there as `{name}`")
    return missing


def test_the_table_lists_every_module_in_its_stages_row():
    missing = unlisted(ARCHITECTURE.read_text(encoding="utf-8"))
    assert not missing, "\n".join(missing)


def test_the_table_check_fails_on_a_module_left_out():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    row = next(line for names, line in table_rows(text) if names == ["io"])
    assert any("ddsolve.io.safe" in line for line in unlisted(text.replace(row, row.replace("`safe", "`other"))))


def test_the_table_orders_the_stages_as_the_imports_do():
    """The table's rows run from the bottom stage up in the order the import check uses (STAGES)."""
    documented = [name for names, _ in table_rows(ARCHITECTURE.read_text(encoding="utf-8")) for name in names]
    assert documented == list(STAGES), f"docs/architecture.md's table: {documented}, the import order: {STAGES}"


def test_nothing_in_the_package_imports_the_experiments():
    users = [f"{module} imports {imported}" for module, path in modules().items() for imported in imports(path)
             if imported.split(".")[0] == "experiments"]
    assert not users, "\n".join(users)
    assert not (PACKAGE / "experiments").exists(), "the experiments live beside the package, in experiments/"


def test_the_experiments_find_the_repository_through_its_root():
    """Children of the experiments import this checkout through ``PYTHONPATH=experiments.ROOT``; a module
    that counts parent folders from its own file breaks when it moves."""
    counting = [path.name for path in (ROOT / "experiments").glob("*.py")
                if path.name != "__init__.py" and "__file__" in path.read_text(encoding="utf-8")]
    assert not counting, counting


def test_tests_import_no_private_name():
    private = []
    for path in Path(__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ddsolve"):
                private += [f"{path.name}: {node.module}.{alias.name}" for alias in node.names
                            if alias.name.startswith("_") and not alias.name.endswith("__")]
    assert not private, "\n".join(private)


def test_tests_use_no_private_attribute_of_a_ddsolve_module():
    private = []
    for path in Path(__file__).parent.glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        modules = {alias.asname or alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                   and (node.module or "").startswith("ddsolve") for alias in node.names
                   if f"{node.module}.{alias.name}" in modules_of_ddsolve()}
        private += [f"{path.name}:{node.lineno}: {node.value.id}.{node.attr}" for node in ast.walk(tree)
                    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules
                    and node.attr.startswith("_") and not node.attr.endswith("__")]
    assert not private, "\n".join(private)


def modules_of_ddsolve() -> set[str]:
    return set(modules())
