"""Same seed, same bytes; different seed, different site; and the `cama synth` command."""

from typer.testing import CliRunner

from cama_pipeline.synthetic.generate import run
from cama_studio.cli import app
from tests.synthetic.synth_helpers import file_digests, micro_config


def test_same_seed_gives_identical_files_whatever_the_worker_count(tmp_path):
    a = run(micro_config(), tmp_path / "a", workers=1, show_progress=False)
    b = run(micro_config(), tmp_path / "b", workers=2, show_progress=False)
    digest_a, digest_b = file_digests(a.out_dir), file_digests(b.out_dir)
    assert len(digest_a) > 100
    assert digest_a == digest_b


def test_other_seed_gives_another_site(tmp_path):
    a = file_digests(run(micro_config(1), tmp_path / "a", workers=1, show_progress=False).out_dir)
    b = file_digests(run(micro_config(2), tmp_path / "b", workers=1, show_progress=False).out_dir)
    assert a.keys() == b.keys()
    assert sum(a[k] != b[k] for k in a) > len(a) // 2


def test_rerun_skips_an_up_to_date_site_and_refuses_foreign_folders(tmp_path, tiny_site):
    again = run(tiny_site.config, tiny_site.result.out_dir, show_progress=False)
    assert again.skipped
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    runner = CliRunner()
    result = runner.invoke(app, ["synth", "--preset", "tiny", "--out", str(foreign)])
    assert result.exit_code == 2
    assert "not a generated site" in result.output
    assert (foreign / "notes.txt").read_text() == "mine"


def test_cli_reports_an_up_to_date_site(tiny_site):
    result = CliRunner().invoke(app, ["synth", "--preset", "tiny", "--out", str(tiny_site.result.out_dir)])
    assert result.exit_code == 0, result.output
    assert "up to date" in result.output
    assert "scene-0004 (night)" in result.output


def test_cli_rejects_an_unknown_preset(tmp_path):
    result = CliRunner().invoke(app, ["synth", "--preset", "huge", "--out", str(tmp_path / "x")])
    assert result.exit_code == 2
    assert "unknown preset 'huge'" in result.output
    assert not (tmp_path / "x").exists()
