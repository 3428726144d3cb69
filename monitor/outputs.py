"""Output files of the monitor, in ``--out DIR`` (default: :func:`default_out_dir`).

``events.jsonl``
    One JSON object per line, written as it happens: ``time`` (simulated s), ``event``
    (``trained`` | ``stable`` | ``refit`` | ``alarm`` | ``clear``), ``state``, ``statistic``
    (the MAE or the CUSUM statistic), ``threshold``, ``message`` (the paper's sentence for an alarm), and for ``trained`` the
    period, model and threshold settings and ``train_start``, ``train_end`` (s, the window
    the model was fitted on; a ``refit`` event names its window too); ``wall`` is the
    wall-clock time (ISO 8601).
``evaluations.csv``
    ``time,statistic,threshold,state``: every evaluation, written as it happens (cusum:
    the largest CUSUM statistic of the interval; mae: the window's MAE).
``forecast.csv``
    ``time,signal,value,forecast``, long format: one row per monitored column per judged
    sample (the training window's samples, then every later one), ``value`` the sample as
    read, ``forecast`` what the detector compared it with when it judged it (cusum: the
    phase-locked forecast with its shape correction; mae: the model's forecast), empty for
    the training samples.  The training rows come when the training ends, later rows as
    each batch of samples is judged; the file is flushed after every batch, so it is at most
    one read behind ``evaluations.csv``.  Floats are written with ``repr`` (shortest text
    that reads back to the same double).
``summary.json``
    Written at the end (atomically): periods (FFT and refined), model settings, fit time,
    validation MAE, threshold rule, first alarm, fault time from run.json, detection latency,
    false alarms before the fault, skipped-row counts, timings.
``history.png``, ``statistic.png``, ``spectrum.png``
    The paper's Fig. 9-13 views: data and forecast with the training window shaded (full
    run and a zoom on the alarm), MAE against the threshold with the alarm marked, and the
    spectrum of the training window with the FFT and refined periods.

When the exchange file is replaced while following, ``events.jsonl``,
``evaluations.csv`` and ``forecast.csv`` start again with the new file.  A new session in a folder removes the
``summary.json`` and plots an earlier one left there as it starts writing, so a session
stopped by a signal before its summary leaves only its own (partial) events and evaluations.
"""
from __future__ import annotations

import datetime as _dt
import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fourbar_common import output_folder_problem, write_json_atomic

from .detector import ALARM_MESSAGE, Event, State
from .errors import OutputDirError

if TYPE_CHECKING:  # pragma: no cover
    from .summary import MonitorResult

__all__ = ["FORECAST_HEADER", "OUTPUT_FILES", "OutputWriters", "PLOT_FILES", "checked_default_out_dir",
           "checked_out_dir", "default_out_dir", "jsonable", "write_plots"]

PLOT_FILES = ("history.png", "statistic.png", "spectrum.png")
#: Every file the monitor writes into its output folder.
OUTPUT_FILES = ("events.jsonl", "evaluations.csv", "forecast.csv", "summary.json", *PLOT_FILES)
#: The header of forecast.csv.
FORECAST_HEADER = "time,signal,value,forecast\n"


def default_out_dir(exchange_path: str | os.PathLike[str]) -> Path:
    """Where the outputs go without ``--out``.

    ``<dir>/monitor`` for fourbar-run's ``<dir>/exchange.csv``; ``<dir>/<stem>.monitor``
    for any other file (``case2_libcosim.csv`` → ``case2_libcosim.monitor``): a name with
    a dot, which no Python package (so none of this project's source folders) can have.
    """
    path = Path(exchange_path)
    return path.parent / ("monitor" if path.name == "exchange.csv" else f"{path.stem}.monitor")


def checked_default_out_dir(exchange_path: str | os.PathLike[str]) -> Path:
    """:func:`default_out_dir`, refused when it exists and holds anything the monitor did not write."""
    out = default_out_dir(exchange_path)
    if out.is_dir():
        foreign = sorted(p.name for p in out.iterdir()
                         if p.name not in OUTPUT_FILES and not (p.name.startswith(".") and p.name.endswith(".tmp")))
        if foreign:
            shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
            raise OutputDirError(f"{out}: the default output folder holds files the monitor did not write "
                                 f"({shown}); choose a folder with --out")
    elif out.exists():
        raise OutputDirError(f"{out}: the default output folder is a file; choose a folder with --out")
    return out


