"""The live page sends every row, also the rows the monitor writes late (issue 37).

During a 1x live run the monitor's files lag the exchange file by its training and each refit
(seconds), and it finishes after the run's last row.  The page used to stream each poll's rows
after the clock's previous value, so the monitor's rows that arrived for times the clock had
passed were never sent: permanent straight-line gaps in the signal, forecast and statistic
plots.  Here the writers are simulated (no pacing, no dependence on the machine's speed): the
exchange file grows by 0.25 s a step, the monitor writes nothing until it has trained, lags,
pauses for a refit, and ends after the run; the page (headless, following the newest row) is
ticked after each step, and at the end its data sources must hold every row written.
"""
from __future__ import annotations

import json
import os
import socket

import numpy as np
import pytest

STEP = 0.01          # s, the exchange grid
STOP = 15.0          # s, shorter than the page's 20 s window: the sources then hold every row
TRAIN = (1.0, 4.0)   # s, the monitor's training window: it writes nothing until the exchange reaches 4.5 s
REFIT = (8.0, 10.5)  # s, rows the monitor holds back (a refit) until the exchange reaches 11 s
LAG = 0.5            # s, how far the monitor's files trail the exchange file otherwise


def _record(status: str, run_id: str = "c" * 32) -> dict:
    return {"schema": 2, "status": status, "run_id": run_id, "case": "late", "case_file": None, "description": "",
            "fmu": {"path": "F.fmu", "guid": "g", "model_name": "M"},
            "experiment": {"start": 0.0, "stop": STOP, "step": STEP, "tolerance": None},
            "parameters": {}, "events": [], "fault_time": None, "outputs": ["x2"], "units": {}, "noise": None,
            "exchange": {"flush_interval": 0.25, "realtime_factor": 1.0, "max_rows": 100000},
            "rows_written": 0, "last_time": None, "started_at": "2026-11-27T00:00:00Z", "updated_at": None,
            "finished_at": None, "wall_time_s": 0.0, "error": None,
            "writer": {"pid": os.getpid(), "host": socket.gethostname(), "heartbeat_s": 2.0}}


def _times(t0: float, t1: float) -> np.ndarray:
    """Grid times in [t0, t1) from integer steps (no accumulated round-off)."""
    return np.arange(round(t0 / STEP), round(t1 / STEP)) * STEP


class Writers:
    """fourbar-run and fourbar-monitor --follow, simulated: what each has written so far."""

    def __init__(self, folder):
        self.folder = folder
        (folder / "monitor").mkdir()
        (folder / "run.json").write_text(json.dumps(_record("running")))
        (folder / "exchange.csv").write_text("time,x2\n")
        (folder / "monitor" / "forecast.csv").write_text("time,signal,value,forecast\n")
        (folder / "monitor" / "evaluations.csv").write_text("time,statistic,threshold,state\n")
        self.exchange_to = 0.0       # rows before this time are written
        self.monitor_to = TRAIN[0]   # the monitor's rows start at its training window's start
        self.forecast: list[float] = []
        self.evaluations: list[float] = []

    def exchange(self, to: float) -> None:
        t = _times(self.exchange_to, to)
        with open(self.folder / "exchange.csv", "a") as f:
            f.writelines(f"{float(v)!r},{float(np.sin(v))!r}\n" for v in t)
        self.exchange_to = to

    def monitor(self, to: float) -> None:
        """The monitor's rows up to ``to``: training samples without a forecast, then judged ones."""
        t = _times(self.monitor_to, to)
        with open(self.folder / "monitor" / "forecast.csv", "a") as f:
            for v in map(float, t):
                forecast = "" if v < TRAIN[1] else repr(float(np.sin(v)) + 1e-3)
                f.write(f"{v!r},x2,{float(np.sin(v))!r},{forecast}\n")
        judged = t[t >= TRAIN[1]]
        with open(self.folder / "monitor" / "evaluations.csv", "a") as f:
            f.writelines(f"{float(v)!r},0.5,5.0,STABLE\n" for v in judged)
        self.forecast.extend(t)
        self.evaluations.extend(judged)
        self.monitor_to = to


