"""What a diagnosis writes: ``diagnosis.json`` and ``diagnosis.png``, and the check that it can.

:func:`prepare_out_dir` runs before the diagnosis (which takes seconds to minutes): it
creates the output folder and a probe file there, so an unusable ``--out`` (a file, a
read-only folder) is refused before anything is computed.  :func:`write_outputs` writes
each file atomically (a reader sees the old file or the new one); when one cannot be
written it raises :class:`OutputError`, which says which files were written and which not.
"""
from __future__ import annotations

import os
import secrets
from pathlib import Path
from typing import Any

import numpy as np

from fourbar_common import replace_atomically
from fourbar_common.contract.diagnosis import write_diagnosis
from fourbar_common.contract.layout import DIAGNOSIS, EXCHANGE

from .diagnosis import Diagnosis
from .errors import DiagnoseError

__all__ = ["OUTPUT_FILES", "OutputError", "diagnosis_figure", "prepare_out_dir", "remove_empty", "write_outputs"]

#: The files a diagnosis writes into its output folder (the plot unless --no-plot).
OUTPUT_FILES = (DIAGNOSIS, "diagnosis.png")


class OutputError(OSError):
    """An output file could not be written after the diagnosis was computed.

    ``written`` are the files written before ``path`` failed (with ``reason``);
    ``not_written`` is ``path`` and every file that was to follow it.
    """

    def __init__(self, path: Path, reason: str, written: list[Path], not_written: list[Path]):
        super().__init__(f"{path}: {reason}")
        self.path, self.reason = path, reason
        self.written, self.not_written = written, not_written


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def prepare_out_dir(out_dir: str | Path, plot: bool = True) -> list[Path]:
    """Make sure ``out_dir`` can receive the outputs, before the diagnosis runs.

    Creates the folder (and missing parents) and a probe file in it, removed at once.
    Returns the folders it created, deepest first (:func:`remove_empty` removes them again
    when the diagnosis then stops).  Raises :class:`~diagnose.errors.DiagnoseError` naming
    the path: ``out_dir`` or a parent is a file, cannot be created, is not writable, or one
    of its output files is a folder.
    """
    out = Path(out_dir)
    where = f"--out {out}"
    names = OUTPUT_FILES if plot else OUTPUT_FILES[:1]
    created: list[Path] = []
    try:
        if out.exists() and not out.is_dir():
            raise DiagnoseError(f"{where}: exists and is not a folder; --out names the folder that receives "
                                f"{' and '.join(names)}")
        missing = []
        parent = out
        while not parent.exists() and parent.parent != parent:
            missing.append(parent)
            parent = parent.parent
        if not parent.is_dir():
            raise DiagnoseError(f"{where}: {parent} is not a folder, so {missing[-1].name}/ cannot be created in it")
        for folder in reversed(missing):
            try:
                folder.mkdir()
            except FileExistsError:
                continue
            except OSError as exc:
                raise DiagnoseError(f"{where}: cannot create the folder {folder}: {_reason(exc)}; choose a writable "
                                    "folder with --out") from None
            created.insert(0, folder)
        for name in names:
            if (out / name).is_dir():
                raise DiagnoseError(f"{where}: {out / name} is a folder; remove it or choose another --out")
        probe = out / f".diagnosis-probe-{secrets.token_hex(6)}"
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        os.close(fd)
        probe.unlink()
    except OSError as exc:
        remove_empty(created)
        raise DiagnoseError(f"{where}: cannot write there: {_reason(exc)}; choose a writable folder with --out") \
            from None
    except DiagnoseError:
        remove_empty(created)
        raise
    return created


