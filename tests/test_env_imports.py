"""The env package's imports run one way: shared layers below the envs, no env importing another.

``agri_envs`` imports neither ``agri_baselines`` nor ``agri_training``; ``sim2d`` and ``scenes`` import no
env; an env package (rover, coverage, chain, arm) imports only the shared layers and itself.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "agri_envs"
ENVS = ("rover", "coverage", "chain", "arm")
SHARED = ("sim2d", "scenes")


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, anywhere in the file (inside functions too)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


FILES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_run_one_way(path):
    parts = path.relative_to(PACKAGE).parts
    own = parts[0] if len(parts) > 1 else None
    for module in imported_modules(path):
        top = module.split(".")
        assert top[0] not in ("agri_baselines", "agri_training"), f"{path.name} imports {module}"
        if top[0] != "agri_envs" or len(top) < 2 or top[1] == own:
            continue
        if own in SHARED:
            assert top[1] not in ENVS, f"shared layer {own}/{path.name} imports the env package {module}"
        if own in ENVS:
            assert top[1] not in ENVS, f"env package {own}/{path.name} imports another env: {module}"
