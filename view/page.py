"""The live page of one run folder: Panel on Bokeh.

One :class:`SharedRun` per server reads the folder for every session: a
:class:`~view.sources.RunFolder` polled at most every ``poll_ms`` (by whichever session's tick
comes first), a :class:`~view.timeline.Timeline` of what was read, and the mechanism's scene.
Each browser session gets its own :class:`RunPage`: its Bokeh models and a clock over the
shared timeline.  (One reader per session made 50 sessions on an hour-long run read and keep
the run 50 times: benchmarks/view_load.py --concurrent 50, docs/view.md.)  The clock
follows the newest row while the run is written (live) and plays the run back at a chosen
speed once it is finished (replay, with pause and a time slider).  At each tick the page
streams to the browser only the rows between the last time shown and the clock
(``ColumnDataSource.stream`` with rollover), so the cost per tick is the new rows, not the run:

- *recent* plots (signal with its forecast, detector statistic with its limit) at full
  resolution over the last ``window_s`` seconds (rollover keeps them bounded);
- a *whole run* plot of the signal's min/max per bin (``overview_bins`` over the run's span),
  re-sent once per bin;
- the mechanism at the clock, drawn from the joint columns (:mod:`view.geometry`);
- a system run's component signals (``motor.current``, ``controller.voltage`` ...), a recent
  plot per component (:mod:`view.components`), streamed like the signal.

The page names its data sources (``signal_recent``, ``forecast_recent``, ``statistic``,
``signal_overview``, ``bodies``, ``joints``, and ``component_NAME`` per component of a
system run) so a test can count the rows a browser holds.
"""
from __future__ import annotations

import html
import math
import threading
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fourbar_common.contract.layout import EXCHANGE

from .geometry import Geometry, faulted_bodies
from .sources import RunFolder
from .timeline import Timeline

__all__ = ["PageSettings", "RunPage", "SharedRun"]

#: s of run between two recomputations of the guides' spans and the extent while a run is written.
SCENE_EVERY_S = 5.0
COLOURS = {"body": "#1f4e79", "faulted": "#c0392b", "joint": "#222222", "ground": "#7f7f7f",
           "signal": "#1f77b4", "forecast": "#d62728", "statistic": "#2ca02c", "limit": "#d62728"}
BANNER = {"WAITING": ("#6c757d", "waiting for the monitor (no monitor outputs yet)"),
          "TRAINING": ("#1f6fb2", "TRAINING: the monitor is learning the healthy signal"),
          "STABLE": ("#2e7d32", "STABLE: the signal follows its forecast"),
          "ALARM": ("#c62828", "ALARM")}


@dataclass(frozen=True)
class PageSettings:
    poll_ms: int = 250             # how often the folder is read and the browser updated
    window_s: float = 20.0         # recent plots: seconds at full resolution
    bin_s: float = 1.0             # whole-run plot: seconds per min/max bin when the run's span is unknown
    overview_bins: int = 1500      # whole-run plot: bins over the run's span (an hour: 2.4 s each)
    speed: float = 1.0             # replay: run seconds per wall second
    max_stream: int = 20_000       # rows sent in one tick at most (a jump re-sends the window)
    at: float | None = None        # open paused at this run time (None: follow, or play from the start)


