"""The gateway's modules form no import circle (every import counts: top level, in functions, TYPE_CHECKING)."""

from __future__ import annotations

import ast
from pathlib import Path

GATEWAY = Path(__file__).resolve().parents[2] / "gateway"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(GATEWAY.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in GATEWAY.rglob("*.py") if "migrations" not in p.parts}


def imported(path: Path, known: set[str]) -> set[str]:
    """The gateway modules ``path`` imports, anywhere in it."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # `from gateway.routers import system` imports the module gateway.routers.system
            names = [f"{node.module}.{alias.name}" for alias in node.names] + [node.module]
        for name in names:
            while name and name not in known:
                name = name.rpartition(".")[0]
            if name and name != "gateway":
                found.add(name)
    return found


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle found by a depth-first search (each reported once, from where it was entered)."""
    found: list[list[str]] = []
    state: dict[str, int] = {}  # 1 = on the current path, 2 = done
    path: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                found.append([*path[path.index(nxt) :], nxt])
            elif nxt not in state:
                visit(nxt)
        path.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    return found


def test_the_cycle_finder_finds_a_circle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_gateway_modules_form_no_import_cycle() -> None:
    mods = modules()
    assert {"gateway.app", "gateway.state", "gateway.deps", "gateway.edge", "gateway.routers.system"} <= set(
        mods
    )
    graph = {name: imported(path, set(mods)) - {name} for name, path in mods.items()}
    assert "gateway.state" in graph["gateway.deps"] and "gateway.state" in graph["gateway.edge"]
    assert cycles(graph) == []


def test_the_shared_state_imports_none_of_the_wiring() -> None:
    mods = modules()
    wiring = {"gateway.app", "gateway.deps", "gateway.edge", "gateway.server"} | {
        m for m in mods if m.startswith("gateway.routers")
    }
    assert imported(mods["gateway.state"], set(mods)) & wiring == set()
