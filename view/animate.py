"""A run folder as an animation for a report: the mechanism beside its monitored signal.

:func:`animate` reads the folder once (:class:`~view.sources.RunFolder`, the whole run as it is
now) and writes a GIF (matplotlib's Pillow writer) or an MP4 (its FFmpeg writer, when ffmpeg is
installed).  Each frame shows, left, the mechanism drawn by :class:`~view.geometry.Geometry`
(bodies as thick lines or boxes, joints as circles, ground joints on a triangle, prismatic
guides as thin lines; a body a fault changes turns :data:`FAULT_COLOUR` after the fault) and,
right, the monitored signal up to the frame's time: the monitor's ``forecast.csv`` (its first
signal's value and forecast) when the monitor ran, else the run's first recorded output, with
a cursor, the fault time, and each alarm (``monitor/events.jsonl``) once the cursor reaches it.

Time.  Frame ``k`` shows the exchange row nearest to ``start + k * speed / fps`` (s), for every
``k`` with that time <= ``stop``: ``floor((stop - start) * fps / speed) + 1`` frames (see
:func:`frame_times`), played at ``fps`` frames per second, so one second of the animation is
``speed`` seconds of the run.  The default window is 5 s before the fault to 10 s after it
(clipped to the run; a run shorter than that window is shown whole; without a fault the window
is anchored on the first alarm, else on the run's start).  The row at the fault time still shows
the old state (docs/contracts.md), so a faulted body changes colour on the first row after it.

Size.  Each frame is reduced, as it is grabbed, to one fixed palette of 37 colours (the six
drawing colours, each with five anti-aliasing blends towards white, and white) without
dithering, so every frame has the same few colours and Pillow writes only the small rectangle
that changed.  Measured on Case 2 with the defaults (native FMU, monitored; 5 to 20 s at 20
frames per second, 640 x 320 px, 301 frames): 0.72 MB (matplotlib's plain Pillow writer, a
palette per frame: 2.77 MB), 11-25 s on a loaded two-core machine, 290 MB resident at most.
"""
from __future__ import annotations

import math
import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from fourbar_common import Drawing, RampEvent, StepEvent
from fourbar_common.contract.layout import EXCHANGE, FORECAST
from fourbar_common.contract.run_record import RunRecord

from .geometry import Geometry, faulted_bodies
from .sources import MonitorEvent, RunFolder

__all__ = ["AnimationError", "AnimationResult", "FAULT_COLOUR", "animate", "default_window", "frame_times",
           "mechanism_axes"]

#: Seconds of the run shown before and after the fault by default.
BEFORE_FAULT_S = 5.0
AFTER_FAULT_S = 10.0
#: Defaults: 20 frames per second, one run second per animation second, 640 px wide.
DEFAULT_FPS = 20.0
DEFAULT_SPEED = 1.0
DEFAULT_WIDTH_PX = 640
#: The figure is 6.4 x 3.2 in (the mechanism's square panel and the signal) at whatever
#: resolution gives the width asked for, so text and lines keep their proportions at any width.
FIGURE_INCHES = (6.4, 3.2)
MIN_WIDTH_PX, MAX_WIDTH_PX = 320, 3840

#: The drawing's colours (few, so the GIF's palette stays small).
INK = "#1a1a1a"              # text, joint rims
BODY_COLOUR = "#1f4e79"      # bodies before a fault, and the signal's value
FAULT_COLOUR = "#c62828"     # a body after a fault changed it, and the fault time's line
FORECAST_COLOUR = "#e08a00"  # the monitor's forecast
ALARM_COLOUR = "#6a1b9a"     # an alarm's line
GROUND_COLOUR = "#8c8c8c"    # ground triangles, guides, the cursor
WHITE = "#ffffff"
#: Each colour with this many blends towards white (anti-aliased edges) makes the palette.
BLENDS = 5

SUFFIXES = {".gif": "pillow", ".mp4": "ffmpeg"}


def mechanism_axes() -> tuple[float, float, float, float]:
    """The mechanism panel's (left, bottom, width, height) as fractions of the figure: a square
    (its limits are the scene's square extent, so a metre is as many pixels across as up)."""
    side = 0.90 * FIGURE_INCHES[1] / FIGURE_INCHES[0]
    return (0.01, 0.02, side, 0.90)


