"""Progress of long loops: a bar on a terminal, periodic log lines (no carriage returns) in a log."""

import io
import logging

import pytest

from markerplace.cli.main import main
from markerplace.progress import LogProgress, progress_bar, track


class _Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_log_progress_writes_a_line_per_interval_and_a_closing_line(caplog):
    clock = _Clock()
    caplog.set_level(logging.INFO, logger="markerplace")
    with LogProgress(10, "map (k=5)", "img", interval_s=60.0, clock=clock) as bar:
        for _ in range(10):
            clock.t += 25.0
            bar.update()
    # a line at 75, 150 and 225 s (60 s or more after the last); none at 250 s (all done)
    assert [r.getMessage() for r in caplog.records] == [
        "map (k=5): 3/10 img (30 %), 25.0 s/img, about 2 min 55 s left",
        "map (k=5): 6/10 img (60 %), 25.0 s/img, about 1 min 40 s left",
        "map (k=5): 9/10 img (90 %), 25.0 s/img, about 25 s left",
        "map (k=5): 10/10 img in 4 min 10 s",
    ]


def test_log_progress_rate_counts_only_this_runs_items_after_start_up(caplog):
    clock = _Clock()
    caplog.set_level(logging.INFO, logger="markerplace")
    bar = LogProgress(100, "observe", "pose", initial=40, interval_s=10.0, clock=clock)
    clock.t += 30.0
    bar.update(10)  # the first chunk after 30 s of worker start-up: not in the rate
    clock.t += 10.0
    bar.update(20)  # 20 poses in 10 s, 30 left -> 15 s (with the start-up in the rate: 30 s)
    bar.close()
    bar.close()  # once only
    msgs = [r.getMessage() for r in caplog.records]
    assert msgs == ["observe: 70/100 pose (70 %), 2.0 pose/s, about 15 s left", "observe: 70/100 pose in 40 s"]


def test_terminal_bar_time_left_excludes_start_up(monkeypatch):
    """The first estimate of the time left on a terminal is not inflated by start-up: after a
    slow first item the bar's rate comes from the items that follow it."""
    from markerplace import progress as progress_mod

    monkeypatch.setattr(progress_mod.sys, "stderr", _Tty())
    with progress_mod.progress_bar(1000, "observe", "pose") as bar:
        bar.start_t -= 100.0  # 100 s of start-up before the first pose
        bar.update(1)
        bar.last_print_t -= 1.0  # then 10 poses in one second
        bar.start_t -= 1.0
        bar.update(10)
        fmt = bar.format_dict
        rate = fmt["rate"] or (fmt["n"] - fmt["initial"]) / fmt["elapsed"]
    assert rate > 5.0, fmt  # with the start-up in it: about 0.1 pose/s


def test_a_resumed_stage_with_nothing_left_logs_nothing(caplog):
    caplog.set_level(logging.INFO, logger="markerplace")
    with LogProgress(5, "observe", "pose", initial=5):
        pass
    assert caplog.records == []


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_bar_picks_a_bar_on_a_terminal_and_lines_elsewhere(monkeypatch):
    from tqdm import tqdm

    monkeypatch.setattr("sys.stderr", io.StringIO())
    assert isinstance(progress_bar(3, "x", "img"), LogProgress)
    monkeypatch.setattr("sys.stderr", _Tty())
    bar = progress_bar(3, "x", "img")
    assert isinstance(bar, tqdm)
    bar.close()
    quiet = progress_bar(3, "x", "img", enabled=False)
    assert not isinstance(quiet, (tqdm, LogProgress))
    quiet.update()


def test_track_yields_every_item_and_counts_them(caplog):
    caplog.set_level(logging.INFO, logger="markerplace")
    assert list(track(iter(range(4)), "scan", "frame", total=4)) == [0, 1, 2, 3]
    assert caplog.records[-1].getMessage().startswith("scan: 4/4 frame in ")


@pytest.mark.parametrize("quiet", [False, True])
def test_plan_log_has_no_carriage_returns(tmp_path, capsys, quiet):
    """What `markerplace plan ... 2> plan.log` writes: log lines only, a closing line per stage."""
    args = ["plan", "tiny", "-k", "1", "--out", str(tmp_path / "p"), "--grid-spacing", "1.0", "--yaws", "4",
            "--workers", "1"]
    assert main(args + (["--quiet"] if quiet else [])) == 0
    err = capsys.readouterr().err
    assert "\r" not in err
    observed = [ln for ln in err.splitlines() if ln.startswith("INFO: observe: ") and " pose in " in ln]
    assert len(observed) == (0 if quiet else 1)


def test_durations_read_as_a_person_would_write_them():
    from markerplace.progress import format_duration

    assert [format_duration(s) for s in (42.4, 75.2, 3600, 7500)] == ["42 s", "1 min 15 s", "1 h 00 min", "2 h 05 min"]
