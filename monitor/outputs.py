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

import contextlib
import datetime as _dt
import errno
import math
import os
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

import numpy as np

from fourbar_common import output_folder_problem
from fourbar_common.contract import evaluations as evaluations_csv
from fourbar_common.contract import forecast as forecast_csv
from fourbar_common.contract.layout import EVALUATIONS, EVENTS, FORECAST, SUMMARY, monitor_folder_for
from fourbar_common.contract.monitor_events import MonitorEvent
from fourbar_common.contract.summary import MonitorSummary, SummaryOutputs, write_summary
from fourbar_common.files import replace_atomically
from fourbar_common.files import NotRegularFileError, file_kind

from .detector import ALARM_MESSAGE, Event, State
from .errors import OutputDirError, OutputWriteError

if TYPE_CHECKING:  # pragma: no cover
    from .summary import MonitorResult

__all__ = ["FORECAST_HEADER", "OUTPUT_FILES", "OutputWriters", "PLOT_FILES", "checked_default_out_dir",
           "checked_out_dir", "default_out_dir", "jsonable", "plot_figures", "write_plots", "zoom_window"]

PLOT_FILES = ("history.png", "statistic.png", "spectrum.png")
#: Every file the monitor writes into its output folder.
OUTPUT_FILES = (EVENTS, EVALUATIONS, FORECAST, SUMMARY, *PLOT_FILES)
#: The header of forecast.csv.
FORECAST_HEADER = forecast_csv.HEADER


def default_out_dir(exchange_path: str | os.PathLike[str]) -> Path:
    """Where the outputs go without ``--out``.

    ``<dir>/monitor`` for fourbar-run's ``<dir>/exchange.csv``; ``<dir>/<stem>.monitor``
    for any other file (``case2_libcosim.csv`` → ``case2_libcosim.monitor``): a name with
    a dot, which no Python package (so none of this project's source folders) can have.
    """
    return monitor_folder_for(exchange_path)


def _not_regular_outputs(out: Path) -> None:
    """Refuse a folder where one of the output names is a FIFO, device or folder (opening a FIFO
    for writing would block until someone reads it)."""
    for name in OUTPUT_FILES:
        try:
            mode = os.lstat(out / name).st_mode
        except OSError:
            continue
        if not stat.S_ISREG(mode):
            raise OutputDirError(f"{out / name}: {file_kind(mode)}, not a regular file; the monitor writes its "
                                 "outputs there: remove it or choose another folder with --out")


def checked_default_out_dir(exchange_path: str | os.PathLike[str]) -> Path:
    """:func:`default_out_dir`, refused when it exists and holds anything the monitor did not write."""
    out = default_out_dir(exchange_path)
    _not_regular_outputs(out)
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
    _not_regular_outputs(out)
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


