"""forecast.csv (the monitor's judged samples and their forecasts) and the training window in
events.jsonl, as the live view reads them.

The data: Case 2 (L2 +2 % at 10 s) for 20 s of simulated time on the native FMU, made once
by ``fourbar-run``.  Every file is parsed with Python's ``float`` (exact: the writers use
17 significant digits or ``repr``), so values are compared for equality, not closeness.
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from monitor import Monitor, MonitorOptions, follow, replay
from support import FOURBAR_MONITOR, FOURBAR_RUN, case_file

STOP = 20.0          # s of simulated time of the run
FAULT = 10.0         # s, Case 2's L2 step
HEADER = ["time", "signal", "value", "forecast"]


@pytest.fixture(scope="module")
def short_run(tmp_path_factory, native_fmu) -> Path:
    base = tmp_path_factory.mktemp("forecast_run")
    case = case_file("case2_fault_L2", native_fmu, base / "case2.toml")
    run = subprocess.run([FOURBAR_RUN, str(case), "--out", str(base / "run"), "--stop", str(STOP), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return base / "run" / "exchange.csv"


def read_exchange_exact(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array([[float(v) for v in r] for r in rows[1:]])


def read_forecast(path: Path) -> tuple[list[str], list[tuple[float, str, float, float]]]:
    """Header and rows of forecast.csv; an empty forecast is NaN."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], [(float(t), s, float(v), float(f) if f != "" else np.nan) for t, s, v, f in rows[1:]]


