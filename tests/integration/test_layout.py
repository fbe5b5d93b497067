"""The package's layout, read from the source with :mod:`ast` (nothing is imported): every import points down the
pipeline, no import cycle, one module per basename, modules small enough to read.

Ranks (an import may point to its own rank or a lower one, never a higher one):

0. the shared leaves at the top of the package: ``errors``, ``choices``, ``config_fields``, ``paths``, ``progress``
   (each imports at most another leaf);
1. ``robot``; 2. ``data``; 3. ``sim``;
4. ``learn``, what every learner shares (run folders, the window-fit loop, residual models, validation selection,
   network files);
5. ``identify`` (the simulator's own physics); 6. ``fit`` (a residual by gradient, alone or over identified physics:
   it calls ``identify``) and ``ppo`` (a residual by reinforcement learning);
7. ``evaluation``, ``export`` and ``adapt`` (online identification: the offline loss of ``identify``); 8. ``skills``;
9. ``experiments`` (the drivers that train and compare several things); 10. ``cli``;
11. the package's face: ``wresdyn/__init__.py`` (re-exports the robot's API) and ``wresdyn/__main__.py`` (runs the
   command line).

A top-level module not named here fails :func:`test_every_module_has_a_rank`: give a new one its rank here.

Imports of the package's own modules sit at module level, outside ``wresdyn/cli/`` (whose command modules are
imported to build ``--help`` and import their work inside ``run``) and the few of :data:`IMPORTS_INSIDE_FUNCTIONS`.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "wresdyn"

RANK = {"errors": 0, "choices": 0, "config_fields": 0, "paths": 0, "progress": 0, "robot": 1, "data": 2, "sim": 3,
        "learn": 4, "identify": 5, "fit": 6, "ppo": 6, "evaluation": 7, "export": 7, "adapt": 7, "skills": 8,
        "experiments": 9, "cli": 10, "__init__": 11, "__main__": 11}
"""Rank of each top-level module or subpackage of ``wresdyn`` (see the module docstring)."""

MAX_LINES = 400
"""Longest module, in lines, every module alike (rsl_rl's largest file is under 500 lines)."""

IMPORTS_INSIDE_FUNCTIONS = {
    # solver_replay imports newton and warp at module level; sim imports them where a solver is built
    "sim/solvers.py -> wresdyn.sim.solver_replay": "newton and warp load with the replay solver only",
    "sim/solver_benchmark.py -> wresdyn.sim.solver_replay": "newton and warp load with the replay solver only",
}
"""Imports of a wresdyn module inside a function, outside ``wresdyn/cli/``: ``"file"`` (any import in it) or
``"file -> module"``, each with its reason; the list only shrinks."""


def _modules() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its ``__init__``)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = ("wresdyn",) + path.relative_to(PACKAGE).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, int, bool]]:
    """``(module, line, module_level)`` of every import of a wresdyn module in ``path``; an import inside a function
    is not module-level (a class body runs at import, so it is)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []

    def visit(node, in_function: bool):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                targets = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")[: len(package.split(".")) - child.level + 1]
                    module = ".".join(base + ([child.module] if child.module else []))
                else:
                    module = child.module or ""
                # ``from pkg import mod`` imports the submodule pkg.mod
                targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in MODULES else module for a in child.names]
            else:
                visit(child, inner)
                continue
            for target in targets:
                if target.split(".")[0] != "wresdyn":
                    continue
                while target not in MODULES and "." in target:  # a name inside a module: the module
                    target = target.rpartition(".")[0]
                found.append((target, child.lineno, not in_function))

    visit(ast.parse(path.read_text(), str(path)), False)
    return found


IMPORTS = {name: _imports(name, path) for name, path in MODULES.items()}


def _rank(name: str) -> int:
    parts = name.split(".")
    return RANK["__init__"] if len(parts) == 1 else RANK[parts[1]]


def _where(name: str, line: int) -> str:
    return f"{MODULES[name].relative_to(PACKAGE.parent)}:{line}"


def test_every_module_has_a_rank():
    assert {name.split(".")[1] for name in MODULES if "." in name} <= set(RANK), (
        "a new top-level module or subpackage: give it its rank in RANK")


def test_no_import_points_back_up_the_pipeline():
    """Module-level imports and imports inside functions alike: a lazy import that points up is still an arrow up."""
    upward = [f"{_where(name, line)}: {name} (rank {_rank(name)}) imports {target} (rank {_rank(target)})"
              for name, imports in IMPORTS.items() for target, line, _ in imports if _rank(target) > _rank(name)]
    assert not upward, "\n".join(upward)


def test_no_import_cycle():
    """Counting imports inside functions too: a function-level import that only hides a cycle is still a cycle."""
    graph = {name: sorted({t for t, _, _ in imports if t != name}) for name, imports in IMPORTS.items()}
    done: set[str] = set()
    cycles = []

    def visit(path: list[str]):
        for nxt in graph[path[-1]]:
            if nxt in path:
                cycles.append(" -> ".join(path[path.index(nxt):] + [nxt]))
            elif nxt not in done:
                visit(path + [nxt])
        done.add(path[-1])

    for name in graph:
        if name not in done:
            visit([name])
    assert not cycles, "\n".join(cycles)


def test_the_shared_leaves_import_only_each_other():
    leaves = {f"wresdyn.{m}" for m, r in RANK.items() if r == 0}
    bad = [f"{_where(name, line)}: {name} imports {target}" for name in leaves if name in IMPORTS
           for target, line, _ in IMPORTS[name] if target not in leaves]
    assert not bad, "\n".join(bad)


def test_module_names_are_unique():
    """No two modules share a basename (``__init__`` and ``__main__`` aside): a name says one role."""
    by_name: dict[str, list[str]] = {}
    for path in MODULES.values():
        if path.stem not in ("__init__", "__main__"):
            by_name.setdefault(path.stem, []).append(str(path.relative_to(PACKAGE)))
    assert not {k: v for k, v in by_name.items() if len(v) > 1}


def test_modules_stay_small():
    """At most :data:`MAX_LINES` lines: a longer module is split by concern."""
    sizes = {path.relative_to(PACKAGE).as_posix(): len(path.read_text().splitlines()) for path in MODULES.values()}
    long = {m: n for m, n in sizes.items() if n > MAX_LINES}
    assert not long, f"over {MAX_LINES} lines, split by concern: {long}"


def test_imports_of_the_package_sit_at_module_level():
    """An import of a wresdyn module inside a function hides the module's dependencies, a cycle among them: it
    belongs at the top of the module, but in ``wresdyn/cli/`` and :data:`IMPORTS_INSIDE_FUNCTIONS`."""
    inside = {}
    for name, imports in IMPORTS.items():
        rel = MODULES[name].relative_to(PACKAGE).as_posix()
        for target, line, module_level in imports:
            if not module_level and not rel.startswith("cli/"):
                inside.setdefault(f"{rel} -> {target}", []).append(line)
    allowed = {k for k in IMPORTS_INSIDE_FUNCTIONS if "->" in k} | {
        k for k in inside if k.split(" -> ")[0] in IMPORTS_INSIDE_FUNCTIONS}
    moved = [f"wresdyn/{k.split(' -> ')[0]}:{line}: {k.split(' -> ')[1]}"
             for k, lines in sorted(inside.items()) if k not in allowed for line in lines]
    assert not moved, "import at module level (or give the reason in IMPORTS_INSIDE_FUNCTIONS):\n" + "\n".join(moved)
    stale = sorted(k for k in IMPORTS_INSIDE_FUNCTIONS if "->" in k and k not in inside)
    assert not stale, f"at module level now (or gone), remove from IMPORTS_INSIDE_FUNCTIONS: {stale}"
