"""The layer order (README, "Layers"): a module may import its own layer and the layers below it, never one above.

Every module of the packages is parsed with `ast`; every import counts, at module level or inside a function
(a lazy import is still a dependency), `TYPE_CHECKING` ones included. A module's layer is the longest prefix in
`LAYERS` that names it or a package above it; a new module of `cama_pipeline` or `app` must be placed there
explicitly (the test says so), so that a new stage or app part lands in the order on purpose.
"""

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("annotations", "app", "cama_pipeline", "cama_studio", "models")

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "core",
        (
            "cama_pipeline",  # the package itself: a docstring
            "cama_pipeline.io",
            "cama_pipeline.console",
            "cama_pipeline.cli_options",
            "cama_pipeline.progress",
            "cama_pipeline.code_version",
            "cama_pipeline.semantics",
            "cama_pipeline.data",
            "cama_pipeline.bev",
            "cama_pipeline.cameras",
            "cama_pipeline.workspace",
            "cama_pipeline.fingerprints",
            "cama_pipeline.results",
            "cama_pipeline.site_identity",
            "cama_pipeline.iterables",
        ),
    ),
    ("annotations", ("annotations",)),
    # the stages, in the order of the data flow: a stage reads the outputs of those before it
    ("stage synthetic", ("cama_pipeline.synthetic",)),
    ("stage wigo", ("cama_pipeline.wigo",)),
    ("stage keyframes", ("cama_pipeline.keyframes",)),
    ("stage site", ("cama_pipeline.site",)),
    ("stage pairs", ("cama_pipeline.pairs",)),
    # image masks for data sets without their own: the segmenter (trained on generator sites) and imported masks
    ("stage segment", ("cama_pipeline.segment",)),
    ("stage features", ("cama_pipeline.features",)),
    ("stage sfm", ("cama_pipeline.sfm",)),
    # the exports' refined poses: SfM poses, and WIGO corrected by them between SfM keyframes
    ("stage refined poses", ("cama_pipeline.refined_poses",)),
    ("stage surface", ("cama_pipeline.surface",)),
    ("stage evaluate", ("cama_pipeline.evaluate",)),
    # exports: an annotation set with the reconstruction's poses and data, in every format that leaves the system
    ("stage export", ("cama_pipeline.export",)),
    ("models", ("models",)),
    # the backend: foundations (config, db models, schemas, clock, tiles, quality) < the job runner < crud <
    # job kinds and auth < API routes < the app and its server
    # (the camera panel's machinery, `app.backend.cameras`, is a foundation: routes and crud import it)
    ("app.backend", ("app", "app.backend", "app.backend.cameras")),
    # what a careful annotator does with proposals and what it costs, pure of the backend: the retrain job's
    # second gate and the scripted annotator over HTTP both use it
    ("app.review_effort", ("app.review_effort",)),
    ("app.backend.jobs.runner", ("app.backend.jobs.runner",)),
    ("app.backend.crud", ("app.backend.crud",)),
    ("app.backend.jobs", ("app.backend.jobs", "app.backend.auth_cache", "app.backend.loop")),
    ("app.backend.api", ("app.backend.api",)),
    ("app.backend.main", ("app.backend.main", "app.backend.serve")),
    # the 3D review is a client of the backend's HTTP API (it shares its log filter); the simulation drives the
    # backend in process; the demo runs the backend and the review together
    ("app.viewer", ("app.viewer",)),
    ("app.simulation", ("app.simulation",)),
    ("app.demo", ("app.demo",)),
    ("cama_studio", ("cama_studio",)),
)
"""Lowest first. Same-layer modules may import each other."""

MUST_BE_PLACED = ("cama_pipeline", "app")
"""Packages whose every module must match a prefix longer than the package's own name."""


@dataclass(frozen=True)
class Import:
    module: str
    """The importing module."""
    target: str
    """The module imported (`from a.b import c` names a.b.c when that is a module)."""
    where: str
    """file:line of the import."""


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def all_modules() -> dict[str, Path]:
    return {
        module_name(path): path
        for package in PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
        if "node_modules" not in path.parts
    }


def imports_of(module: str, source: str, *, is_package: bool, where: str, modules: set[str]) -> list[Import]:
    """Every import of the packages in a module's source, wherever it stands in the file."""
    found = []
    for node in ast.walk(ast.parse(source, filename=where)):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = module.split(".") if is_package else module.split(".")[:-1]
                parts = package[: len(package) - node.level + 1] + ([node.module] if node.module else [])
                base = ".".join(parts)
            else:
                base = node.module or ""
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        found += [
            Import(module, target, f"{where}:{node.lineno}")
            for target in dict.fromkeys(targets)
            if target.split(".")[0] in PACKAGES
        ]
    return found


