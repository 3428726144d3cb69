"""The static plots, checked through their matplotlib objects (issue 25).

One real run is shared: Case 2 (L2 1.0 -> 1.1 m at 10 s) cut at 20 s on the native FMU,
monitored with the harmonic model (the plots do not depend on the model) and diagnosed.
For the sweep plots, four scenarios of a small sweep (L2 +0.5 % and +2 % at 10 s, noise 0
and 5 mm) are run in this process with :func:`sweep.scenario.run_scenario`.

Checked: history.png draws the fault and the first alarm as distinct lines with their times,
the fault on top, and zooms on them (not on the training window); the forecast band is the
detector's noise scale; statistic.png draws a CUSUM of 0 at 0 and shades a latched alarm
from the alarm's own time; diagnosis.png marks the estimated change time and the alarm,
writes units as "(m)" and keeps its legend off the data; detection.png names the detector;
delay_arl0.png and detection.png give the same delays at the designed ARL0 for the same runs.
"""
from __future__ import annotations

import os
import subprocess

import numpy as np
import pytest

from support import FOURBAR_RUN, case_file

FAULT, ALARM = 10.0, 10.01          # Case 2's fault time (run.json) and first alarm (the first changed row)
TIME_TOL = 1e-9                     # times are read back from floats written with repr


@pytest.fixture(scope="module")
def case2(tmp_path_factory, native_fmu):
    """(MonitorResult, run folder) of Case 2 cut at 20 s, monitored into run/monitor."""
    from monitor import replay

    work = tmp_path_factory.mktemp("static_plots")
    case = case_file("case2_fault_L2", native_fmu, work)
    run = work / "run"
    subprocess.run([FOURBAR_RUN, str(case), "--out", str(run), "--stop", "20", "--quiet"], check=True, timeout=120)
    result = replay(run / "exchange.csv", out_dir=run / "monitor", plots=False, model="harmonic")
    assert result.first_alarm_time == pytest.approx(ALARM, abs=TIME_TOL) and result.fault_time == FAULT
    return result, run


@pytest.fixture(scope="module")
def figures(case2):
    from monitor.outputs import plot_figures

    return plot_figures(case2[0])


def _by_gid(ax, gid):
    return [a for a in ax.get_children() if a.get_gid() == gid]


def _vline_x(line) -> float:
    x = np.unique(np.asarray(line.get_xdata(), dtype=float))
    assert x.size == 1, "a vertical line"
    return float(x[0])


def _x_extent(patch) -> tuple[float, float]:
    """The data x-range of an axvspan (a Polygon or a Rectangle, x in data units)."""
    xy = patch.get_patch_transform().transform(patch.get_path().vertices)
    return float(xy[:, 0].min()), float(xy[:, 0].max())


def _legend_texts(fig) -> list[str]:
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return [t.get_text() for lg in legends for t in lg.get_texts()]


# ------------------------------------------------------------------------------ history.png

def test_history_draws_fault_and_alarm_distinct_with_their_times(figures):
    fig = figures["history.png"]
    for ax in fig.axes:
        (fault,), (alarm,) = _by_gid(ax, "fault"), _by_gid(ax, "alarm")
        assert _vline_x(fault) == pytest.approx(FAULT, abs=TIME_TOL)
        assert _vline_x(alarm) == pytest.approx(ALARM, abs=TIME_TOL)
        # 0.01 s apart: told apart by style, the fault (thinner, dashed) drawn over the alarm
        assert fault.get_color() != alarm.get_color() and fault.get_linestyle() != alarm.get_linestyle()
        assert fault.get_zorder() > alarm.get_zorder() and fault.get_linewidth() < alarm.get_linewidth()
    texts = _legend_texts(fig)
    assert any(t.startswith("fault 10 s") for t in texts), texts
    assert any(t.startswith("first alarm 10.01 s") for t in texts), texts


def test_history_zooms_on_the_alarm_not_the_training(case2, figures):
    result = case2[0]
    (zoom,) = [ax for ax in figures["history.png"].axes if ax.get_gid() == "zoom"]
    lo, hi = zoom.get_xlim()
    fit = result.fits[0]
    assert lo >= fit.end - TIME_TOL, (lo, fit.end)         # not the training window
    assert lo < FAULT and hi > ALARM
    assert hi - lo <= 6 * fit.estimate.period              # a few periods, not the run