def test_rows_the_monitor_writes_late_are_all_sent(tmp_path):
    from view.page import PageSettings, RunPage, SharedRun

    writers = Writers(tmp_path)
    page = RunPage(SharedRun(tmp_path, poll_s=0.0), PageSettings())     # live: the clock follows the newest row
    for k in range(1, round(STOP / 0.25) + 1):
        now = k * 0.25
        writers.exchange(now)
        if now >= TRAIN[1] + LAG and not REFIT[0] + LAG <= now < REFIT[1] + LAG:
            writers.monitor(now - LAG)
        page.tick()
        assert page.clock == pytest.approx(now - STEP, abs=1e-9)          # following the exchange file
    (tmp_path / "run.json").write_text(json.dumps(_record("finished")))
    page.tick()
    writers.monitor(STOP)                                                # the monitor ends after the run
    page.tick()

    src = page.src
    assert writers.forecast[0] == TRAIN[0] and len(writers.forecast) == round((STOP - TRAIN[0]) / STEP)
    np.testing.assert_array_equal(src["signal_recent"].data["time"], writers.forecast)
    judged = [t for t in writers.forecast if t >= TRAIN[1]]
    np.testing.assert_array_equal(src["forecast_recent"].data["time"], judged)
    np.testing.assert_array_equal(src["statistic"].data["time"], writers.evaluations)
    # no gap anywhere: consecutive rows one grid step apart
    for name in ("signal_recent", "forecast_recent", "statistic"):
        gaps = np.diff(np.asarray(src[name].data["time"]))
        assert gaps.max() < 1.5 * STEP, (name, float(gaps.max()))
    # the whole-run plot's last bin holds the monitor's last row, written after the run ended
    assert src["signal_overview"].data["time"][-1] > STOP - 1.0


def test_a_monitor_a_window_behind_still_shows_its_newest_rows(tmp_path):
    """The monitor's newest row more than a window behind the clock (trained late on a loaded
    machine): the recent plots show its newest rows, not an empty window, and the rest when
    they come."""
    from view.page import PageSettings, RunPage, SharedRun

    writers = Writers(tmp_path)
    page = RunPage(SharedRun(tmp_path, poll_s=0.0), PageSettings(window_s=5.0))
    writers.exchange(STOP)
    page.tick()                                     # the exchange's x2 column: no monitor yet
    writers.monitor(6.0)                            # 9 s behind the clock, the window is 5 s
    page.tick()
    assert page.clock == pytest.approx(STOP - STEP, abs=1e-9)
    shown = np.asarray(page.src["signal_recent"].data["time"])
    assert len(shown) and shown[-1] == pytest.approx(6.0 - STEP, abs=1e-9) and shown[0] > 1.0 - 1e-9
    writers.monitor(STOP)
    page.tick()
    shown = np.asarray(page.src["signal_recent"].data["time"])
    assert shown[-1] == pytest.approx(STOP - STEP, abs=1e-9) and np.diff(shown).max() < 1.5 * STEP


def test_a_new_run_in_a_replayed_folder_is_followed(tmp_path):
    """A page replaying a finished run, when a new run starts in the folder: the page starts
    again as if opened now, following the new run's newest row (not replaying it at 1x)."""
    from view.page import PageSettings, RunPage, SharedRun

    writers = Writers(tmp_path)
    writers.exchange(1.0)
    (tmp_path / "run.json").write_text(json.dumps(_record("finished", "a" * 32)))
    page = RunPage(SharedRun(tmp_path, poll_s=0.0), PageSettings())
    page.tick()
    assert not page.live and page.clock == 0.0                     # a finished run: replayed from its start
    (tmp_path / "exchange.csv").write_text("time,x2\n")            # fourbar-run replaces both files
    (tmp_path / "run.json").write_text(json.dumps(_record("running", "b" * 32)))
    writers.exchange_to = 0.0
    writers.exchange(3.0)
    page.tick()
    assert page.live and page.follow.value and page.clock == pytest.approx(3.0 - STEP, abs=1e-9)