def remove_empty(folders: list[Path]) -> None:
    """Remove the folders (deepest first) that are still empty; leave the rest."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            pass


def write_outputs(diagnosis: Diagnosis, out_dir: str | Path, plot: bool = True) -> list[Path]:
    """Write diagnosis.json (and diagnosis.png) into ``out_dir``; return the paths written.

    Raises :class:`OutputError` (which lists what was written) when a file cannot be written.
    """
    out = Path(out_dir)
    targets = [out / OUTPUT_FILES[0]]
    if plot and diagnosis.curves is not None:
        targets.append(out / OUTPUT_FILES[1])
    written: list[Path] = []
    for i, path in enumerate(targets):
        try:
            if i == 0:
                out.mkdir(parents=True, exist_ok=True)
                write_diagnosis(path, diagnosis.record())
            else:
                _plot(diagnosis, path)
        except OSError as exc:
            raise OutputError(path, _reason(exc), written, targets[i:]) from None
        written.append(path)
    return written


def diagnosis_figure(d: Diagnosis) -> Any:
    """diagnosis.png as a matplotlib Figure (Agg canvas, no pyplot); ``d.curves`` must be set.

    One panel per fitted column (data, healthy model, best explanation) and one of the
    residuals.  The estimated change time (red dots, on top) and the first alarm (black,
    wider, beneath) are drawn on every panel and named with their times in the legend, which
    sits to the right of the panels so it never covers the data.  Artists carry gids:
    ``change`` and ``alarm`` (the lines), ``legend``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c = d.curves
    ncol = len(d.columns)
    fig = Figure(figsize=(12.5, 2.0 * ncol + 3.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(ncol + 1, 1, sharex=True, squeeze=False)[:, 0]
    for i, name in enumerate(d.columns):
        ax = axes[i]
        unit = d.units.get(name, "")
        ax.plot(c.time, c.data[:, i], ".", ms=2, color="0.55", label=f"data ({EXCHANGE})")
        ax.plot(c.time, c.healthy[:, i], "-", lw=1.0, color="tab:blue", label="healthy model (run.json)")
        if d.best is not None:
            ax.plot(c.time, c.model[:, i], "-", lw=1.2, color="tab:red", label=f"best explanation: {d.best.parameter}")
        ax.set_ylabel(f"{name} ({unit})" if unit else name)
    # Residuals against the healthy model and the best explanation, scaled by the noise.
    sigma = np.array([d.noise[n] for n in d.columns])
    ax = axes[-1]
    ax.plot(c.time, np.sqrt(np.mean(np.square((c.data - c.healthy) / sigma), axis=1)), lw=0.8, color="tab:blue",
            label="data − healthy")
    ax.plot(c.time, np.sqrt(np.mean(np.square((c.data - c.model) / sigma), axis=1)), lw=0.8, color="tab:red",
            label="data − best explanation")
    ax.set_yscale("log")
    ax.set_ylabel("residual / noise\n(RMS over columns)")
    ax.set_xlabel("time (s)")
    best = d.best
    for i, ax in enumerate(axes):
        first = i == 0
        ax.axvline(d.alarm_time, color="k", lw=2.4, alpha=0.45, zorder=5, gid="alarm",
                   label=f"first alarm {d.alarm_time:g} s" if first else None)
        ax.axvspan(c.time[0], c.fit_from, color="0.92", lw=0,
                   label=f"noise estimate {c.time[0]:g}–{c.fit_from:g} s" if first else None)
        if best is not None:
            ax.axvline(best.change_time, color="tab:red", ls=(0, (2, 1.5)), lw=1.4, zorder=6, gid="change",
                       label=f"estimated change {best.change_time:.2f} s" if first else None)
            if best.kind == "ramp":
                ax.axvspan(best.change_time, best.end_time, color="tab:red", alpha=0.08, lw=0,
                           label=f"ramp {best.change_time:.2f}–{best.end_time:.2f} s" if first else None)
    # the legends beside the panels (outside the axes), never on the data
    legend = axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)
    legend.set_gid("legend")
    axes[-1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)
    title = {"explained": "Diagnosis", "unexplained": "Not explained by one parameter",
             "no_change": "No change found", "ambiguous": "Ambiguous: two explanations fit"}[d.verdict]
    fig.suptitle(f"{title} — {d.case}\n{_wrap(d.message)}", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def _plot(d: Diagnosis, path: Path) -> Path:
    fig = diagnosis_figure(d)
    replace_atomically(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return path


def _wrap(text: str, width: int = 160) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))
