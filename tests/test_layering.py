"""Imports run one way (ARCHITECTURE.md, Layout): parsed from the source with ``ast``, never imported.

- ``services.common`` imports only itself; ``services.kinematics`` and ``services.dobot`` import
  ``services.common`` and themselves;
- every other package under ``services/`` imports only those three, the generated proto and itself;
- ``services.apps`` (the composition root) imports anything, and nothing imports it;
- ``gateway`` imports only ``services.common``, ``services.kinematics`` and itself;
- no module sits directly under ``services/`` but ``__init__.py``.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LIBRARIES = frozenset({"services.common", "services.kinematics", "services.dobot", "services.rtde"})
ALLOWED: dict[str, frozenset[str]] = {
    "services.common": frozenset({"services.common"}),
    "services.kinematics": frozenset({"services.common", "services.kinematics"}),
    "services.dobot": frozenset({"services.common", "services.dobot"}),
    "services.rtde": frozenset({"services.common", "services.rtde"}),
    "gateway": frozenset({"gateway", "services.common", "services.kinematics"}),
}


def owner(path: Path) -> str:
    """The layer a source file belongs to: ``gateway`` or ``services.<package>``."""
    rel = path.relative_to(ROOT).with_suffix("").parts
    return "gateway" if rel[0] == "gateway" else ".".join(rel[:2])


def target(module: str) -> str | None:
    """The layer an imported module belongs to, or None for stdlib, third-party and proto."""
    parts = module.split(".")
    if parts[0] == "gateway":
        return "gateway"
    if parts[0] == "services":
        return ".".join(parts[:2]) if len(parts) > 1 else "services"
    return None


def imports(path: Path) -> Iterator[tuple[int, str]]:
    """Every absolute module an import statement names (``from services import dobot`` names
    ``services.dobot``), with its line; relative imports stay inside their package."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "services":
                for alias in node.names:
                    yield node.lineno, f"services.{alias.name}"
            else:
                yield node.lineno, node.module


def allowed(layer: str) -> frozenset[str]:
    if layer in ALLOWED:
        return ALLOWED[layer]
    return LIBRARIES | {layer}


def sources() -> list[Path]:
    return sorted([*ROOT.glob("services/**/*.py"), *ROOT.glob("gateway/**/*.py")])


def violations() -> list[str]:
    found = []
    for path in sources():
        layer = owner(path)
        for line, module in imports(path):
            dest = target(module)
            if dest is None or dest == layer:
                continue
            if dest == "services.apps" or (layer != "services.apps" and dest not in allowed(layer)):
                found.append(f"{path.relative_to(ROOT)}:{line}: {layer} imports {module}")
    return found


def test_imports_run_one_way() -> None:
    found = violations()
    assert not found, "imports against ARCHITECTURE.md's layering:\n" + "\n".join(found)


def test_only_packages_sit_under_services() -> None:
    loose = [p.name for p in (ROOT / "services").glob("*.py") if p.name != "__init__.py"]
    assert not loose, f"modules directly under services/ (move them into a package): {loose}"


@pytest.mark.parametrize(
    ("source", "message"),
    [
        ("from services.motion.planner import plan\n", "services.grasp imports services.motion.planner"),
        ("from services import sim\n", "services.grasp imports services.sim"),
        ("import services.apps.cli\n", "services.grasp imports services.apps.cli"),
    ],
)
def test_the_rule_catches_a_crossing_import(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, source: str, message: str
) -> None:
    # the checker itself can fail: a planted file in a copy of the layout is reported by file and line
    pkg = tmp_path / "services" / "grasp"
    pkg.mkdir(parents=True)
    (pkg / "bad.py").write_text("import numpy\n" + source)
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = violations()
    assert found == [f"services/grasp/bad.py:2: {message}"]