def layer_of(module: str) -> tuple[int, str, str]:
    """(rank, layer name, matching prefix) of a module; the longest prefix wins."""
    best: tuple[int, str, str] | None = None
    for rank, (name, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and (
                best is None or len(prefix) > len(best[2])
            ):
                best = (rank, name, prefix)
    if best is None:
        raise LookupError(f"{module} is in no layer: add it to LAYERS in {Path(__file__).name}")
    return best


def test_every_module_is_placed_in_a_layer() -> None:
    unplaced = [
        module
        for module in all_modules()
        if module.split(".")[0] in MUST_BE_PLACED
        and module not in MUST_BE_PLACED
        and layer_of(module)[2] in MUST_BE_PLACED
    ]
    assert not unplaced, f"place these modules in LAYERS ({Path(__file__).name}): {', '.join(unplaced)}"


def violations_in(module: str, source: str, *, is_package: bool, where: str, modules: set[str]) -> list[str]:
    """One line per import of `source` that runs up the layers, naming file, line, module and import."""
    rank, name, _ = layer_of(module)
    lines = []
    for found in imports_of(module, source, is_package=is_package, where=where, modules=modules):
        target_rank, target_name, _ = layer_of(found.target)
        if target_rank > rank:
            lines.append(
                f"{found.where}: {module} ({name}) imports {found.target} ({target_name}, a higher layer)"
            )
    return lines


def test_no_module_imports_a_layer_above_its_own() -> None:
    modules = all_modules()
    violations = [
        line
        for module, path in modules.items()
        for line in violations_in(
            module,
            path.read_text(encoding="utf-8"),
            is_package=path.name == "__init__.py",
            where=str(path.relative_to(ROOT)),
            modules=set(modules),
        )
    ]
    assert not violations, "imports that run up the layers:\n" + "\n".join(violations)


@pytest.mark.parametrize(
    ("source", "is_package", "expected"),
    [
        ("import cama_pipeline.io", False, ["cama_pipeline.io"]),
        ("from app.backend import crud", False, ["app.backend.crud"]),
        ("from annotations import AnnotationSet", False, ["annotations"]),
        ("def f():\n    from models.vma.propose import propose", False, ["models.vma.propose"]),
        ("if TYPE_CHECKING:\n    from app.viewer.scene import Scene", False, ["app.viewer.scene"]),
        ("from .stage import run", False, ["cama_pipeline.wigo.stage"]),
        ("from . import stage", False, ["cama_pipeline.wigo.stage"]),
        ("from .. import io", False, ["cama_pipeline.io"]),
        ("from .stage import run", True, ["cama_pipeline.wigo.command.stage"]),
        ("import numpy", False, []),
    ],
)
def test_imports_are_found_wherever_they_stand(source: str, is_package: bool, expected: list[str]) -> None:
    """The walker sees function-level, TYPE_CHECKING and relative imports, and names a module imported from
    its package."""
    modules = set(all_modules())
    found = imports_of(
        "cama_pipeline.wigo.command", source, is_package=is_package, where="t.py", modules=modules
    )
    assert [i.target for i in found] == expected


@pytest.mark.parametrize(
    ("module", "source", "allowed"),
    [
        ("cama_pipeline.io", "def f():\n    from cama_pipeline.sfm.stage import run", False),
        ("cama_pipeline.wigo.stage", "from cama_pipeline.keyframes import KeyframeConfig", False),
        ("cama_pipeline.keyframes.stage", "from cama_pipeline.wigo import WigoConfig", True),
        ("annotations.lift", "from cama_pipeline.evaluate import sre", False),
        ("cama_pipeline.evaluate.observed", "from annotations.geometry import densify", True),
        ("app.backend.jobs.runner", "from app.backend.crud.users import create_user", False),
        ("app.backend.crud.jobs", "from app.backend.jobs.runner import JobRunner", True),
        ("app.backend.serve", "from app.viewer.review import serve_in_background", False),
        ("app.viewer.sources", "from app.backend.poll_log import quiet_change_polls", True),
        ("models.vma.propose", "from cama_studio.pipeline import run", False),
    ],
)
def test_an_import_up_the_layers_is_named(module: str, source: str, allowed: bool) -> None:
    """The check itself, on made-up sources: an import up the layers is reported with its place."""
    lines = violations_in(module, source, is_package=False, where="x.py", modules=set(all_modules()))
    if allowed:
        assert lines == []
    else:
        assert len(lines) == 1 and lines[0].startswith("x.py:") and module in lines[0]
