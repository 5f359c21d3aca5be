"""Only `cama_pipeline.workspace` joins workspace path pieces: no other module of the product or the benches
builds `<workspace>/sfm/...` (or any other stage folder, or the default `workspace` folder) with `/` or
`joinpath`, so a layout change is made in one place (issue 22.1).

The check reads the source (ast): a `/` (or `joinpath`, `os.path.join`) with a string operand whose first path
segment is a workspace folder name. Tests and the generator's site layout (`ground_truth/bev`, `nuscenes/`) are
out of scope.
"""

import ast
from pathlib import Path

import pytest

from cama_pipeline.workspace import STAGE_FOLDERS, WORKSPACE_DIRNAME

REPO = Path(__file__).resolve().parents[1]
SCANNED = ("annotations", "app", "bench", "cama_pipeline", "cama_studio", "models")
OWNER = REPO / "cama_pipeline" / "workspace.py"
FOLDER_NAMES = frozenset((*STAGE_FOLDERS, WORKSPACE_DIRNAME))


def _names_a_folder(node: ast.expr) -> bool:
    """A string literal whose first path segment is a workspace folder name ("sfm", "sfm/poses.json", ...)."""
    return (
        isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and node.value.strip("/").split("/")[0] in FOLDER_NAMES
    )


def _is_join_call(node: ast.Call) -> bool:
    func = node.func
    if isinstance(func, ast.Attribute) and func.attr == "joinpath":
        return True
    return (
        isinstance(func, ast.Attribute)
        and func.attr == "join"
        and isinstance(func.value, ast.Attribute)
        and func.value.attr == "path"
    )


def workspace_joins(source: str) -> list[int]:
    """Line numbers where `source` joins a workspace folder name onto a path."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            if _names_a_folder(node.left) or _names_a_folder(node.right):
                lines.append(node.lineno)
        elif isinstance(node, ast.Call) and _is_join_call(node) and any(map(_names_a_folder, node.args)):
            lines.append(node.lineno)
    return lines


def scanned_files() -> list[Path]:
    files = [p for folder in SCANNED for p in sorted((REPO / folder).rglob("*.py")) if p != OWNER]
    return [p for p in files if "node_modules" not in p.parts]


@pytest.mark.parametrize(
    ("snippet", "found"),
    [
        ('root / "sfm" / site_id / "poses.json"', True),
        ('Path(ws) / "surface"', True),
        ('site / "workspace"', True),
        ('ws / "pairs/site-001/pairs.txt"', True),
        ('root.joinpath("proposals", name)', True),
        ('os.path.join(root, "keyframes")', True),
        ('"/wigo" / root', True),
        ('site / "ground_truth" / "bev"', False),
        ("workspace.sfm_poses(site_id)", False),
        ('f"/api/sites/{site_id}"', False),
        ("total / 2", False),
    ],
)
def test_the_check_finds_joins_and_nothing_else(snippet: str, found: bool) -> None:
    assert bool(workspace_joins(snippet)) is found


def test_no_module_outside_the_workspace_module_joins_workspace_folders() -> None:
    files = scanned_files()
    assert len(files) > 100 and OWNER.is_file()  # the scan covers the product, not an empty glob
    offenders = [
        f"{path.relative_to(REPO)}:{line}"
        for path in files
        for line in workspace_joins(path.read_text(encoding="utf-8"))
    ]
    assert not offenders, f"use cama_pipeline.workspace.Workspace instead of joining: {offenders}"