class AnimationError(ValueError):
    """An animation that cannot be made; the message names the option or file and the fix."""


@dataclass(frozen=True)
class AnimationResult:
    """What :func:`animate` wrote."""

    path: Path
    frames: int
    start: float                   # s, the run time of the first frame
    stop: float                    # s, the run time of the last frame
    bytes: int
    signal: str                    # the column shown on the right
    not_drawn: str | None = None   # why the mechanism is not drawn (None: it is)

    @property
    def seconds(self) -> float:
        """Seconds of the run the animation covers."""
        return self.stop - self.start


def default_window(first: float, last: float, fault_time: float | None,
                   alarm_time: float | None = None) -> tuple[float, float]:
    """The default (start, stop) in s for a run from ``first`` to ``last`` (module docstring)."""
    span = BEFORE_FAULT_S + AFTER_FAULT_S
    if last - first <= span:
        return first, last
    anchor = fault_time if fault_time is not None else alarm_time
    if anchor is None:
        return first, first + span
    start = min(max(first, anchor - BEFORE_FAULT_S), last - span)
    return start, start + span


def frame_times(start: float, stop: float, fps: float, speed: float) -> np.ndarray:
    """The run times (s) of the frames: ``start + k * speed / fps`` up to ``stop``.

    The count is computed from an integer (``floor((stop - start) * fps / speed)``, with a
    tolerance of 1e-9 frames so a window that is a whole number of frame steps ends on its
    ``stop`` despite round-off), never by adding steps.
    """
    n = int(math.floor((stop - start) * fps / speed + 1e-9)) + 1
    return start + np.arange(n) * (speed / fps)


def _check_writable(out: Path) -> None:
    """:class:`AnimationError` naming ``out`` when the animation could not be written there: its
    folder is missing or not a folder, ``out`` is a folder, or the folder refuses a new file
    (tried with a probe file, removed at once).  Checked before any frame is drawn: a few hundred
    frames take tens of seconds, and the file is written only after the last."""
    folder = out.parent
    if not folder.exists():
        raise AnimationError(f"{out}: the folder {folder} does not exist; create it first")
    if not folder.is_dir():
        raise AnimationError(f"{out}: {folder} is not a folder; name the animation inside a folder")
    if out.is_dir():
        raise AnimationError(f"{out}: is a folder; name the animation file, e.g. {out / 'run.gif'}")
    probe = folder / f".{out.stem}.probe-{secrets.token_hex(6)}{out.suffix}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise AnimationError(f"{out}: cannot write in {folder} ({exc.strerror or exc}); choose a writable "
                             f"folder") from None
    os.close(fd)
    probe.unlink(missing_ok=True)


