"""Stage progress: a rich bar on a terminal, otherwise logged lines (done/total, rate, time left) at most one
per interval, paced by an injected clock so that no test depends on the machine's speed."""

import logging
import re

import numpy as np
import pytest

import cama_pipeline.progress as progress_module
from app.backend.tiles import build_pyramid
from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.progress import INTERVAL_ENV, StageProgress, format_duration, observed_progress


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class Lines(logging.Handler):
    """The lines logged to a private logger, each with the fake time it was written at."""

    def __init__(self, clock: FakeClock) -> None:
        super().__init__()
        self.clock = clock
        self.lines: list[tuple[float, str]] = []
        self.logger = logging.getLogger(f"test-progress-{id(self)}")
        self.logger.setLevel(logging.INFO)
        self.logger.propagate = False
        self.logger.addHandler(self)

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append((self.clock.now, record.getMessage()))


def _plain(label: str, lines: Lines, clock: FakeClock, *, terminal: bool = False, **options) -> StageProgress:
    return StageProgress(
        label, logger=lines.logger, terminal=terminal, interval_s=5.0, clock=clock, **options
    )


def test_plain_lines_say_done_total_rate_and_time_left_at_most_once_per_interval() -> None:
    clock = FakeClock()
    log = Lines(clock)
    with _plain("synthetic", log, clock) as progress:
        task = progress.add_task("render images", total=800)
        for _ in range(800):
            clock.now += 1 / 16  # exact in binary, so the 5 s steps fall on an advance
            progress.advance(task)
    assert log.lines[0] == (5.0, "synthetic: render images 80/800 (10 %), 16.0/s, about 45 s left")
    assert log.lines[-1] == (50.0, "synthetic: render images 800/800 (100 %), 16.0/s, done in 50 s")
    times = [t for t, _ in log.lines[:-1]]
    assert len(times) == 9 and all(b - a >= 5.0 - 1e-9 for a, b in zip(times, times[1:], strict=False))


def test_slow_work_reports_per_minute_and_minutes_left() -> None:
    clock = FakeClock()
    log = Lines(clock)
    with _plain("sfm", log, clock) as progress:
        task = progress.add_task("clips", total=10)
        clock.now = 60.0
        progress.advance(task)  # the first step: the rate counts from here, so no estimate yet
        clock.now = 235.0
        progress.advance(task, 5)
    assert log.lines == [
        (60.0, "sfm: clips 1/10 (10 %)"),
        (235.0, "sfm: clips 6/10 (60 %), 1.7/min, about 2 min 20 s left"),
    ]
    assert format_duration(3840) == "1 h 4 min"


def test_phases_without_total_and_an_unfinished_task_get_their_lines() -> None:
    clock = FakeClock()
    log = Lines(clock)
    with _plain("sfm", log, clock) as progress:
        merge = progress.add_task("merge")
        clock.now = 6.0
        progress.update(merge, completed=3, description="merge: solving")
        progress.update(merge, completed=1, total=1, description="merge: bundle adjustment")
        training = progress.add_task("training", total=100)
        clock.now = 7.0
        progress.advance(training, 10)
        clock.now = 9.0
        progress.update(training, advance=20, description="loss 0.500")  # cut short: no line yet
    assert [text for _, text in log.lines] == [
        "sfm: merge: solving 3",
        "sfm: merge: bundle adjustment 1/1 (100 %), done in 0 s",
        "sfm: loss 0.500 30/100 (30 %), 10.0/s, about 7 s left",  # on leaving the block
    ]


@pytest.mark.parametrize("terminal", [True, False])
def test_disabled_progress_is_silent(terminal: bool, capsys: pytest.CaptureFixture[str]) -> None:
    clock = FakeClock()
    log = Lines(clock)
    with _plain("wigo", log, clock, terminal=terminal, enabled=False) as progress:
        task = progress.add_task("fuse scenes", total=3)
        for _ in range(3):
            clock.now += 10.0
            progress.advance(task)
    assert log.lines == [] and capsys.readouterr().out == ""


def test_a_terminal_gets_the_rich_bar_and_no_logged_lines(capsys: pytest.CaptureFixture[str]) -> None:
    clock = FakeClock()
    log = Lines(clock)
    with StageProgress("wigo", logger=log.logger, terminal=True, clock=clock) as progress:
        task = progress.add_task("fuse scenes", total=3)
        for _ in range(3):
            clock.now += 10.0
            progress.advance(task)
    assert log.lines == []
    assert "wigo: fuse scenes" in capsys.readouterr().out  # rich's final frame, as it draws into a file


@pytest.mark.parametrize(("terminal", "enabled"), [(True, True), (False, True), (False, False)])
def test_an_observer_sees_every_step_of_every_bar_shown_or_not(terminal: bool, enabled: bool) -> None:
    clock = FakeClock()
    log = Lines(clock)
    seen: list[tuple[str, float, float | None]] = []
    with observed_progress(lambda text, done, total: seen.append((text, done, total))):
        with _plain("cama export", log, clock, terminal=terminal, enabled=enabled) as progress:
            scenes = progress.add_task("scenes", total=2)
            progress.advance(scenes)
            progress.advance(scenes)
            images = progress.add_task("clip data scene-0001")
            progress.update(images, completed=5, total=6)
    assert seen == [
        ("cama export: scenes", 1, 2),
        ("cama export: scenes", 2, 2),
        ("cama export: clip data scene-0001", 5, 6),
    ]
    with _plain("after", log, clock) as progress:  # the block is over: no observer
        progress.advance(progress.add_task("x", total=1))
    assert len(seen) == 3


def test_an_observer_that_raises_stops_the_stage_at_that_step() -> None:
    clock = FakeClock()
    log = Lines(clock)
    done: list[int] = []

    def stop_at_three(text: str, completed: float, total: float | None) -> None:
        if completed >= 3:
            raise InterruptedError(f"{text} stopped")

    with pytest.raises(InterruptedError, match="wigo: fuse scenes stopped"):
        with observed_progress(stop_at_three), _plain("wigo", log, clock) as progress:
            task = progress.add_task("fuse scenes", total=10)
            for step in range(10):
                done.append(step)
                progress.advance(task)
    assert done == [0, 1, 2]


def test_interval_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(INTERVAL_ENV, "0.5")
    assert StageProgress("x").interval_s == 0.5
    monkeypatch.setenv(INTERVAL_ENV, "soon")
    with pytest.raises(ValueError, match=INTERVAL_ENV):
        StageProgress("x")


def test_a_real_stage_without_terminal_logs_progress_lines(
    tmp_path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(progress_module, "output_is_terminal", lambda: False)
    monkeypatch.setenv(INTERVAL_ENV, "0")
    geo = RasterGeoreference(origin_xy=(0.0, 0.0), resolution=0.5, width=600, height=300)
    with caplog.at_level(logging.INFO, logger="app.backend.tiles.pyramid"):
        build_pyramid("semantic", np.zeros((300, 600), np.uint8), geo, tmp_path, tile_size=32)
    lines = [r.getMessage() for r in caplog.records if r.name == "app.backend.tiles.pyramid"]
    assert any(re.fullmatch(r"tiles semantic \d+/\d+ \(\d+ %\), .*/(s|min), about .* left", s) for s in lines)
    assert any(re.fullmatch(r"tiles semantic (\d+)/\1 \(100 %\), .*, done in .*", s) for s in lines)
