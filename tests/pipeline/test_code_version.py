"""The code digest in stage fingerprints: it follows what runs, not comments, docstrings or unrelated modules."""

import os
import sys
import time
import types
from pathlib import Path

import pytest

from cama_pipeline import code_version as code_version_module
from cama_pipeline.code_version import CodeChangedError, code_version


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


def test_a_file_changed_after_this_process_imported_it_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stage's digest names the code on disk; once a module this process runs has changed there, the digest
    would name code that does not run, so it is refused, naming the file. A module imported from elsewhere, or a
    file unchanged since the process began, is not."""
    root = _project(tmp_path / "p")
    helper = root / "cama_pipeline/helper.py"
    started = code_version_module.PROCESS_STARTED
    os.utime(helper, (started - 60, started - 60))
    monkeypatch.setitem(sys.modules, "cama_pipeline.helper", types.SimpleNamespace(__file__=str(helper)))
    before = code_version("cama_pipeline.stage", root)  # imported, and unchanged since the process began
    edited = (started + time.time()) / 2  # after the process began, before now
    os.utime(helper, (edited, edited))
    with pytest.raises(CodeChangedError, match=r"helper\.py: changed on disk after this process imported it"):
        code_version.__wrapped__("cama_pipeline.stage", root)
    ahead = time.time() + 3600  # a copy made under a clock ahead of this one: not an edit
    os.utime(helper, (ahead, ahead))
    assert code_version.__wrapped__("cama_pipeline.stage", root) == before
    elsewhere = types.SimpleNamespace(__file__=str(tmp_path / "other" / "helper.py"))
    monkeypatch.setitem(sys.modules, "cama_pipeline.helper", elsewhere)
    assert code_version.__wrapped__("cama_pipeline.stage", root) == before