def checked_out_dir(out_dir: str | os.PathLike[str]) -> Path:
    """An output folder given with ``--out``, refused (:class:`OutputDirError`) when it is a
    file, cannot be created where it is, or cannot be written.  Nothing is created here: the
    folder is made once the input has been accepted."""
    out = Path(out_dir)
    problem = output_folder_problem(out, f"{', '.join(OUTPUT_FILES[:4])} and the plots")
    if problem is not None:
        raise OutputDirError(f"--out {out}: {problem}")
    return out


def jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays, Paths and non-finite floats (→ None) for JSON."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, State):
        return value.value
    return value


class OutputWriters:
    """The files of one monitor session; events, evaluations and forecasts are streamed.

    ``signals`` are the monitored columns, in the order of the forecast rows' columns.
    """

    def __init__(self, out_dir: Path, signals: tuple[str, ...]):
        self.out_dir = Path(out_dir)
        self.signals = tuple(signals)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        # The summary and plots of an earlier session here describe other data: removed, so a
        # session that is stopped before its own summary does not leave them beside its events.
        for name in ("summary.json", *PLOT_FILES):
            (self.out_dir / name).unlink(missing_ok=True)
        opened = []
        try:
            for name in ("events.jsonl", "evaluations.csv", "forecast.csv"):
                opened.append(open(self.out_dir / name, "w", encoding="utf-8"))
        except BaseException:
            for fh in opened:
                fh.close()
            raise
        self._events, self._evals, self._forecast = opened
        self._headers()

    def _headers(self) -> None:
        self._evals.write("time,statistic,threshold,state\n")
        self._forecast.write(FORECAST_HEADER)
        for fh in (self._events, self._evals, self._forecast):
            fh.flush()

    def event(self, e: Event) -> None:
        d = e.as_dict()
        d["wall"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")
        self._events.write(json.dumps(jsonable(d), allow_nan=False) + "\n")
        self._events.flush()

    def evaluation(self, t: float, statistic: float, threshold: float, state: State) -> None:
        self._evals.write(f"{t!r},{statistic!r},{threshold!r},{state.value}\n")
        self._evals.flush()

    def forecast(self, t: np.ndarray, x: np.ndarray, f: np.ndarray) -> None:
        """Rows of judged samples: times ``t``, values ``x`` and forecasts ``f`` (one column per signal)."""
        names = self.signals
        if x.shape[1] != len(names) or f.shape != x.shape:
            raise ValueError(f"forecast rows: {x.shape[1]} value and {f.shape} forecast columns for "
                             f"{len(names)} signals")
        # repr of a Python float is the shortest text that reads back to the same double
        tt = [repr(v) for v in np.asarray(t, dtype=float).tolist()]
        lines = []
        for j, name in enumerate(names):
            xs = [repr(v) for v in x[:, j].tolist()]
            fs = ["" if v != v else repr(v) for v in f[:, j].tolist()]     # NaN (v != v): no forecast
            lines.append([f"{a},{name},{b},{c}\n" for a, b, c in zip(tt, xs, fs)])
        # sample by sample, each sample's signals together
        self._forecast.write("".join(lines[0]) if len(lines) == 1 else "".join(map("".join, zip(*lines))))
        self._forecast.flush()

    def restart(self) -> None:
        for fh in (self._events, self._evals, self._forecast):
            fh.seek(0)
            fh.truncate()
        self._headers()

    def finish(self, result: "MonitorResult", plots: bool = True) -> None:
        for fh in (self._events, self._evals, self._forecast):
            fh.flush()
        summary = result.summary.as_json()
        summary["outputs"] = {"events": "events.jsonl", "evaluations": "evaluations.csv", "forecast": "forecast.csv",
                              "plots": list(PLOT_FILES) if plots and result.fits else []}
        write_json_atomic(self.out_dir / "summary.json", jsonable(summary))
        if plots and result.fits:
            write_plots(result, self.out_dir)

    def close(self) -> None:
        for fh in (self._events, self._evals, self._forecast):
            fh.close()


def write_plots(result: "MonitorResult", out_dir: str | os.PathLike[str]) -> list[Path]:
    """Write history.png, statistic.png and spectrum.png for ``result``; return their paths."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fn in zip(PLOT_FILES, (_plot_history, _plot_statistic, _plot_spectrum)):
        fig = Figure(figsize=(10, 6.8), dpi=100)
        fn(fig, result)
        path = out / name
        fig.savefig(path)
        paths.append(path)
    return paths


def _unit(result: "MonitorResult") -> str:
    """The monitored signal's unit from run.json (the FMU's declaration), or "" when unknown."""
    run = result.summary.run
    return (run.units.get(result.options.signals[0], "") if run is not None else "") or ""


def _label(result: "MonitorResult", what: str) -> str:
    unit = _unit(result)
    return f"{what} ({unit})" if unit else what


def _marks(ax: Any, result: "MonitorResult", label: bool = True) -> None:
    s = result.summary
    if s.fault_time is not None:
        ax.axvline(s.fault_time, color="0.3", ls="--", lw=1.0,
                   label=f"fault (run.json) {s.fault_time:g} s" if label else None)
    times = [e.time for e in s.alarm_events]
    for i, t in enumerate(times[:50]):
        ax.axvline(t, color="red", lw=1.2 if i == 0 else 0.6, alpha=1.0 if i == 0 else 0.4,
                   label=(f"first alarm {t:g} s" if i == 0 else None) if label else None)


def _plot_history(fig: Any, result: "MonitorResult") -> None:
    h = result.history
    sig = result.options.signals[0]
    fit = result.fits[0]
    axes = fig.subplots(2, 1)
    t = h["time"].to_numpy()
    x = h[sig].to_numpy()
    f = h["forecast"].to_numpy()
    s = result.summary
    first = s.first_alarm_time
    fault = s.fault_time
    forecast_name = result.options.detector_class.plot_text(result.options, fit).forecast
    if first is not None:
        lo = fit.start
        hi = max(first, fault or first) + 4.0
    else:
        lo, hi = fit.start, fit.end + 11.0
    # in-sample fit over the training window, for the paper's Fig. 9 view
    train = (t >= fit.start) & (t <= fit.end)
    fitted = np.full(t.size, np.nan)
    if train.any():
        fitted[train] = fit.forecaster.predict(t[train])
    for ax, (a, b), title in ((axes[0], (t[0] if t.size else 0, t[-1] if t.size else 1), "whole run"),
                              (axes[1], (lo, hi), "zoom")):
        m = (t >= a) & (t <= b)
        ax.plot(t[m], x[m], color="tab:blue", lw=0.9, zorder=3, label=f"{sig} (exchange file)")
        ax.plot(t[m], fitted[m], color="tab:green", lw=1.2, ls="--", zorder=4, label="model on training data")
        ax.plot(t[m], f[m], color="tab:orange", lw=1.2, ls="--", zorder=4,
                label=f"{forecast_name} ({fit.forecaster.kind})")
        for i, ft in enumerate(result.fits):
            ax.axvspan(ft.start, ft.end, color="tab:green", alpha=0.12,
                       label=f"training {ft.start:g}–{ft.end:g} s" if i == 0 else None)
        _marks(ax, result)
        ax.set_xlim(a, b)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(_label(result, sig))
        ax.grid(alpha=0.3)
        ax.set_title(f"{sig}: data and forecast — {title}", fontsize=10)
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", fontsize=8, ncol=4, frameon=False)
    fig.subplots_adjust(left=0.08, right=0.98, top=0.9, bottom=0.15, hspace=0.45)
    fig.suptitle(f"{s.case}: {fit.forecaster.kind} model, period {fit.estimate.period:.6g} s, "
                 f"Fourier order {fit.forecaster.order}", fontsize=11)


def _plot_statistic(fig: Any, result: "MonitorResult") -> None:
    ev = result.evaluations
    s = result.summary
    o = result.options
    cls = o.detector_class
    look = cls.plot_text(o, s.fit)
    axes = fig.subplots(2, 1, height_ratios=[1.4, 1])
    first = s.first_alarm_time
    t = ev["time"].to_numpy()
    stat = ev["statistic"].to_numpy()
    thr = ev["threshold"].to_numpy()
    if first is not None:
        zoom = (first - 3.0, first + 2.0)
    else:
        zoom = (t[0] - 0.5, t[0] + 10.0) if t.size else (0.0, 1.0)
    what, limit = look.what, look.limit
    ylabel = _label(result, look.ylabel) if look.ylabel_in_signal_units else look.ylabel
    for ax, span, title in ((axes[0], None, "whole run"), (axes[1], zoom, "zoom")):
        m = np.ones(t.size, bool) if span is None else (t >= span[0]) & (t <= span[1])
        floor = look.floor
        ax.semilogy(t[m], np.maximum(stat[m], floor), color="tab:blue", lw=1.0, marker="." if span else None,
                    ms=3, label=what)
        ax.semilogy(t[m], thr[m], color="red", ls="--", lw=1.2, label=limit)
        above = m & (stat > thr)
        ax.semilogy(t[above], stat[above], "o", ms=2.5, color="red", label="above the limit")
        if look.shade_alarm:
            alarm = m & (ev["state"].to_numpy() == "ALARM")
            if alarm.any():
                ax.fill_between(t[m], 0, 1, where=alarm[m], transform=ax.get_xaxis_transform(), color="red",
                                alpha=0.08, label="alarm latched")
        _marks(ax, result)
        if span is not None:
            ax.set_xlim(*span)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
        ax.set_title(f"detector statistic against its limit — {title}", fontsize=10)
    if first is not None:
        txt = (f"t = {first:g} s    {cls.label}: {s.first_alarm.statistic:.4g} > limit {s.first_alarm.threshold:.4g}\n"
               f"{ALARM_MESSAGE}")
        if s.detection_latency is not None:
            txt += f"\ndetection delay {s.detection_latency:.3g} s after the fault; {s.alarms} alarm episode(s)"
        box = {"facecolor": "white", "edgecolor": "red", "alpha": 0.9}
    else:
        txt = f"no alarm; largest statistic/limit {s.max_statistic_over_threshold or 0:.3g}"
        box = {"facecolor": "white", "edgecolor": "green", "alpha": 0.9}
    # below the axes, so it never hides the threshold line; the legend sits beside it
    fig.text(0.99, 0.015, txt, fontsize=8, ha="right", va="bottom", bbox=box)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.01, 0.0), fontsize=8, ncol=2, frameon=False)
    fig.subplots_adjust(left=0.11, right=0.98, top=0.9, bottom=0.24, hspace=0.45)
    fig.suptitle(f"{s.case}: {o.signal}, {result.fits[0].forecaster.kind} model, detector {o.detector}",
                 fontsize=11)


def _plot_spectrum(fig: Any, result: "MonitorResult") -> None:
    est = result.fits[0].estimate
    fit = result.fits[0]
    ax, ax2 = fig.subplots(1, 2, width_ratios=[1.6, 1])
    f = est.frequencies
    m = f <= min(f[-1], 12.0 / est.period)
    ax.semilogy(f[m], np.maximum(est.spectrum[m], 1e-12), color="tab:blue", lw=1.0,
                label="|FFT| (mean removed, Hann, zero-padded)")
    ax.axvline(est.fft_frequency, color="tab:orange", ls="--",
               label=f"FFT peak {est.fft_frequency:.4f} Hz → {est.fft_period:.4f} s")
    ax.axvline(est.frequency, color="red", lw=1.0,
               label=f"refined {est.frequency:.6f} Hz → {est.period:.6f} s ± {est.period_stderr:.1g} s")
    ax.axvspan(est.fft_frequency - est.fft_bin_width / 2, est.fft_frequency + est.fft_bin_width / 2,
               color="tab:orange", alpha=0.12, label=f"FFT bin width 1/T = {est.fft_bin_width:.3f} Hz")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(_label(result, "amplitude"))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="upper right")
    fig.suptitle(f"{result.summary.case}: period of {result.options.signals[0]}", fontsize=11)
    ax.set_title(f"spectrum of {result.options.signals[0]}, training {fit.start:g}–{fit.end:g} s", fontsize=10)
    # one period of the training data folded on the refined period, with the model
    h = result.history
    t = h["time"].to_numpy()
    x = h[result.options.signals[0]].to_numpy()
    sel = (t >= fit.start) & (t <= fit.end)
    phase = np.mod(t[sel] - fit.start, est.period)
    ax2.plot(phase, x[sel], ".", ms=2, color="tab:blue", label="training data, folded")
    grid = fit.start + np.linspace(0, est.period, 400)
    ax2.plot(grid - fit.start, fit.forecaster.predict(grid), color="red", lw=1.0,
             label=f"{fit.forecaster.kind}, order {fit.forecaster.order}")
    ax2.set_xlabel(f"time modulo {est.period:.5f} s")
    ax2.set_ylabel(_label(result, result.options.signals[0]))
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7)
    ax2.set_title("one period", fontsize=10)
    fig.subplots_adjust(left=0.08, right=0.98, top=0.88, bottom=0.09, wspace=0.25)