def _check_options(out: Path, fps: float, speed: float, width_px: int) -> str:
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise AnimationError(f"{out}: cannot write a {suffix or 'suffix-less'} file; the animation is written as "
                             f".gif (Pillow) or .mp4 (ffmpeg): name the output e.g. {out.with_suffix('.gif').name}")
    _check_writable(out)
    writer = SUFFIXES[suffix]
    from matplotlib import animation

    if writer == "ffmpeg" and not animation.writers.is_available("ffmpeg"):
        raise AnimationError(f"{out}: an .mp4 needs ffmpeg, which is not on PATH (install it, e.g. "
                             f"`apt-get install ffmpeg` or `conda install ffmpeg`), or write a .gif instead")
    for name, value in (("fps", fps), ("speed", speed)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise AnimationError(f"{name} = {value!r}; expected a positive number"
                                 + (" (frames per second)" if name == "fps" else " (run seconds per animation second)"))
    if isinstance(width_px, bool) or not isinstance(width_px, int) or not MIN_WIDTH_PX <= width_px <= MAX_WIDTH_PX:
        raise AnimationError(f"width_px = {width_px!r}; expected a whole number of pixels from {MIN_WIDTH_PX} "
                             f"to {MAX_WIDTH_PX}")
    return writer


# -- what the folder says ------------------------------------------------------------------


@dataclass(frozen=True)
class _Run:
    record: RunRecord
    rows: pd.DataFrame
    forecast: pd.DataFrame | None
    events: tuple[MonitorEvent, ...]


def _read(folder) -> _Run:
    source = RunFolder(folder)           # RunFolderError when it is not a run folder
    update = source.poll()
    if source.record is None:
        raise AnimationError(f"{source.folder}: run.json cannot be read: {update.record_problem}")
    rows = update.rows
    if rows is None or not len(rows) or "time" not in rows.columns:
        raise AnimationError(f"{source.folder}/{EXCHANGE}: no rows yet (the run has not written any); "
                             f"animate it once it has")
    rows = rows[np.isfinite(rows["time"].to_numpy(float))].sort_values("time").reset_index(drop=True)
    return _Run(record=source.record, rows=rows, forecast=update.forecast, events=tuple(update.events))


@dataclass(frozen=True)
class _Signal:
    name: str
    time: np.ndarray
    value: np.ndarray
    forecast: np.ndarray | None          # None: no forecast (the monitor did not run)
    source: str                          # what the panel says the curve is


def _signal(run: _Run) -> _Signal:
    f = run.forecast
    if f is not None and len(f) and {"signal", "value", "forecast"} <= set(f.columns):
        name = str(f["signal"].iloc[0])
        one = f[f["signal"] == name]
        return _Signal(name, one["time"].to_numpy(float), one["value"].to_numpy(float),
                       one["forecast"].to_numpy(float), "monitor")
    drawn = set(run.record.drawing.columns) if run.record.drawing is not None else set()
    candidates = [c for c in run.record.outputs if c in run.rows.columns and c not in drawn] \
        or [c for c in run.record.outputs if c in run.rows.columns] \
        or [c for c in run.rows.columns if c != "time"]
    if not candidates:
        raise AnimationError(f"{EXCHANGE} has no column besides time: nothing to show")
    name = candidates[0]
    return _Signal(name, run.rows["time"].to_numpy(float), run.rows[name].to_numpy(float), None, "exchange")


def _not_drawn(record: RunRecord, rows: pd.DataFrame) -> str | None:
    drawing = record.drawing
    if drawing is None:
        return ("run.json records no drawing (the FMU declares none, or the run was recorded "
                "with [outputs] drawing = false)")
    lacking = Geometry(drawing).lacking(rows.columns)
    if lacking:
        return f"{EXCHANGE} lacks the drawing's column(s) {', '.join(lacking)}"
    return None


def _describe(event) -> str:
    if isinstance(event, StepEvent):
        return f"{event.variable} = {event.value:g} at {event.time:g} s" if isinstance(event.value, (int, float)) \
            else f"{event.variable} = {event.value} at {event.time:g} s"
    if isinstance(event, RampEvent):
        return f"{event.variable} {event.from_:g} -> {event.to:g} over {event.start:g}-{event.end:g} s"
    return str(event)


def _fault_times(drawing: Drawing, events) -> dict[str, float]:
    """Each faulted body's name and the time (s) after which it is drawn in the fault's colour."""
    first: dict[str, float] = {}
    for event in events:
        for body in faulted_bodies(drawing, [event.variable]):
            first[body] = min(first.get(body, math.inf), float(event.first_time))
    return first


# -- the figure ----------------------------------------------------------------------------


def _palette_image():
    """A Pillow "P" image holding the fixed palette: each drawing colour and its blends to white."""
    from matplotlib.colors import to_rgb
    from PIL import Image

    colours = []
    for c in (INK, BODY_COLOUR, FAULT_COLOUR, FORECAST_COLOUR, ALARM_COLOUR, GROUND_COLOUR):
        rgb = np.array(to_rgb(c))
        for k in range(BLENDS + 1):
            f = k / (BLENDS + 1)
            colours.append(tuple(int(round(255 * (v * (1 - f) + f))) for v in rgb))
    colours.append((255, 255, 255))
    flat = [v for rgb in colours for v in rgb]
    image = Image.new("P", (1, 1))
    image.putpalette(flat + flat[-3:] * (256 - len(colours)))
    return image


def _writer_class(kind: str):
    """matplotlib's writer for ``kind``; the Pillow one reduces each frame to the fixed palette
    as it is grabbed (smaller GIF, and a frame kept in memory is one byte per pixel)."""
    from matplotlib import animation

    if kind == "ffmpeg":
        return animation.FFMpegWriter
    from PIL import Image

    class PaletteGifWriter(animation.PillowWriter):
        palette = _palette_image()

        def grab_frame(self, **savefig_kwargs):
            super().grab_frame(**savefig_kwargs)
            self._frames[-1] = self._frames[-1].convert("RGB").quantize(palette=self.palette,
                                                                      dither=Image.Dither.NONE)

    return PaletteGifWriter


class _Picture:
    """The figure and the artists each frame updates."""

    def __init__(self, run: _Run, signal: _Signal, start: float, stop: float, width_px: int,
                 not_drawn: str | None, window_rows: pd.DataFrame):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.lines import Line2D
        from matplotlib.patches import Polygon

        width = 4 * (width_px // 4)            # the height (half) even too: an .mp4's frame size must be
        self.dpi = width / FIGURE_INCHES[0]
        self.fig = Figure(figsize=FIGURE_INCHES, dpi=self.dpi, facecolor=WHITE)
        FigureCanvasAgg(self.fig)
        self.record = run.record
        self.signal = signal
        case = run.record.case or Path(str(run.record.case_file or "run")).stem
        self.case = case
        self.title = self.fig.text(0.015, 0.965, "", ha="left", va="top", fontsize=10, color=INK)
        side = mechanism_axes()[2]
        self.ax_m = self.fig.add_axes(mechanism_axes())
        self.ax_s = self.fig.add_axes((side + 0.10, 0.14, 0.97 - side - 0.10, 0.72))
        self.ax_m.set_axis_off()
        self.ax_m.set_aspect("equal")

        # -- the mechanism
        self.geometry: Geometry | None = None
        self.bodies: dict[str, object] = {}
        self.fault_after: dict[str, float] = {}
        self.fault_note = None
        if not_drawn is None:
            self.geometry = Geometry(run.record.drawing)
            self.scene = self.geometry.scene(window_rows)
            self.ax_m.set_xlim(*self.scene.x_range)
            self.ax_m.set_ylim(*self.scene.y_range)
            # the guides and the ground marks are placed at each frame (Geometry.frame): a guide
            # on a moving body turns with it, and a fault may move a ground point
            self.guides = [Line2D((), (), lw=1.0, color=GROUND_COLOUR, zorder=1) for _ in self.scene.guide_spans]
            for line in self.guides:
                self.ax_m.add_line(line)
            self.ground = [Polygon(np.zeros((3, 2)), closed=True, facecolor=GROUND_COLOUR, edgecolor=GROUND_COLOUR,
                                   lw=0.8, zorder=1)
                           for j in run.record.drawing.joints if j.ground and j.type == "revolute"]
            for patch in self.ground:
                self.ax_m.add_patch(patch)
            for body in run.record.drawing.bodies:
                if body.kind == "rod":
                    artist = Line2D((), (), lw=5, color=BODY_COLOUR, solid_capstyle="round", zorder=2)
                    self.ax_m.add_line(artist)
                else:
                    artist = Polygon(np.zeros((4, 2)), closed=True, facecolor=BODY_COLOUR, edgecolor=INK,
                                     lw=1.0, zorder=2)
                    self.ax_m.add_patch(artist)
                self.bodies[body.name] = artist
            self.joints = Line2D((), (), ls="none", marker="o", ms=6, mfc=WHITE, mec=INK, mew=1.2, zorder=3)
            self.ax_m.add_line(self.joints)
            self.fault_after = _fault_times(run.record.drawing, run.record.events)
            if self.fault_after:
                changed = ", ".join(sorted(self.fault_after))
                what = "; ".join(_describe(e) for e in run.record.events)
                self.fault_note = self.ax_m.text(0.5, 0.01, f"{changed}: {what}", transform=self.ax_m.transAxes,
                                                 ha="center", va="bottom", fontsize=7, color=FAULT_COLOUR,
                                                 visible=False, wrap=True)
        else:
            self.ax_m.text(0.5, 0.5, "mechanism not drawn:\n" + _wrap(not_drawn, 34), transform=self.ax_m.transAxes,
                           ha="center", va="center", fontsize=8, color=INK)

        # -- the signal
        ax = self.ax_s
        inside = (signal.time >= start) & (signal.time <= stop)
        shown = [signal.value[inside]] + ([signal.forecast[inside]] if signal.forecast is not None else [])
        values = np.concatenate(shown) if shown else np.array([])
        values = values[np.isfinite(values)]
        lo, hi = (float(values.min()), float(values.max())) if len(values) else (-1.0, 1.0)
        pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.1
        ax.set_xlim(start, stop if stop > start else start + 1.0)
        ax.set_ylim(lo - pad, hi + pad)
        unit = run.record.units.get(signal.name, "") if run.record.units else ""
        ax.set_ylabel(f"{signal.name} ({unit})" if unit else signal.name, fontsize=8, color=INK)
        ax.set_xlabel("time (s)", fontsize=8, color=INK)
        ax.tick_params(labelsize=7, colors=INK)
        for spine in ax.spines.values():
            spine.set_color(GROUND_COLOUR)
        self.value_line, = ax.plot((), (), lw=1.2, color=BODY_COLOUR, label="value")
        self.forecast_line = None
        if signal.forecast is not None:
            self.forecast_line, = ax.plot((), (), lw=1.0, ls="--", color=FORECAST_COLOUR, label="forecast")
        self.fig.legend(loc="upper right", bbox_to_anchor=(0.99, 0.99), fontsize=7, frameon=False, ncol=2,
                        borderaxespad=0.0)
        fault = run.record.fault_time
        if fault is None and run.record.events:
            fault = min(float(e.first_time) for e in run.record.events)
        if fault is not None and start <= fault <= stop:
            ax.axvline(fault, color=FAULT_COLOUR, lw=1.0, ls=":")
            ax.text(fault, 1.0, " fault", transform=ax.get_xaxis_transform(), ha="left", va="bottom",
                    fontsize=7, color=FAULT_COLOUR)
        self.alarms = []
        for e in run.events:
            if e.event == "alarm" and start <= e.time <= stop:
                line = ax.axvline(e.time, color=ALARM_COLOUR, lw=1.2, visible=False)
                label = ax.text(e.time, 0.02, " alarm", transform=ax.get_xaxis_transform(), ha="left",
                                va="bottom", fontsize=7, color=ALARM_COLOUR, visible=False)
                self.alarms.append((e.time, line, label))
        self.cursor = ax.axvline(start, color=GROUND_COLOUR, lw=1.0)
        self.fig.text(0.99, 0.01, f"monitor {FORECAST}" if signal.source == "monitor" else EXCHANGE,
                      ha="right", va="bottom", fontsize=6, color=GROUND_COLOUR)

    def show(self, time: float, row: pd.Series) -> None:
        """Update every artist to the run at ``time`` (s), ``row`` the exchange row shown."""
        self.title.set_text(f"{self.case}    t = {time:7.2f} s")
        if self.geometry is not None:
            frame = self.geometry.frame(row, self.scene)
            for line, ((x0, x1), (y0, y1)) in zip(self.guides, frame.guides):
                line.set_data((x0, x1), (y0, y1))
            b = self.scene.block_size
            for patch, (gx, gy) in zip(self.ground, frame.ground):
                patch.set_xy(((gx, gy), (gx - 0.6 * b, gy - b), (gx + 0.6 * b, gy - b)))
            for shape in frame.bodies:
                artist = self.bodies[shape.name]
                faulted = time > self.fault_after.get(shape.name, math.inf)
                colour = FAULT_COLOUR if faulted else BODY_COLOUR
                artist.set_zorder(2.5 if faulted else 2)      # a faulted body in front of the others
                if shape.kind == "rod":
                    artist.set_data(shape.xs, shape.ys)
                    artist.set_color(colour)
                else:
                    artist.set_xy(np.column_stack((shape.xs, shape.ys)))
                    artist.set_facecolor(colour)
            self.joints.set_data([x for _, x, _ in frame.joints], [y for _, _, y in frame.joints])
            if self.fault_note is not None:
                self.fault_note.set_visible(any(time > t for t in self.fault_after.values()))
        s = self.signal
        upto = s.time <= time + 1e-9
        self.value_line.set_data(s.time[upto], s.value[upto])
        if self.forecast_line is not None:
            self.forecast_line.set_data(s.time[upto], s.forecast[upto])
        self.cursor.set_xdata((time, time))
        for when, line, label in self.alarms:
            line.set_visible(time >= when)
            label.set_visible(time >= when)


def _wrap(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))


# -- the one public function ---------------------------------------------------------------


def animate(folder: str | os.PathLike[str], out_path: str | os.PathLike[str], *, fps: float = DEFAULT_FPS,
            speed: float = DEFAULT_SPEED, start: float | None = None, stop: float | None = None,
            width_px: int = DEFAULT_WIDTH_PX,
            progress: Callable[[int, int], None] | None = None) -> AnimationResult:
    """Write the run in ``folder`` as an animation to ``out_path`` (.gif, or .mp4 with ffmpeg).

    ``fps`` frames per second; ``speed`` run seconds per animation second; ``start``, ``stop``
    the run times (s) shown (defaults: :func:`default_window`; one given, the other is 15 s
    away, clipped to the run); ``width_px`` the frame's width in pixels (rounded down to a
    multiple of 4; the height is half of it).  ``progress(done, total)`` is called after each
    frame is drawn (the GIF is then written in one go, a second or two for a few hundred frames).

    Raises :class:`~view.sources.RunFolderError` when ``folder`` is not a run folder and
    :class:`AnimationError` for a bad option or a run with nothing to show.
    """
    out = Path(out_path)
    writer_kind = _check_options(out, fps, speed, width_px)
    run = _read(folder)
    times = run.rows["time"].to_numpy(float)
    first, last = float(times[0]), float(times[-1])
    span = BEFORE_FAULT_S + AFTER_FAULT_S
    for name, value in (("start", start), ("stop", stop)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                  or not first <= value <= last):
            raise AnimationError(f"{name} = {value!r} s; the run's {EXCHANGE} covers {first:g} to {last:g} s")
    if start is None and stop is None:
        alarm = next((e.time for e in run.events if e.event == "alarm"), None)
        start, stop = default_window(first, last, run.record.fault_time, alarm)
    elif stop is None:
        stop = min(last, start + span)
    elif start is None:
        start = max(first, stop - span)
    start, stop = float(start), float(stop)
    if stop < start:
        raise AnimationError(f"start = {start:g} s is after stop = {stop:g} s")

    wanted = frame_times(start, stop, fps, speed)
    index = np.clip(np.searchsorted(times, wanted), 1, len(times) - 1) if len(times) > 1 else np.zeros(len(wanted), int)
    if len(times) > 1:
        nearer_left = np.abs(times[index - 1] - wanted) <= np.abs(times[index] - wanted)
        index = np.where(nearer_left, index - 1, index)
    window_rows = run.rows.iloc[np.unique(index)]
    not_drawn = _not_drawn(run.record, run.rows)
    signal = _signal(run)
    picture = _Picture(run, signal, float(times[index[0]]), float(times[index[-1]]), width_px, not_drawn, window_rows)

    writer = _writer_class(writer_kind)(fps=fps)
    total = len(index)
    # written beside the output and renamed when complete: an error or Ctrl-C midway leaves no
    # partial animation (matplotlib's writers finish the file even then) and any older one intact
    partial = out.with_name(f".{out.stem}.partial{out.suffix}")
    try:
        with writer.saving(picture.fig, str(partial), dpi=picture.dpi):
            for k, i in enumerate(index):
                picture.show(float(times[i]), run.rows.iloc[i])
                writer.grab_frame()
                if progress is not None:
                    progress(k + 1, total)
        os.replace(partial, out)
    finally:
        partial.unlink(missing_ok=True)
    return AnimationResult(path=out, frames=total, start=float(times[index[0]]), stop=float(times[index[-1]]),
                           bytes=out.stat().st_size, signal=signal.name, not_drawn=not_drawn)
