"""The source layout: no module of the package grows past a size one can read through."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

MAX_LINES = 800
SRC = Path(__file__).resolve().parents[1] / "src"


def test_no_module_is_over_800_lines():
    sizes = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in sorted((SRC / "mpcdrive").rglob("*.py"))}
    assert len(sizes) > 20  # the package's modules, not an empty folder
    over = {p.relative_to(SRC).as_posix(): n for p, n in sizes.items() if n > MAX_LINES}
    assert not over, f"modules over {MAX_LINES} lines (split them along a seam): " + ", ".join(
        f"{name} ({n})" for name, n in sorted(over.items())
    )


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    """Every module of the package -> the modules of the package it imports: every import
    statement, wherever it stands (in a function, under ``TYPE_CHECKING``), as import-linter
    counts them; ``from .a import b`` imports ``a`` and, where it is a module, ``a.b``."""
    files = sorted((SRC / "mpcdrive").rglob("*.py"))
    modules = {_module_name(p) for p in files}
    graph: dict[str, set[str]] = {}
    for p in files:
        name = _module_name(p)
        package = name if p.name == "__init__.py" else name.rpartition(".")[0]
        found: set[str] = set()
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                found.add(target)
                found.update(f"{target}.{a.name}" for a in node.names)
        graph[name] = {m for m in found if m in modules and m != name}
    return graph


def _cycle_between_children(ancestor: str) -> list[str] | None:
    """A cycle of imports between the children of ``ancestor`` (its modules and subpackages, each
    standing for everything inside it), as a list of children that ends where it starts; None
    if there is none (the rule of import-linter's ``acyclic_siblings`` contracts)."""
    depth = ancestor.count(".") + 1

    def child(module: str) -> str | None:
        parts = module.split(".")
        if len(parts) <= depth or ".".join(parts[:depth]) != ancestor:
            return None
        return ".".join(parts[: depth + 1])

    edges: dict[str, set[str]] = {}
    for importer, imported in _imports().items():
        a = child(importer)
        for m in imported:
            b = child(m)
            if a is not None and b is not None and a != b:
                edges.setdefault(a, set()).add(b)
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = 1
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [node, nxt] if nxt in path else [node, nxt]
            if nxt not in state:
                found = visit(nxt, path + [node])
                if found:
                    return found
        state[node] = 2
        return None

    for start in sorted(edges):
        if start not in state:
            found = visit(start, [])
            if found:
                return found
    return None


@pytest.mark.parametrize("ancestor", ["mpcdrive", "mpcdrive.control"])
def test_no_import_cycle_between_the_children_of(ancestor):
    """The package's parts import each other one way only (``scenarios`` no adapter: a CommonRoad
    plant is handed to ``build_experiment``), and so do the modules of ``control``: ``mpc``
    (``LtvMpc(...)``) imports both implementations, ``python_mpc`` and ``compiled_mpc``, which
    import what they share (``mpc_base``, ``mpc_config``) and never ``mpc``. The contracts of
    pyproject.toml say the same for ``lint-imports``."""
    cycle = _cycle_between_children(ancestor)
    assert cycle is None, f"import cycle in {ancestor}: " + " -> ".join(c.rpartition(".")[2] for c in cycle)


def test_the_cycle_finder_finds_the_old_cycle(monkeypatch):
    """The check above sees a cycle through a lazy import in a method (as ``LtvMpc.__new__`` once
    imported the compiled controller, which imports ``mpc``)."""
    real = _imports()
    real["mpcdrive.control.mpc_base"] = real["mpcdrive.control.mpc_base"] | {"mpcdrive.control.compiled_mpc"}
    monkeypatch.setattr(sys.modules[__name__], "_imports", lambda: real)
    cycle = _cycle_between_children("mpcdrive.control")
    assert cycle is not None and {"mpcdrive.control.mpc_base", "mpcdrive.control.compiled_mpc"} <= set(cycle)