def test_history_zoom_without_fault_or_alarm_follows_the_training(case2):
    from dataclasses import replace

    from monitor.outputs import ZOOM_PERIODS_AFTER, ZOOM_PERIODS_BEFORE, zoom_window

    result = case2[0]
    healthy = replace(result, summary=replace(result.summary, alarm_events=(), run=None))   # no alarm, no fault time
    fit = result.fits[0]
    lo, hi = zoom_window(healthy)
    assert lo == pytest.approx(fit.end, abs=TIME_TOL)
    wanted = fit.end + (ZOOM_PERIODS_BEFORE + ZOOM_PERIODS_AFTER) * fit.estimate.period   # 24.3 s: one signal's period
    assert hi == pytest.approx(min(wanted, float(result.history["time"].iloc[-1])), rel=1e-12)  # cut to the data (20 s)


def test_history_band_is_the_detectors_noise_scale(case2, figures):
    result = case2[0]
    sigma = next(e for e in result.events if e["event"] == "trained")["noise_sigma"]["x2"]
    (zoom,) = [ax for ax in figures["history.png"].axes if ax.get_gid() == "zoom"]
    (band,) = _by_gid(zoom, "forecast-band")
    v = band.get_paths()[0].vertices
    v = v[np.isfinite(v).all(axis=1)]
    at = v[np.isclose(v[:, 0], 12.0, atol=1e-9)]           # the band's two edges at t = 12 s
    assert at.shape[0] >= 2
    assert at[:, 1].max() - at[:, 1].min() == pytest.approx(2 * sigma, rel=1e-9)   # float sums only
    assert f"{sigma:.3g}" in band.get_label()


# ---------------------------------------------------------------------------- statistic.png

def test_statistic_draws_zero_at_zero(case2, figures):
    ev = case2[0].evaluations
    zero_times = ev["time"][ev["statistic"] == 0].to_numpy()
    assert zero_times.size > 5                              # the CUSUM rests at 0 before the fault
    for ax in figures["statistic.png"].axes:
        (line,) = _by_gid(ax, "statistic")
        x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
        shown = np.isin(np.round(x, 9), np.round(zero_times, 9))
        assert shown.any() and (y[shown] == 0).all()        # not clipped to a floor
        assert ax.get_yscale() != "log"                     # a log axis cannot show 0
        bottom = ax.get_ylim()[0]
        assert bottom <= 0                                  # 0 is on the axis, at its bottom
        assert np.isfinite(ax.transData.transform((zero_times[0], 0.0))).all()


def test_statistic_shading_starts_at_the_alarm(figures):
    for ax in figures["statistic.png"].axes:
        spans = _by_gid(ax, "alarm-latched")
        assert len(spans) == 1
        start, end = _x_extent(spans[0])
        assert start == pytest.approx(ALARM, abs=TIME_TOL)   # the alarm event, not the next evaluation (10.1 s)
        assert end == pytest.approx(20.0, abs=TIME_TOL)      # latched to the end of the run
        (alarm,) = _by_gid(ax, "alarm")
        assert _vline_x(alarm) == pytest.approx(start, abs=TIME_TOL)


# --------------------------------------------------------------- log axes, statistic and spectrum

_SUPERSCRIPTS = {c: d for c, d in zip("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-")}


def _label_value(text: str) -> float:
    """The number a plain-text log label says: ``0``, ``10⁻³``, ``2×10⁴`` (a minus as ``−``)."""
    sign = -1.0 if text.startswith("−") else 1.0
    text = text.lstrip("−")
    coeff, _, power = text.rpartition("×") if "×" in text else ("1", "", text)
    if power == "0":
        return 0.0
    assert power.startswith("10"), text
    return sign * float(coeff) * 10.0 ** int("".join(_SUPERSCRIPTS[c] for c in power[2:]))


