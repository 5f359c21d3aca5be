"""The code digest in stage fingerprints: it follows what runs, not comments, docstrings or unrelated modules."""

from pathlib import Path

import pytest

from cama_pipeline.code_version import code_version


def _write(root: Path, relative: str, text: str) -> None:
    path = root / relative
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def _project(root: Path, helper_body: str = "return 1", stage_doc: str = "Stage.") -> Path:
    """A tiny project: a stage package importing a helper module (lazily) and a module nobody imports."""
    _write(root, "cama_pipeline/__init__.py", "")
    _write(
        root,
        "cama_pipeline/stage/__init__.py",
        f'"""{stage_doc}"""\nfrom cama_pipeline.stage.run import go\n',
    )
    _write(
        root,
        "cama_pipeline/stage/run.py",
        "def go():\n    from cama_pipeline.helper import h\n    return h()\n",
    )
    _write(root, "cama_pipeline/helper.py", f'def h():\n    """Helps."""\n    {helper_body}\n')
    _write(root, "cama_pipeline/unrelated.py", "X = 1\n")
    return root


def test_the_digest_changes_with_imported_code_only(tmp_path: Path) -> None:
    base = code_version("cama_pipeline.stage", _project(tmp_path / "a"))
    assert base == code_version("cama_pipeline.stage", _project(tmp_path / "b"))
    assert code_version("cama_pipeline.stage", _project(tmp_path / "c", helper_body="return 2")) != base
    reworded = _project(tmp_path / "d", helper_body="return 1  # the one", stage_doc="Another docstring.")
    assert code_version("cama_pipeline.stage", reworded) == base
    unrelated = _project(tmp_path / "e")
    _write(unrelated, "cama_pipeline/unrelated.py", "X = 2\n")
    assert code_version("cama_pipeline.stage", unrelated) == base


def test_an_unknown_package_is_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="cama_pipeline.nothing"):
        code_version("cama_pipeline.nothing", _project(tmp_path))
    with pytest.raises(ValueError, match="numpy"):
        code_version("numpy")


def test_project_stages_have_distinct_digests() -> None:
    digests = {code_version(f"cama_pipeline.{stage}") for stage in ("wigo", "pairs", "sfm", "surface")}
    assert len(digests) == 4