def _open_output(path: Path) -> Any:
    """``open(path, "w")`` that never blocks: a FIFO put there since the folder was checked
    fails at once (``O_NONBLOCK``; ``ENXIO`` without a reader) or is refused after ``fstat``."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0), 0o666)
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegularFileError(errno.EINVAL, f"{file_kind(mode)}, not a regular file")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "w", encoding="utf-8")
    except BaseException:
        os.close(fd)
        raise


class OutputWriters:
    """The files of one monitor session; events, evaluations and forecasts are streamed.

    ``signals`` are the monitored columns, in the order of the forecast rows' columns.
    Every write error (disk full, read-only folder) raises :class:`OutputWriteError`
    naming the file; :meth:`discard` then removes what this session wrote, so no partial
    output is left.  summary.json and the plots are written atomically (a temporary file
    renamed over the name), so they are whole or absent.
    """

    def __init__(self, out_dir: Path, signals: tuple[str, ...], detector: str = ""):
        self.out_dir = Path(out_dir)
        self.signals = tuple(signals)
        self.detector = detector          # events of a built-in detector are checked against their payload type
        self._files: list[Any] = []
        self._paths: dict[Any, Path] = {}
        with self._writing(self.out_dir):
            self.out_dir.mkdir(parents=True, exist_ok=True)
            # The summary and plots of an earlier session here describe other data: removed, so a
            # session that is stopped before its own summary does not leave them beside its events.
            for name in (SUMMARY, *PLOT_FILES):
                (self.out_dir / name).unlink(missing_ok=True)
        try:
            for name in (EVENTS, EVALUATIONS, FORECAST):
                with self._writing(self.out_dir / name):
                    fh = _open_output(self.out_dir / name)
                    self._files.append(fh)
                    self._paths[fh] = self.out_dir / name
            self._events, self._evals, self._forecast = self._files
            self._headers()
        except BaseException:
            self.discard()
            raise

    @staticmethod
    @contextlib.contextmanager
    def _writing(path: Path) -> Iterator[None]:
        """Turn an OSError of writing ``path`` into :class:`OutputWriteError` naming it."""
        try:
            yield
        except OSError as exc:
            raise OutputWriteError(f"{path}: cannot write: {exc.strerror or exc}") from exc

    def _put(self, fh: Any, text: str) -> None:
        with self._writing(self._paths[fh]):
            fh.write(text)
            fh.flush()

    def _headers(self) -> None:
        self._put(self._evals, evaluations_csv.HEADER)
        self._put(self._forecast, FORECAST_HEADER)
        self._put(self._events, "")

    def event(self, e: Event) -> None:
        wall = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")
        line = MonitorEvent.build(e.time, e.kind, e.state.value, jsonable(e.statistic), jsonable(e.threshold),
                                  e.message, jsonable(e.data), wall, detector=self.detector).to_json()
        self._put(self._events, line + "\n")

    def evaluation(self, t: float, statistic: float, threshold: float, state: State) -> None:
        self._put(self._evals, evaluations_csv.format_row(t, statistic, threshold, state.value))

    def forecast(self, t: np.ndarray, x: np.ndarray, f: np.ndarray) -> None:
        """Rows of judged samples: times ``t``, values ``x`` and forecasts ``f`` (one column per signal)."""
        self._put(self._forecast, forecast_csv.format_rows(self.signals, t, x, f))

    def restart(self) -> None:
        for fh in (self._events, self._evals, self._forecast):
            with self._writing(self._paths[fh]):
                fh.seek(0)
                fh.truncate()
        self._headers()

    def finish(self, result: "MonitorResult", plots: bool = True) -> None:
        for fh in (self._events, self._evals, self._forecast):
            self._put(fh, "")
        outputs = SummaryOutputs(events=EVENTS, evaluations=EVALUATIONS, forecast=FORECAST,
                                 plots=PLOT_FILES if plots and result.fits else ())
        path = self.out_dir / SUMMARY
        # through the contract's reader: a summary it would refuse is never written
        record = MonitorSummary.from_json(jsonable({**result.summary.as_json(), "outputs": outputs.to_json()}),
                                          str(path))
        with self._writing(path):
            write_summary(path, record)
        if plots and result.fits:
            write_plots(result, self.out_dir)

    def close(self) -> None:
        """Close the streamed files (the first error, naming its file, is raised after all are closed)."""
        error = None
        for fh in self._files:
            try:
                with self._writing(self._paths[fh]):
                    fh.close()
            except OutputWriteError as exc:
                error = error or exc
        self._files = []
        if error is not None:
            raise error

    def discard(self) -> None:
        """After a write error: close and remove every file this session wrote (the streamed
        files, summary.json, the plots), so nothing partial is left."""
        for fh in self._files:
            try:
                fh.close()
            except OSError:
                pass                 # the data it could not write are being removed anyway
        self._files = []
        self.discard_in(self.out_dir)

    @staticmethod
    def discard_in(out_dir: Path) -> None:
        """Remove the monitor's output files from ``out_dir`` (errors ignored: best effort)."""
        for name in OUTPUT_FILES:
            try:
                (Path(out_dir) / name).unlink(missing_ok=True)
            except OSError:
                pass


#: The history zoom shows this many periods of the signal before the earlier of the fault and
#: the first alarm, and this many after the later (never starting inside a training window).
ZOOM_PERIODS_BEFORE = 2.0
ZOOM_PERIODS_AFTER = 3.0