def test_log_axes_are_labelled_in_plain_text(figures):
    """The statistic's (symlog) and the spectrum's (log) axes say their decades in plain text:
    no mathtext, whose parser a fresh process builds in about 0.15 s of CPU (docs/benchmarks.md),
    and each label the value of its tick."""
    import matplotlib.mathtext

    parsed = []
    parse = matplotlib.mathtext.MathTextParser.parse
    matplotlib.mathtext.MathTextParser.parse = lambda self, s, *a, **k: parsed.append(s) or parse(self, s, *a, **k)
    try:
        for name in ("statistic.png", "spectrum.png"):
            figures[name].canvas.draw()
    finally:
        matplotlib.mathtext.MathTextParser.parse = parse
    assert parsed == []
    log_axes = [ax for name in ("statistic.png", "spectrum.png") for ax in figures[name].axes
                if ax.get_yscale() in ("log", "symlog")]
    assert len(log_axes) == 3
    for ax in log_axes:
        ticks = [(tick.get_loc(), tick.label1.get_text()) for tick in ax.yaxis.get_major_ticks()
                 if tick.label1.get_visible() and tick.label1.get_text()]
        assert len(ticks) >= 3
        for loc, text in ticks:
            assert _label_value(text) == pytest.approx(loc, rel=1e-12, abs=0), (text, loc)  # decades, exactly


def test_write_plots_starts_no_cycle_collection(case2, tmp_path):
    """Drawing the figures starts no garbage-collector pass (before: about 100, each would walk every object the
    process holds: 0.2 s of a fresh monitor's CPU, docs/benchmarks.md), and collection is on
    again after, also when a write fails."""
    import gc

    from monitor.errors import OutputWriteError
    from monitor.outputs import PLOT_FILES, write_plots

    import sys

    passes = []       # collections started from inside matplotlib (importing, building, drawing)

    def count(phase, info):
        frame = sys._getframe(1)
        while phase == "start" and frame is not None:
            if f"{os.sep}matplotlib{os.sep}" in frame.f_code.co_filename:
                passes.append((info["generation"], frame.f_code.co_name))
                return
            frame = frame.f_back

    gc.callbacks.append(count)
    try:
        paths = write_plots(case2[0], tmp_path / "plots")
        assert passes == [] and gc.isenabled()
        (tmp_path / "bad" / PLOT_FILES[0]).mkdir(parents=True)    # a folder where a PNG should be
        with pytest.raises(OutputWriteError):
            write_plots(case2[0], tmp_path / "bad")
    finally:
        gc.callbacks.remove(count)
    assert gc.isenabled()
    assert [p.name for p in paths] == list(PLOT_FILES) and all(p.stat().st_size > 0 for p in paths)


def test_plain_label_keeps_what_it_cannot_write():
    from monitor.log_labels import plain_label

    assert plain_label(r"$\mathdefault{10^{-3}}$") == "10⁻³"
    assert plain_label(r"$\mathdefault{-2\times10^{14}}$") == "−2×10¹⁴"
    assert plain_label(r"$\mathdefault{0}$") == "0"
    assert plain_label("") == ""
    assert plain_label(r"$\mathdefault{\sqrt{2}}$") == r"$\mathdefault{\sqrt{2}}$"    # left to mathtext


# ---------------------------------------------------------------------------- diagnosis.png

@pytest.fixture(scope="module")
def diagnosis(case2):
    from diagnose import diagnose

    return diagnose(case2[1])


def test_diagnosis_marks_the_change_and_keeps_the_legend_off_the_data(diagnosis):
    from diagnose.outputs import diagnosis_figure

    d = diagnosis
    assert d.verdict == "explained" and d.best.parameter == "L2"
    fig = diagnosis_figure(d)
    fig.canvas.draw()
    for ax in fig.axes:
        (change,), (alarm,) = _by_gid(ax, "change"), _by_gid(ax, "alarm")
        assert _vline_x(change) == pytest.approx(d.best.change_time, abs=TIME_TOL)
        assert _vline_x(alarm) == pytest.approx(d.alarm_time, abs=TIME_TOL)
        assert change.get_zorder() > alarm.get_zorder()
    texts = _legend_texts(fig)
    assert f"estimated change {d.best.change_time:.2f} s" in texts and f"first alarm {d.alarm_time:g} s" in texts
    renderer = fig.canvas.get_renderer()
    for legend in [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]:
        box = legend.get_window_extent(renderer)
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent(renderer)), "a legend covers an axes"
    labels = [ax.get_ylabel() for ax in fig.axes] + [fig.axes[-1].get_xlabel()]
    assert "x2 (m)" in labels and "time (s)" in labels
    assert not any("[" in label for label in labels), labels


# ------------------------------------------------------------------------------- sweep plots