def per_signal(rows, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sel = [r for r in rows if r[1] == name]
    return (np.array([r[0] for r in sel]), np.array([r[2] for r in sel]), np.array([r[3] for r in sel]))


def events(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]


CASES = {
    "cusum-x2": dict(),                                                   # the defaults (Prophet)
    "cusum-3-signals": dict(signal="x2,y2,x4", model="harmonic"),
    "cusum-train-2-8": dict(model="harmonic", train=(2.0, 8.0)),
    "mae-x2": dict(detector="mae", model="harmonic"),
}


@pytest.mark.parametrize("settings", CASES.values(), ids=CASES.keys())
def test_forecast_csv_holds_every_judged_sample_with_its_forecast(short_run, tmp_path, settings):
    out = tmp_path / "m"
    result = replay(short_run, out_dir=out, plots=False, **settings)
    header, rows = read_forecast(out / "forecast.csv")
    assert header == HEADER
    names = result.options.signals
    trained = next(e for e in events(out) if e["event"] == "trained")
    start, end = trained["train_start"], trained["train_end"]

    columns, data = read_exchange_exact(short_run)
    t_ex = data[:, 0]
    judged = t_ex[t_ex >= result.options.train[0] - 1e-9]          # samples before the window are not used
    assert len(rows) == judged.size * len(names)
    # sample by sample, each sample's signals in the order of --signal
    assert [r[1] for r in rows[:2 * len(names)]] == list(names) * 2
    assert summary_of(out)["outputs"]["forecast"] == "forecast.csv"

    for j, name in enumerate(names):
        t, value, forecast = per_signal(rows, name)
        np.testing.assert_array_equal(t, judged)                   # one row per judged sample, in time order
        assert np.all(np.diff(t) > 0)
        np.testing.assert_array_equal(value, data[t_ex >= judged[0], columns.index(name)])   # as read, exactly
        training = t <= end + 1e-9
        assert t[0] == start and np.isnan(forecast[training]).all() and np.isfinite(forecast[~training]).all()
        # before the fault every signal's forecast is within its noise scale σ of its value (the
        # noise-free model error is µm, σ ≥ 0.1 % of the amplitude): a forecast written under
        # another column's name, or one sample off, misses by millimetres or more
        healthy = ~training & (t < FAULT)
        sigma = trained["noise_sigma"][name] if "noise_sigma" in trained else 5e-4   # mae: cusum's x2 floor
        assert np.abs(value[healthy] - forecast[healthy]).max() < sigma
        assert np.abs(value[t > FAULT + 1.0] - forecast[t > FAULT + 1.0]).max() > 100 * sigma   # the fault shows

    # the first signal's rows are the history's (not decimated: 2001 samples < history_points)
    t, value, forecast = per_signal(rows, names[0])
    h = result.history
    np.testing.assert_array_equal(h["time"].to_numpy(), t)
    np.testing.assert_array_equal(h[names[0]].to_numpy(), value)
    # repr round-trips, so the forecast is the history's to the last bit
    np.testing.assert_array_equal(h["forecast"].to_numpy(), forecast)


def summary_of(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("settings", [dict(), dict(detector="mae", model="harmonic"),
                                      dict(model="harmonic", train=(2.0, 8.0))], ids=["cusum", "mae", "train-2-8"])
def test_the_trained_event_names_the_training_window(short_run, tmp_path, settings):
    out = tmp_path / "m"
    result = replay(short_run, out_dir=out, plots=False, **settings)
    trained = [e for e in events(out) if e["event"] == "trained"]
    assert len(trained) == 1
    e = trained[0]
    s = summary_of(out)
    lo, hi = result.options.train
    assert 0.0 <= e["train_start"] < e["train_end"] <= s["last_time"]
    # the samples actually used: the first at or after the window's start, and its end
    assert e["train_start"] == pytest.approx(lo, abs=1e-9) and e["train_end"] == hi == e["time"]
    assert (e["train_start"], e["train_end"]) == (s["fits"][0]["train_start"], s["fits"][0]["train_end"])


def test_refits_name_their_window_and_the_forecast_follows_the_new_model(short_run, tmp_path):
    """mae with refit="paper" and a threshold nothing meets: it refits at each evaluation until
    max_refits, then alarms.  Each refit event names the window of the model it fits, and each
    sample's forecast is the model in force when it was judged, however the samples come."""
    out = tmp_path / "m"
    settings = dict(detector="mae", model="harmonic", refit="paper", threshold=1e-9, max_refits=3)
    result = replay(short_run, out_dir=out, plots=False, **settings)
    log = events(out)
    refits = [e for e in log if e["event"] == "refit"]
    trained = [e for e in log if e["event"] == "trained"]
    fits = summary_of(out)["fits"]
    assert len(refits) == 3 and len(trained) == 4 and len(fits) == 4
    columns, data = read_exchange_exact(short_run)
    t_ex = data[:, 0]
    o = result.options
    for refit, after, fit in zip(refits, trained[1:], fits[1:]):
        upto = t_ex[t_ex <= refit["time"] + 1e-9]
        assert refit["train_end"] == refit["time"] == after["train_end"] == fit["train_end"]
        assert refit["train_start"] == upto[-o.settings.refit_samples:][0] == after["train_start"] == fit["train_start"]

    _, rows = read_forecast(out / "forecast.csv")
    t, value, forecast = per_signal(rows, "x2")
    ends = [f.end for f in result.fits] + [np.inf]
    for k, fit in enumerate(result.fits):
        sel = (t > ends[k] + 1e-9) & (t <= ends[k + 1] + 1e-9)
        assert sel.sum() >= 40
        # the same model evaluated on another array: equal up to the round-off of sin/cos
        np.testing.assert_allclose(forecast[sel], fit.forecaster.predict(t[sel]), rtol=0, atol=1e-12)

    # fed 37 samples at a time (as a follower reads): the same rows
    got = []
    mon = Monitor(MonitorOptions(**settings), on_samples=lambda tt, xx, ff: got.append(np.column_stack([tt, xx, ff])))
    x2 = data[:, columns.index("x2")]
    for i in range(0, t_ex.size, 37):
        mon.feed(t_ex[i:i + 37], x2[i:i + 37])
    np.testing.assert_array_equal(np.vstack(got), np.column_stack([t, value, forecast]))


def test_a_new_session_replaces_the_old_forecast(short_run, tmp_path):
    out = tmp_path / "m"
    replay(short_run, out_dir=out, plots=False, signal="x2,y2", model="harmonic")
    _, before = read_forecast(out / "forecast.csv")
    assert {r[1] for r in before} == {"x2", "y2"}
    replay(short_run, out_dir=out, plots=False, signal="x4", model="harmonic")
    header, rows = read_forecast(out / "forecast.csv")
    assert header == HEADER and {r[1] for r in rows} == {"x4"} and len(rows) == len(before) // 2


def test_a_replaced_exchange_file_restarts_the_forecast(short_run, tmp_path):
    """The first 15 s of the run, then a new file with all of it renamed over it (new inode, as an
    atomic writer does): forecast.csv starts again and ends as a replay of the new file writes it."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    path = run_dir / "exchange.csv"
    lines = short_run.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:1 + 1501]))                  # header + 0 ... 15 s
    (run_dir / "run.json").write_text(json.dumps({"schema": 1, "status": "running", "fault_time": FAULT,
                                                  "events": [], "error": None}))
    seen = {}

    def rewrite():
        seen["rows before"] = len(read_forecast(tmp_path / "m" / "forecast.csv")[1])
        fresh = run_dir / "exchange.csv.new"                        # a new file renamed over the old one
        fresh.write_bytes(b"".join(lines))
        os.replace(fresh, path)
        (run_dir / "run.json").write_text(json.dumps({"schema": 1, "status": "finished", "fault_time": FAULT,
                                                      "events": [], "error": None}))

    actions = [rewrite]

    def script(seconds):
        if actions:
            actions.pop(0)()

    r = follow(path, poll=0.01, timeout=30, sleep=script, out_dir=tmp_path / "m", plots=False, model="harmonic")
    assert r.summary.restarts == 1 and seen["rows before"] == 1501
    replay(path, out_dir=tmp_path / "replayed", plots=False, model="harmonic")
    assert (tmp_path / "m" / "forecast.csv").read_bytes() == (tmp_path / "replayed" / "forecast.csv").read_bytes()


def _rows(path: Path) -> int:
    try:
        return path.read_bytes().count(b"\n") - 1
    except FileNotFoundError:
        return -1


def _wait_for(condition, seconds: float) -> bool:
    """Poll ``condition`` until it holds (True) or ``seconds`` pass (False): a hang guard only."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_forecast_csv_grows_while_a_live_run_is_followed(tmp_path, native_fmu):
    """fourbar-monitor --follow (x2 and y2) on Case 2 run at 5x real time (20 s of data in 4 s,
    a block of 1 s of data every 0.2 s): forecast.csv appears when the training ends (9 s of
    data) and grows block by block; in the end it is what a replay of the finished file writes.

    The test holds the run (SIGSTOP; its process stays alive, so the follower does not call it
    lost) after 11, 14 and 17 s of data until the monitor has written forecast rows for what it
    has read, so the growth is seen while the run is still writing however slow the machine is."""
    case = case_file("case2_fault_L2", native_fmu, tmp_path / "case2.toml")
    run_dir = tmp_path / "live"
    mon_dir = tmp_path / "followed"
    err = open(tmp_path / "monitor.err", "w")
    monitor = subprocess.Popen([FOURBAR_MONITOR, str(run_dir / "exchange.csv"), "--follow", "--poll", "0.05",
                                "--timeout", "120", "--out", str(mon_dir), "--no-plots", "--model", "harmonic",
                                "--signal", "x2,y2"],
                               stdout=subprocess.PIPE, stderr=err, text=True)
    printed: list[str] = []
    waiting = threading.Event()

    def read_out():
        for line in monitor.stdout:
            printed.append(line)
            if "waiting for" in line:
                waiting.set()

    threading.Thread(target=read_out, daemon=True).start()
    counts = []
    try:
        assert waiting.wait(120), printed
        run = subprocess.Popen([FOURBAR_RUN, str(case), "--out", str(run_dir), "--realtime", "5", "--stop", str(STOP),
                                "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            for hold in (11.0, 14.0, 17.0):       # s of data: after the training window (9 s)
                rows = int(hold / 0.01) + 1
                assert _wait_for(lambda: _rows(run_dir / "exchange.csv") >= rows or run.poll() is not None, 120)
                run.send_signal(signal.SIGSTOP)
                before = max(counts, default=0)
                # 120 s: a hang guard; the monitor catches up with what was written in well under 1 s idle
                grew = _wait_for(lambda: counts.append(_rows(mon_dir / "forecast.csv")) or counts[-1] > before, 120)
                run.send_signal(signal.SIGCONT)
                assert grew and run.poll() is None, (hold, counts[-5:], printed)
        finally:
            run.send_signal(signal.SIGCONT)
        while run.poll() is None:
            counts.append(_rows(mon_dir / "forecast.csv"))
            time.sleep(0.05)
        assert run.returncode == 0, run.communicate()[1]
        assert monitor.wait(timeout=120) == 1, printed             # Case 2 alarms
    finally:
        if monitor.poll() is None:
            monitor.kill()
            monitor.wait()
        err.close()
    assert "Traceback" not in (tmp_path / "monitor.err").read_text()
    growing = sorted({c for c in counts if c > 0})
    # rows came in several steps while the run was still writing (at least one per hold)
    assert len(growing) >= 3, counts
    assert counts == sorted(counts)                                # never shrinks
    replay(run_dir / "exchange.csv", out_dir=tmp_path / "replayed", plots=False, model="harmonic", signal="x2,y2")
    assert (mon_dir / "forecast.csv").read_bytes() == (tmp_path / "replayed" / "forecast.csv").read_bytes()
    assert _rows(mon_dir / "forecast.csv") == 2 * (int(STOP / 0.01) + 1)
