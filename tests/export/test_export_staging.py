"""An export appears under its final name only when complete: staging beside it, rename, cleanup on failure."""

from pathlib import Path

import pytest

from cama_pipeline.export.staging import staged_output


def _leftovers(folder: Path) -> list[str]:
    """Hidden staging or set-aside entries left in `folder`."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_folder_appears_only_when_complete(tmp_path: Path) -> None:
    out = tmp_path / "export"
    with staged_output(out) as staging:
        (staging / "maps").mkdir(parents=True)
        (staging / "maps" / "a.json").write_text("{}")
        assert not out.exists()
    assert (out / "maps" / "a.json").read_text() == "{}"
    assert _leftovers(tmp_path) == []


def test_failure_leaves_nothing_and_keeps_the_previous_export(tmp_path: Path) -> None:
    out = tmp_path / "export.json"
    out.write_text("old")
    with pytest.raises(RuntimeError, match="disk full"):
        with staged_output(out, overwrite=True) as staging:
            staging.write_text("half")
            raise RuntimeError("disk full")
    assert out.read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_existing_output_needs_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "export"
    out.mkdir()
    (out / "old.txt").write_text("old")
    with pytest.raises(FileExistsError, match="--overwrite"):
        with staged_output(out):
            pass
    with staged_output(out, overwrite=True) as staging:
        staging.mkdir()
        (staging / "new.txt").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == ["new.txt"]
    assert _leftovers(tmp_path) == []


def test_writing_nothing_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="wrote nothing"):
        with staged_output(tmp_path / "export"):
            pass
    assert list(tmp_path.iterdir()) == []