class SharedRun:
    """The run folder as every session of one server sees it: one reader, one timeline.

    :meth:`refresh` polls the folder when ``poll_s`` has passed since the last poll (the first
    session's tick after that does it; the others read what it read), so the folder is read
    once per period whatever the number of sessions, and the rows are kept once.  The
    mechanism's scene (the extent and the guides' spans, from a sample of every row) is made once per
    ``SCENE_EVERY_S`` of run for all sessions too."""

    def __init__(self, folder: str | Path, poll_s: float = 0.25):
        self.folder = RunFolder(folder)
        self.timeline = Timeline()
        self.poll_s = poll_s
        self.record_version = 0            # +1 whenever run.json was read again
        self._polled = -math.inf
        self._lock = threading.Lock()
        self._scene = None
        self._scene_key: tuple | None = None
        self._scene_t = -math.inf

    def refresh(self) -> Timeline:
        """The timeline, read again from the folder when ``poll_s`` has passed."""
        with self._lock:
            now = _time.monotonic()
            if now - self._polled >= self.poll_s:
                self._polled = now
                update = self.folder.poll()
                self.timeline.feed(update)
                if update.record is not None:
                    self.record_version += 1
            return self.timeline

    def scene(self, geometry: Geometry):
        """The scene of ``geometry`` over every row read (a sample of at most ~5,000 of them),
        made again every SCENE_EVERY_S of run while the run is written."""
        tl = self.timeline
        key = (tl.generation, geometry.drawing)
        running = tl.record is not None and not tl.record.ended
        if self._scene is None or self._scene_key != key or (running and tl.rows.last_time - self._scene_t
                                                             >= SCENE_EVERY_S):
            import pandas as pd

            n = tl.rows.n
            take = np.unique(np.r_[np.arange(0, n, max(1, n // 5000)), n - 1])
            self._scene = geometry.scene(pd.DataFrame({c: tl.rows.column(c)[take] for c in tl.rows.columns}))
            self._scene_key, self._scene_t = key, tl.rows.last_time
        return self._scene


class RunPage:
    """One session's page over a :class:`SharedRun` (or a folder: then a run of its own).
    ``panel`` is imported here, when a page is made."""

    def __init__(self, shared: SharedRun | str | Path, settings: PageSettings = PageSettings()):
        import panel as pn
        from bokeh.models import ColumnDataSource

        self.pn = pn
        self.settings = settings
        self.shared = shared if isinstance(shared, SharedRun) else SharedRun(shared, settings.poll_ms / 1000)
        self.timeline = self.shared.timeline
        self._record_version = -1
        self.geometry: Geometry | None = None
        self.scene = None
        self.shown_t: float | None = None          # the clock value the plots show
        self.generation = -1
        self.clock: float | None = None
        self.playing = settings.at is None
        self.live = settings.at is None
        self._wall = _time.monotonic()
        self._signal: str | None = None
        self._rollover: dict[int, int] = {}       # per timeline series: its recent plot's rollover
        self._sent: dict[str, tuple[int, float]] = {}   # per recent source: (id of its series, time of its last row)
        self._overview_key: tuple | None = None
        self._components: tuple = ()               # the component groups plotted (view.components)

        self.src = {
            "signal_recent": ColumnDataSource({"time": [], "value": []}, name="signal_recent"),
            "forecast_recent": ColumnDataSource({"time": [], "forecast": []}, name="forecast_recent"),
            "statistic": ColumnDataSource({"time": [], "statistic": [], "threshold": []}, name="statistic"),
            "signal_overview": ColumnDataSource({"time": [], "low": [], "high": []}, name="signal_overview"),
            "bodies": ColumnDataSource({"xs": [], "ys": [], "colour": [], "name": []}, name="bodies"),
            "joints": ColumnDataSource({"x": [], "y": [], "name": [], "time": []}, name="joints"),
            "ground": ColumnDataSource({"x": [], "y": []}, name="ground"),
            "guides": ColumnDataSource({"xs": [], "ys": []}, name="guides"),
        }
        self._build(pn)

    # -- layout -------------------------------------------------------------------------
    def _build(self, pn) -> None:
        from bokeh.models import BoxAnnotation, DataRange1d, Span
        from bokeh.plotting import figure

        s = self.src
        self.mechanism = figure(title="mechanism", height=380, width=380, match_aspect=True,
                                x_axis_label="x (m)", y_axis_label="y (m)", tools="pan,wheel_zoom,reset")
        self.mechanism.multi_line("xs", "ys", source=s["guides"], line_color=COLOURS["ground"], line_width=1,
                                  line_dash="dashed")
        self.mechanism.scatter("x", "y", source=s["ground"], marker="triangle", size=16, color=COLOURS["ground"])
        self.mechanism.multi_line("xs", "ys", source=s["bodies"], line_color="colour", line_width=6)
        self.mechanism.scatter("x", "y", source=s["joints"], size=9, color="white", line_color=COLOURS["joint"],
                               line_width=2)

        # the recent plots' x range follows the newest data (annotations outside it do not widen it)
        recent = dict(follow="end", follow_interval=self.settings.window_s, range_padding=0.0)
        self.signal_plot = figure(title="signal and forecast (recent)", height=250, sizing_mode="stretch_width",
                                  x_axis_label="time (s)", tools="pan,xwheel_zoom,reset",
                                  x_range=DataRange1d(**recent))
        self.signal_plot.line("time", "value", source=s["signal_recent"], color=COLOURS["signal"], legend_label="signal")
        self.signal_plot.line("time", "forecast", source=s["forecast_recent"], color=COLOURS["forecast"],
                              line_dash="dashed", legend_label="forecast")
        self.signal_plot.legend.location = "top_left"
        self.train_box = BoxAnnotation(fill_alpha=0.12, fill_color="#1f6fb2", visible=False)
        self.signal_plot.add_layout(self.train_box)

        self.overview = figure(title="whole run (min/max per bin)", height=160, sizing_mode="stretch_width",
                               x_axis_label="time (s)", tools="pan,xwheel_zoom,reset")
        self.overview.varea("time", "low", "high", source=s["signal_overview"], fill_color=COLOURS["signal"],
                            fill_alpha=0.35)
        for edge in ("low", "high"):       # a bin of one row has low == high: the lines still show it
            self.overview.line("time", edge, source=s["signal_overview"], color=COLOURS["signal"], line_width=1)
        self.overview_train = BoxAnnotation(fill_alpha=0.12, fill_color="#1f6fb2", visible=False)
        self.overview.add_layout(self.overview_train)
        self.fault_marks = []
        for fig in (self.signal_plot, self.overview):
            mark = Span(dimension="height", line_color="#555555", line_dash="dotted", line_width=2, visible=False)
            fig.add_layout(mark)
            self.fault_marks.append(mark)
        self.alarm_marks = []
        for fig in (self.signal_plot, self.overview):
            mark = Span(dimension="height", line_color=COLOURS["limit"], line_width=2, visible=False)
            fig.add_layout(mark)
            self.alarm_marks.append(mark)

        self.stat_plot = figure(title="detector statistic and its limit", height=200, sizing_mode="stretch_width",
                                x_axis_label="time (s)", tools="pan,xwheel_zoom,reset",
                                x_range=DataRange1d(**recent))
        self.stat_plot.line("time", "statistic", source=s["statistic"], color=COLOURS["statistic"],
                            legend_label="statistic")
        self.stat_plot.line("time", "threshold", source=s["statistic"], color=COLOURS["limit"], line_dash="dashed",
                            legend_label="limit")
        self.stat_plot.legend.location = "top_left"

        self.banner = pn.pane.HTML("", sizing_mode="stretch_width", name="banner")
        self.facts = pn.pane.HTML("", width=380, name="facts")
        self.verdict = pn.pane.HTML("", sizing_mode="stretch_width", name="diagnosis")
        self.notice = pn.pane.HTML("", sizing_mode="stretch_width", name="notice")
        self.play = pn.widgets.Toggle(name="pause" if self.playing else "play", value=self.playing, width=90,
                                      button_type="primary")
        self.play.param.watch(self._on_play, "value")
        speeds = sorted({0.5, 1.0, 2.0, 5.0, 10.0, 50.0, float(self.settings.speed)})
        self.speed = pn.widgets.Select(name="speed", options={f"{v:g}x": v for v in speeds},
                                       value=float(self.settings.speed), width=90)
        self.slider = pn.widgets.FloatSlider(name="time (s)", start=0.0, end=1.0, value=0.0, step=0.01,
                                             sizing_mode="stretch_width")
        self.slider.param.watch(self._on_slider, "value_throttled")
        self.follow = pn.widgets.Checkbox(name="follow the newest row", value=self.live, width=170)
        self.follow.param.watch(self._on_follow, "value")
        controls = pn.Row(self.play, self.speed, self.follow, self.slider, sizing_mode="stretch_width")
        self.component_plots = pn.Column(sizing_mode="stretch_width", name="components")
        left = pn.Column(self.mechanism, self.facts)
        right = pn.Column(self.banner, controls, self.signal_plot, self.stat_plot, self.overview,
                          self.component_plots, self.verdict, self.notice, sizing_mode="stretch_width")
        self.layout = pn.Row(left, right, sizing_mode="stretch_width")

    def servable(self):
        """The layout, filled once; its periodic update starts when a browser has loaded the
        page (``pn.state.onload``), so a session no browser connects to (a bare GET, a page
        closed while loading) costs no ticks until Bokeh drops it."""
        self.tick()
        self.pn.state.onload(self._start_ticking)
        return self.layout

    def _start_ticking(self) -> None:
        self.tick()
        self.pn.state.add_periodic_callback(self.tick, period=self.settings.poll_ms)

    # -- controls -----------------------------------------------------------------------
    def _on_play(self, event) -> None:
        self.playing = bool(event.new)
        self.play.name = "pause" if self.playing else "play"
        self._wall = _time.monotonic()

    def _on_follow(self, event) -> None:
        self.live = bool(event.new)

    def _on_slider(self, event) -> None:
        if event.new is None:
            return
        self.live = False
        self.follow.value = False
        self.clock = float(event.new)
        self._wall = _time.monotonic()

    # -- one tick -------------------------------------------------------------------------
    def tick(self) -> None:
        """Read what is new, move the clock, send the browser what changed."""
        tl = self.shared.refresh()
        if tl.generation != self.generation:
            self._reset()
        if self.shared.record_version != self._record_version:
            self._record_version = self.shared.record_version
            self._set_facts()
        self._set_notice()
        last = tl.last_time
        if last is None:
            self.banner.object = ('<div id="state" data-state="WAITING" style="background:#6c757d;color:white;'
                                  'padding:8px 12px;border-radius:4px;font-size:16px">waiting for the first rows '
                                  f'of {EXCHANGE}</div>')
            return
        if self.geometry is None and tl.record is not None and tl.record.drawing is not None and tl.rows is not None:
            geometry = Geometry(tl.record.drawing)
            if not geometry.lacking(tl.rows.columns):
                self.geometry = geometry
        if not self._components and tl.rows is not None:
            self._add_component_plots(tl.components)
        self._advance_clock(last)
        self._show(self.clock)
        self.slider.end = max(last, self.slider.start + 1e-9)
        self.slider.value = min(self.clock, self.slider.end)      # value_throttled (a user's drag) stays

    def _advance_clock(self, last: float) -> None:
        now = _time.monotonic()
        running = self.timeline.record is not None and not self.timeline.record.ended
        if self.clock is None:
            first = self.timeline.first_time or 0.0
            if self.settings.at is not None:
                self.clock = min(max(self.settings.at, first), last)
            elif running and self.live:
                self.clock = last
            else:                          # a finished run: replay it from its start
                self.clock = first
                self.live = False
                self.follow.value = False
        elif self.live:                    # follow the newest row, also once the run has ended
            self.clock = last
        elif self.playing:
            self.clock = min(last, self.clock + (now - self._wall) * float(self.speed.value))
        self._wall = now

    def _reset(self) -> None:
        self.generation = self.timeline.generation
        for name in ("signal_recent", "forecast_recent", "statistic", "signal_overview", "bodies", "joints"):
            self.src[name].data = {k: [] for k in self.src[name].data}
        self.shown_t, self.clock, self.geometry, self.scene, self._overview_key = None, None, None, None, None
        # a new run starts the page as if it were opened now: following it while it is written
        if self.settings.at is None and not self.live:
            self.live = True
            self.follow.value = True
        self._rollover.clear()
        self._sent.clear()
        for group in self._components:
            del self.src[f"component_{group.component}"]
        self._components = ()
        self.component_plots.objects = []

    def _add_component_plots(self, groups) -> None:
        """A recent plot per component of a system run, a line per signal (its source
        ``component_NAME`` holds ``time`` and the signals); nothing for a one-FMU run or a run.json
        that cannot be read (no groups)."""
        if not groups:
            return
        from bokeh.models import ColumnDataSource, DataRange1d
        from bokeh.palettes import Category10_10
        from bokeh.plotting import figure

        recent = dict(follow="end", follow_interval=self.settings.window_s, range_padding=0.0)
        units = self.timeline.record.units or {}
        plots = []
        for group in groups:
            name = f"component_{group.component}"
            self.src[name] = ColumnDataSource({"time": [], **{c: [] for c in group.signals}}, name=name)
            fig = figure(title=f"{group.component} (recent)", height=160, sizing_mode="stretch_width",
                         x_axis_label="time (s)", tools="pan,xwheel_zoom,reset", x_range=DataRange1d(**recent))
            for i, signal in enumerate(group.signals):
                unit = units.get(signal)
                fig.line("time", signal, source=self.src[name], color=Category10_10[i % 10],
                         legend_label=f"{signal} ({unit})" if unit else signal)
            fig.legend.location = "top_left"
            plots.append(fig)
        self._components = tuple(groups)
        self.component_plots.objects = plots

    # -- what the browser gets ---------------------------------------------------------
    def _window_rows(self, series) -> int:
        """A recent plot's rollover: the rows in ``window_s`` at the series' sample step, fixed
        once known.  It must not change between two streams to one source: BokehJS then keeps
        its arrays out of time order (seen: a 2001/2002 flip froze the line's end)."""
        key = id(series)
        if key not in self._rollover:
            if series is None or series.n < 2:
                return 10_000
            step = max(float(np.median(np.diff(series.time[-50:]))), 1e-9)
            self._rollover[key] = int(round(self.settings.window_s / step)) + 1
        return self._rollover[key]

    def _show(self, t: float) -> None:
        tl = self.timeline
        signal = tl.signals[0] if tl.signals else None
        if signal != self._signal:
            self._signal = signal
            self.signal_plot.title.text = f"{signal}: signal and forecast, last {self.settings.window_s:g} s"
            self.shown_t = None
        jump = self.shown_t is None or t < self.shown_t or t - self.shown_t > self.settings.window_s
        if jump:
            self._sent.clear()
        if signal is not None:
            if signal in tl.forecasts:
                fc = tl.forecasts[signal]
                part, replace = self._unsent("signal_recent", fc, t, ("value", "forecast"))
                self._send("signal_recent", {"time": part["time"], "value": part["value"]}, replace,
                           self._window_rows(fc))
                keep = np.isfinite(part["forecast"])
                self._send("forecast_recent", {"time": part["time"][keep], "forecast": part["forecast"][keep]},
                           replace, self._window_rows(fc))
            elif tl.rows is not None and signal in tl.rows.columns:
                part, replace = self._unsent("signal_recent", tl.rows, t, (signal,))
                self._send("signal_recent", {"time": part["time"], "value": part[signal]}, replace,
                           self._window_rows(tl.rows))
        ev, replace = self._unsent("statistic", tl.evaluations, t, ("statistic", "threshold"))
        self._send("statistic", ev, replace, self._window_rows(tl.evaluations))
        for group in self._components:
            name = f"component_{group.component}"
            part, replace = self._unsent(name, tl.rows, t, group.signals)
            self._send(name, part, replace, self._window_rows(tl.rows))
        self._overview(signal, t)
        self._marks(t)
        self._mechanism(t)
        self.shown_t = t

    def _unsent(self, name: str, series, t: float, columns) -> tuple[dict, bool]:
        """The rows of ``series`` that source ``name`` lacks up to the clock ``t``, and whether
        they replace what it holds (after a jump, or when another series feeds it: the
        ``window_s`` up to the series' newest row at or before ``t``).  What a source holds is tracked by the time of the last row sent
        to it, per source: the monitor's files are written after the exchange file (late by its
        training or a refit, seconds at 1x), so its rows at times the clock has passed still
        come, and are sent when they do.  (Taking every source's rows after the clock's last
        value dropped those, for good: the live page's straight-line gaps of issue 37.)"""
        feed, sent = self._sent.get(name, (None, None))
        replace = feed != id(series)
        if replace:        # the window up to the series' newest row (the monitor may lag more than a window)
            newest = series.last_time if series.last_time is not None else t
            t0 = min(t, newest) - self.settings.window_s
        else:
            t0 = sent
        part = series.between(t0, t, columns)
        self._sent[name] = (id(series), float(part["time"][-1]) if len(part["time"]) else t0)
        return part, replace

    def _send(self, name: str, data: dict, replace: bool, rollover: int) -> None:
        source = self.src[name]
        if replace:
            source.data = {k: np.asarray(v)[-rollover:] for k, v in data.items()}
        elif len(data["time"]):
            n = min(len(data["time"]), self.settings.max_stream)
            source.stream({k: np.asarray(v)[-n:] for k, v in data.items()}, rollover=rollover)

    def _overview(self, signal: str | None, t: float) -> None:
        tl = self.timeline
        if signal is None:
            return
        series = tl.forecasts.get(signal)
        column = "value"
        if series is None:
            series, column = tl.rows, signal
        if series is None or column not in series.columns:
            return
        bin_s = self._bin_s()
        # again when the clock or the series' newest row (up to the clock) reaches another bin:
        # the monitor's rows come late, also after the run's last row
        newest = min(t, series.last_time) if series.last_time is not None else -math.inf
        key = (id(series), int(t // bin_s), math.floor(newest / bin_s) if math.isfinite(newest) else None)
        if key != self._overview_key:
            self._overview_key = key
            self.src["signal_overview"].data = series.envelope(column, t, bin_s)

    def _bin_s(self) -> float:
        """The whole-run plot's bin: the run's span in ``overview_bins`` bins, at least one row."""
        r = self.timeline.record
        if r is None or r.experiment is None:
            return self.settings.bin_s
        span = r.experiment.stop - r.experiment.start
        return max(r.experiment.step, span / self.settings.overview_bins)

    def _marks(self, t: float) -> None:
        tl = self.timeline
        state = tl.state_at(t)
        colour, text = BANNER[state.state]
        if state.state == "ALARM":
            text = f"ALARM at t = {state.alarm_time:.2f} s: {html.escape(state.message or 'alarm')}"
        if tl.writer_gone:
            colour, text = "#6c757d", text + " — the run's writer stopped (run.json says running, nobody writes)"
        self.banner.object = (f'<div id="state" data-state="{state.state}" style="background:{colour};color:white;'
                              f'padding:8px 12px;border-radius:4px;font-size:16px">'
                              f't = {t:.2f} s &nbsp; {text}</div>')
        for box in (self.train_box, self.overview_train):
            if state.train is not None:
                box.left, box.right, box.visible = state.train[0], state.train[1], True
        fault = tl.record.fault_time if tl.record is not None else None
        for mark in self.fault_marks:
            if fault is not None:
                mark.location, mark.visible = fault, True
        for mark in self.alarm_marks:
            if state.alarm_time is not None:
                mark.location, mark.visible = state.alarm_time, True
        d = tl.diagnosis
        if d is not None:
            self.verdict.object = (f'<div id="verdict" data-verdict="{html.escape(d.verdict)}" style="border-left:6px '
                                   f'solid #444;padding:6px 10px"><b>diagnosis</b>: {html.escape(d.message)}</div>')

    def _mechanism(self, t: float) -> None:
        tl = self.timeline
        if self.geometry is None or tl.rows is None:
            self.mechanism.title.text = ("mechanism: not drawn — " + self._why_no_drawing()) if tl.rows is not None \
                else "mechanism"
            return
        i = tl.rows.index_at(t)
        if i < 0:
            return
        # guides span what the sliders reach (the shared scene: SharedRun.scene); each is drawn
        # where this row puts it (a guide on a moving body turns with it), as are the ground marks
        self.scene = self.shared.scene(self.geometry)
        row = {c: tl.rows.column(c)[i] for c in tl.rows.columns}
        frame = self.geometry.frame(row, self.scene)
        self.src["guides"].data = {"xs": [list(g[0]) for g in frame.guides], "ys": [list(g[1]) for g in frame.guides]}
        self.src["ground"].data = {"x": [g[0] for g in frame.ground], "y": [g[1] for g in frame.ground]}
        faulted = set()
        if tl.record is not None:
            faulted = faulted_bodies(self.geometry.drawing, [e.variable for e in tl.record.events if e.first_time <= t])
        self.src["bodies"].data = {"xs": [list(b.xs) for b in frame.bodies], "ys": [list(b.ys) for b in frame.bodies],
                                   "colour": [COLOURS["faulted" if b.name in faulted else "body"] for b in frame.bodies],
                                   "name": [b.name for b in frame.bodies]}
        self.src["joints"].data = {"x": [j[1] for j in frame.joints], "y": [j[2] for j in frame.joints],
                                   "name": [j[0] for j in frame.joints], "time": [frame.time] * len(frame.joints)}
        self.mechanism.title.text = f"{self.geometry.drawing.mechanism} at t = {t:.2f} s"

    def _why_no_drawing(self) -> str:
        r = self.timeline.record
        if r is None:
            return "run.json could not be read"
        if r.drawing is None:
            return "the run recorded no joint positions (its FMU declares no drawing, or [outputs] drawing = false)"
        return f"{EXCHANGE} lacks the drawing's columns"

    def _set_facts(self) -> None:
        r = self.timeline.record
        if r is None:
            return
        events = "".join(f"<li>{html.escape(_event_text(e))}</li>" for e in r.events) or "<li>none</li>"
        fmu = r.fmu.model_name if r.fmu is not None else "?"
        if r.system is not None:
            drawn = f", the mechanism is {r.system.drawing}'s" if r.system.drawing else ""
            fmu = f"system {r.system.name} ({', '.join(c.name for c in r.system.components)}{drawn})"
        self.facts.object = (f'<div id="facts"><b>case</b> {html.escape(r.case or "?")}<br>'
                             f'{html.escape(r.description or "")}<br><b>FMU</b> {html.escape(fmu)}<br>'
                             f'<b>status</b> <span id="status">{html.escape(r.status)}</span>, '
                             f'{r.rows_written or 0} rows written<br><b>events</b><ul>{events}</ul></div>')

    def _set_notice(self) -> None:
        tl = self.timeline
        lines = []
        if tl.record_problem:
            lines.append(tl.record_problem)
        if tl.record is not None and tl.record.status == "failed":
            lines.append(f"the run failed: {tl.record.error}")
        if tl.writer_gone:
            lines.append("the run's writer is gone: run.json still says running, but no process writes it")
        lines.extend(tl.warnings[-3:])
        self.notice.object = ('<div id="notice" style="color:#8a4b00">' + "<br>".join(html.escape(x) for x in lines)
                              + "</div>") if lines else ""


def _event_text(e) -> str:
    if hasattr(e, "value"):
        return f"t = {e.time:g} s: {e.variable} -> {e.value}"
    return f"{e.start:g}-{e.end:g} s: {e.variable} {e.from_:g} -> {e.to:g} (ramp)"
