"""A digest of the code that makes a stage's outputs, for the stages' fingerprints: outputs written by older
code are not up to date, so a rerun after a code change redoes the stage instead of keeping them.

The digest covers a package's modules and every project module they import, directly or through others
(imports inside functions included), as syntax trees without docstrings: edits to comments, docstrings or
layout keep outputs, edits to what runs do not.

The digest is read from the files on disk, and a process runs the code it imported: a file edited after that (a
`git pull`, a commit while a long run or a benchmark is going) would have the stage write outputs made by the old
code under the new code's digest, which a later run takes as up to date. So a digest over a module this process has
already imported from a file changed since the process began is refused (`CodeChangedError`, naming the file):
restart the process.
"""

import ast
import hashlib
import sys
import time
from functools import cache
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent
PROJECT_PACKAGES = ("cama_pipeline", "models")
PROCESS_STARTED = time.time()
"""When this module was imported: with the first stage, at the start of any process that runs one."""


class CodeChangedError(ValueError):
    """A project file this process imported has changed on disk since: its stage digests would not name the code
    that runs."""


def module_files(module: str, root: Path = PROJECT_ROOT) -> list[Path]:
    """The project source files of a dotted module name: its `.py` or its package `__init__.py`; [] otherwise."""
    if module.split(".")[0] not in PROJECT_PACKAGES:
        return []
    base = root.joinpath(*module.split("."))
    return [path for path in (base.with_suffix(".py"), base / "__init__.py") if path.is_file()]


def imported_modules(tree: ast.AST) -> set[str]:
    """Dotted names a module imports, with `from a import b` giving both `a` and `a.b` (b may be a module)."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _without_docstrings(tree: ast.Module) -> ast.Module:
    """The tree with the docstring of the module and of every class and function removed."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                if isinstance(body[0].value.value, str):
                    node.body = body[1:] or [ast.Pass()]
    return tree


def _package_files(package: str, root: Path) -> list[Path]:
    """Every module file of a package (recursively), or the module's own file."""
    files = module_files(package, root)
    if files and files[0].name == "__init__.py":
        return sorted(files[0].parent.rglob("*.py"))
    return files


def _module_name(path: Path, root: Path) -> str:
    """The dotted module name of a project file (a package's `__init__.py` names the package)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _check_unchanged_since_import(path: Path, root: Path) -> None:
    """CodeChangedError when this process imported `path`'s module from `path` and the file changed after the
    process began."""
    module = sys.modules.get(_module_name(path, root))
    loaded_from = getattr(module, "__file__", None)
    if loaded_from is None or Path(loaded_from).resolve() != path.resolve():
        return
    modified = path.stat().st_mtime
    if (
        PROCESS_STARTED < modified <= time.time()
    ):  # a time still ahead of the clock is a skewed copy, not an edit
        raise CodeChangedError(
            f"{path}: changed on disk after this process imported it; restart the process, so that the stage "
            "runs the code its outputs' fingerprint names"
        )


@cache
def code_version(package: str, root: Path = PROJECT_ROOT) -> str:
    """A short digest of `package` and the project code it imports (under `root`, the project by default);
    ValueError if it is not project code. Cached: the code does not change under a running process."""
    pending = _package_files(package, root)
    if not pending:
        raise ValueError(f"code_version: {package!r} is not a module of {PROJECT_PACKAGES}")
    trees: dict[Path, str] = {}
    while pending:
        path = pending.pop()
        if path in trees:
            continue
        _check_unchanged_since_import(path, root)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for name in imported_modules(tree):
            parts = name.split(".")  # importing a.b.c runs a/__init__ and a/b/__init__ too
            for depth in range(1, len(parts) + 1):
                pending.extend(module_files(".".join(parts[:depth]), root))
        trees[path] = ast.dump(_without_docstrings(tree))
    digest = hashlib.sha256()
    for path in sorted(trees):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(trees[path].encode())
    return digest.hexdigest()[:16]