SWEEP = """
name = "static-plots"
case = "{case}"
stop = 20.0
[fault]
variable = "L2"
kind = "step"
relative = [0.005, 0.02]
time = 10.0
no_fault = false
[noise]
std = [0.0, 0.005]
seed = 1
[monitor]
signal = "x2"
model = "harmonic"
threshold = "auto"
[report]
latency_limit = 2.0
"""


@pytest.fixture(scope="module")
def sweep_table(tmp_path_factory, native_fmu):
    """(results table, the sweep's DetectorDesign) of 4 scenarios run in this process."""
    from sweep import load_sweep, plan_scenarios
    from sweep.report import DetectorDesign
    from sweep.results import table_from_rows
    from sweep.scenario import run_scenario

    work = tmp_path_factory.mktemp("static_sweep")
    case = case_file("case1_normal", native_fmu, work)
    path = work / "sweep.toml"
    path.write_text(SWEEP.format(case=case.as_posix()))
    sweep = load_sweep(path)
    monitor = dict(sweep.monitor.options)
    rows = [run_scenario(s, sweep.case, str(work / s.id), monitor, latency_limit=sweep.latency_limit)
            for s in plan_scenarios(sweep)]
    assert [r["status"] for r in rows] == ["ok"] * 4, [r["error"] for r in rows]
    return table_from_rows(rows), DetectorDesign.from_options(monitor)


def test_detection_legend_names_the_detector(sweep_table):
    from sweep.report import detection_figure, summarize

    table, design = sweep_table
    assert design.name == "cusum" and design.arl0_hours == pytest.approx(100.0)    # 0.01 false alarms/h
    h = float(table["threshold_base"].iloc[0])
    texts = _legend_texts(detection_figure(summarize(table, 2.0, unit="m", detector=design)))
    assert len(texts) == 2
    for text in texts:
        assert f"CUSUM h {h:.4g} (ARL0 100 h)" in text and "threshold auto" not in text


def test_delays_at_the_designed_arl0_are_the_alarm_latencies(sweep_table):
    from sweep.report import delay_arl0_figure, delay_curves, detection_figure, run_delays, summarize
    from sweep.scenario import delay_column

    table, design = sweep_table
    column = delay_column(design.arl0_hours)
    latency = table["latency"].to_numpy(dtype=float)
    grid = table[column].to_numpy(dtype=float)
    assert np.isfinite(latency).all() and np.isfinite(grid).all()
    # the cause of the old disagreement: the evaluation grid (0.1 s) rounds each latency up
    assert (grid >= latency - TIME_TOL).all() and (grid < latency + design.every + TIME_TOL).all()
    assert (grid > latency + TIME_TOL).any()
    np.testing.assert_allclose(run_delays(table)[column].to_numpy(float), latency, rtol=0, atol=TIME_TOL)

    # the figures: for each series and size, delay_arl0.png's point at the designed ARL0 is
    # detection.png's median latency
    summary = summarize(table, 2.0, unit="m", detector=design)
    curves = delay_curves(table, "m", design)
    for s in summary["series"]:
        for e in s["sizes"]:
            (c,) = [c for c in curves if c["series"] == s["series"] and c["relative_change"] == e["relative_change"]]
            assert c["median_delay"][c["arl0_hours"].index(design.arl0_hours)] == \
                pytest.approx(e["median_latency"], abs=TIME_TOL)
    right = detection_figure(summary).axes[1]
    delay_fig = delay_arl0_figure(table, unit="m", detector=design)
    for s in summary["series"]:
        (latency_line,) = _by_gid(right, f"latency: {s['series']}")
        (ax,) = [ax for ax in delay_fig.axes if ax.get_title() == s["series"]]
        (designed,) = _by_gid(ax, "designed-arl0")
        assert _vline_x(designed) == pytest.approx(design.arl0_hours)
        for size, plotted in zip(latency_line.get_xdata(), latency_line.get_ydata()):
            (line,) = [ln for ln in ax.get_lines() if (ln.get_gid() or "").startswith("delay: ")
                       and float(ln.get_gid()[7:]) == pytest.approx(size / 100, rel=1e-12)]   # % back to a ratio
            x = np.asarray(line.get_xdata(), float)
            y = np.asarray(line.get_ydata(), float)
            assert y[np.isclose(x, design.arl0_hours)] == pytest.approx([plotted], abs=TIME_TOL)