def plot_figures(result: "MonitorResult") -> dict[str, Any]:
    """history.png, statistic.png and spectrum.png as matplotlib Figures (Agg canvas, no pyplot), by file name.

    The artists a reader may look for carry a gid: ``fault`` and ``alarm`` (the lines of the
    fault time and the first alarm, in the history and statistic plots), ``zoom`` (the zoomed
    axes), ``statistic`` (the statistic's line), ``alarm-latched`` (the shading of a latched
    alarm, from its alarm event to its clear event or the end), ``forecast-band`` (the
    forecast ± the detector's noise scale, cusum only).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figures = {}
    for name, fn in zip(PLOT_FILES, (_plot_history, _plot_statistic, _plot_spectrum)):
        fig = Figure(figsize=(10, 6.8), dpi=100)
        FigureCanvasAgg(fig)
        fn(fig, result)
        figures[name] = fig
    return figures


def write_plots(result: "MonitorResult", out_dir: str | os.PathLike[str]) -> list[Path]:
    """Write history.png, statistic.png and spectrum.png for ``result``; return their paths."""
    import gc

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    # no cycle collection while matplotlib is imported and draws: its thousands of new objects
    # would start full collections of everything the process holds (pandas, scipy, the result),
    # 0.2 s of a fresh process's CPU (docs/benchmarks.md); what they leave is collected after
    collecting = gc.isenabled()
    gc.disable()
    try:
        for name, fig in plot_figures(result).items():
            path = out / name
            try:            # atomically: a full disk leaves no truncated PNG
                replace_atomically(path, lambda tmp, fig=fig: fig.savefig(tmp, format="png"))
            except OSError as exc:
                raise OutputWriteError(f"{path}: cannot write: {exc.strerror or exc}") from exc
            paths.append(path)
    finally:
        if collecting:
            gc.enable()
    return paths


def _unit(result: "MonitorResult") -> str:
    """The monitored signal's unit from run.json (the FMU's declaration), or "" when unknown."""
    run = result.summary.run
    return (run.units.get(result.options.signals[0], "") if run is not None else "") or ""


def _label(result: "MonitorResult", what: str) -> str:
    unit = _unit(result)
    return f"{what} ({unit})" if unit else what


def zoom_window(result: "MonitorResult") -> tuple[float, float]:
    """The history plot's zoom (s): ``ZOOM_PERIODS_BEFORE`` periods before the earlier of the
    fault and the first alarm to ``ZOOM_PERIODS_AFTER`` after the later (without either: as
    many periods from the end of the training window), starting no earlier than the end of a
    training window that began before them (or a tenth of a period before the earlier mark,
    when that is earlier), and cut to the data."""
    s = result.summary
    fit = result.fits[0]
    period = fit.period or fit.estimate.period
    marks = [m for m in (s.fault_time, s.first_alarm_time) if m is not None]
    if marks:
        a, b = min(marks), max(marks)
        lo, hi = a - ZOOM_PERIODS_BEFORE * period, b + ZOOM_PERIODS_AFTER * period
    else:                       # the first periods judged
        a = lo = fit.end
        hi = lo + (ZOOM_PERIODS_BEFORE + ZOOM_PERIODS_AFTER) * period
    for ft in result.fits:
        # a training window before the marks: start after it, but at least a tenth of a period before a mark
        if ft.start < a:
            lo = max(lo, min(ft.end, a - 0.1 * period))
    t = result.history["time"].to_numpy()
    if t.size:
        lo, hi = max(lo, float(t[0])), min(hi, float(t[-1]))
    return (lo, hi) if hi > lo else (lo, lo + period)


def _noise_scale(result: "MonitorResult") -> Any:
    """The detector's noise scale of the plotted signal (a :class:`~monitor.sequential.NoiseScale`),
    None when the detector has none (mae)."""
    sig = result.options.signals[0]
    for s in result.fits[0].signals:
        if getattr(s, "name", None) == sig and getattr(s, "scale", None) is not None:
            return s.scale
    return None


def _marks(ax: Any, result: "MonitorResult", label: bool = True, names: bool = False) -> None:
    """The fault time (black dashes, on top) and the alarms (red, wider, beneath): 0.01 s apart in
    Case 2, so both stay visible; their times are in the legend and, with ``names``, on the axes."""
    s = result.summary
    fault = s.fault_time
    times = [e.time for e in s.alarm_events]
    if times:
        first = times[0]
        after = f", {s.detection_latency:.3g} s after the fault" if s.detection_latency is not None else ""
        ax.axvline(first, color="red", lw=3.0, alpha=0.55, zorder=5, gid="alarm",
                   label=f"first alarm {first:g} s{after}" if label else None)
        for i, t in enumerate(times[1:50]):
            ax.axvline(t, color="red", lw=0.8, alpha=0.4, zorder=5,
                       label=("later alarm episodes" if i == 0 else None) if label else None)
    if fault is not None:
        ax.axvline(fault, color="black", ls=(0, (4, 2)), lw=1.3, zorder=6, gid="fault",
                   label=f"fault {fault:g} s (run.json)" if label else None)
    if names:
        tr = ax.get_xaxis_transform()
        both = fault is not None and times
        if fault is not None:
            ax.text(fault, 1.01, f"fault {fault:g} s ", transform=tr, fontsize=8, va="bottom",
                    ha="right" if both and fault <= times[0] else "left")
        if times:
            ax.text(times[0], 1.01, f" alarm {times[0]:g} s", transform=tr, fontsize=8, va="bottom", color="red",
                    ha="left" if not both or fault <= times[0] else "right")


def _plot_history(fig: Any, result: "MonitorResult") -> None:
    h = result.history
    sig = result.options.signals[0]
    fit = result.fits[0]
    axes = fig.subplots(2, 1)
    t = h["time"].to_numpy()
    x = h[sig].to_numpy()
    f = h["forecast"].to_numpy()
    s = result.summary
    forecast_name = result.options.detector_class.plot_text(result.options, fit).forecast
    lo, hi = zoom_window(result)
    # in-sample fit over the training window, for the paper's Fig. 9 view
    train = (t >= fit.start) & (t <= fit.end)
    fitted = np.full(t.size, np.nan)
    if train.any():
        fitted[train] = fit.forecaster.predict(t[train])
    scale = _noise_scale(result)
    unit = _unit(result)
    for ax, (a, b), title in ((axes[0], (t[0] if t.size else 0, t[-1] if t.size else 1), "whole run"),
                              (axes[1], (lo, hi), f"zoom {lo:.4g}–{hi:.4g} s")):
        zoom = ax is axes[1]
        m = (t >= a) & (t <= b)
        ax.plot(t[m], x[m], color="tab:blue", lw=0.9, zorder=3, label=f"{sig} (exchange file)")
        ax.plot(t[m], fitted[m], color="tab:green", lw=1.2, ls="--", zorder=4, label="model on training data")
        ax.plot(t[m], f[m], color="tab:orange", lw=1.2, ls="--", zorder=4,
                label=f"{forecast_name} ({fit.forecaster.kind})")
        if zoom and scale is not None:
            floor = ", at its floor" if scale.at_floor else ""
            ax.fill_between(t[m], f[m] - scale.sigma, f[m] + scale.sigma, color="tab:orange", alpha=0.25, lw=0,
                            zorder=2, gid="forecast-band",
                            label=f"forecast ± σ: the detector's noise scale σ = {scale.sigma:.3g}"
                                  f"{' ' + unit if unit else ''}{floor}")
        for i, ft in enumerate(result.fits):
            ax.axvspan(ft.start, ft.end, color="tab:green", alpha=0.12,
                       label=f"training {ft.start:g}–{ft.end:g} s" if i == 0 else None)
        _marks(ax, result, names=zoom)
        ax.set_xlim(a, b)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(_label(result, sig))
        ax.grid(alpha=0.3)
        ax.set_title(f"{sig}: data and forecast — {title}", fontsize=10, pad=14 if zoom else 6)
    axes[1].set_gid("zoom")
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", fontsize=8, ncol=3, frameon=False)
    fig.subplots_adjust(left=0.08, right=0.98, top=0.9, bottom=0.17, hspace=0.5)
    fig.suptitle(f"{s.case}: {fit.forecaster.kind} model, period {fit.estimate.period:.6g} s, "
                 f"Fourier order {fit.forecaster.order}", fontsize=11)


def _alarm_spans(result: "MonitorResult", end: float) -> list[tuple[float, float]]:
    """(alarm event time, its clear event time or ``end``) for each alarm episode."""
    spans, start = [], None
    for e in result.events:
        if e.get("event") == "alarm" and start is None:
            start = float(e["time"])
        elif e.get("event") == "clear" and start is not None:
            spans.append((start, float(e["time"])))
            start = None
    if start is not None:
        spans.append((start, max(start, end)))
    return spans


def _interval_maximum(result: "MonitorResult") -> bool:
    """The statistic recorded at ``t`` is the largest of the interval ``(t - every, t]`` (cusum):
    drawn as steps over its interval, so an alarm inside it falls where the statistic is high
    (the detector's :attr:`StatisticPlot.interval_maximum <monitor.detector.StatisticPlot>`)."""
    o = result.options
    return o.detector_class.plot_text(o, result.summary.fit).interval_maximum


def _statistic_scale(stat: np.ndarray, thr: np.ndarray) -> tuple[str, float | None]:
    """("log", None) when every value is positive, else ("symlog", linthresh): a statistic of 0
    (a CUSUM at rest) is drawn at 0, linear up to a tenth of the limit's decade, log above."""
    finite = stat[np.isfinite(stat)]
    if finite.size and finite.min() > 0:
        return "log", None
    limits = thr[np.isfinite(thr) & (thr > 0)]
    ref = float(limits.min()) if limits.size else (float(finite.max()) if finite.size and finite.max() > 0 else 1.0)
    return "symlog", 10.0 ** (math.floor(math.log10(ref)) - 1)


def _plot_statistic(fig: Any, result: "MonitorResult") -> None:
    from .log_labels import plain_log_labels

    ev = result.evaluations
    s = result.summary
    o = result.options
    cls = o.detector_class
    look = cls.plot_text(o, s.fit)
    axes = fig.subplots(2, 1, height_ratios=[1.4, 1])
    first = s.first_alarm_time
    t = ev["time"].to_numpy()
    stat = ev["statistic"].to_numpy(dtype=float)
    thr = ev["threshold"].to_numpy(dtype=float)
    if first is not None:
        zoom = (first - 3.0, first + 2.0)
    else:
        zoom = (t[0] - 0.5, t[0] + 10.0) if t.size else (0.0, 1.0)
    what, limit = look.what, look.limit
    ylabel = _label(result, look.ylabel) if look.ylabel_in_signal_units else look.ylabel
    scale, linthresh = _statistic_scale(stat, thr)
    if scale == "symlog":
        ylabel += f"\n(linear 0–{linthresh:g}, log above)"
    steps = "steps-pre" if _interval_maximum(result) else "default"
    end = float(t[-1]) if t.size else (s.last_time or 0.0)
    spans = _alarm_spans(result, end) if look.shade_alarm else []
    for ax, span, title in ((axes[0], None, "whole run"), (axes[1], zoom, "zoom")):
        m = np.ones(t.size, bool) if span is None else (t >= span[0]) & (t <= span[1])
        ax.plot(t[m], stat[m], color="tab:blue", lw=1.0, marker="." if span else None, ms=3, drawstyle=steps,
                gid="statistic", label=what)
        ax.plot(t[m], thr[m], color="red", ls="--", lw=1.2, label=limit)
        above = m & (stat > thr)
        ax.plot(t[above], stat[above], "o", ms=2.5, color="red", label="above the limit")
        for i, (a, b) in enumerate(spans):
            ax.axvspan(a, b, color="red", alpha=0.08, lw=0, gid="alarm-latched",
                       label="alarm latched (alarm to clear)" if i == 0 else None)
        _marks(ax, result)
        if scale == "symlog":
            ax.set_yscale("symlog", linthresh=linthresh, linscale=0.5)
            if np.nanmin(stat) >= 0:       # 0 just above the bottom spine, so a statistic at rest is seen
                ax.set_ylim(bottom=-0.08 * linthresh)
        else:
            ax.set_yscale("log")
        plain_log_labels(ax.yaxis)
        if span is not None:
            ax.set_xlim(*span)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
        ax.set_title(f"detector statistic against its limit — {title}", fontsize=10)
    axes[1].set_gid("zoom")
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
    fig.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.01, 0.0), fontsize=7.5, ncol=1, frameon=False)
    fig.subplots_adjust(left=0.11, right=0.98, top=0.9, bottom=0.26, hspace=0.45)
    fig.suptitle(f"{s.case}: {o.signal}, {result.fits[0].forecaster.kind} model, detector {o.detector}",
                 fontsize=11)


def _plot_spectrum(fig: Any, result: "MonitorResult") -> None:
    from .log_labels import plain_log_labels

    est = result.fits[0].estimate
    fit = result.fits[0]
    ax, ax2 = fig.subplots(1, 2, width_ratios=[1.6, 1])
    f = est.frequencies
    m = f <= min(f[-1], 12.0 / est.period)
    ax.semilogy(f[m], np.maximum(est.spectrum[m], 1e-12), color="tab:blue", lw=1.0,
                label="|FFT| (mean removed, Hann, zero-padded)")
    plain_log_labels(ax.yaxis)
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
