"""What a diagnosis writes: ``diagnosis.json`` and ``diagnosis.png``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fourbar_common import write_json_atomic

from .diagnosis import Diagnosis

__all__ = ["write_outputs"]


def write_outputs(diagnosis: Diagnosis, out_dir: str | Path, plot: bool = True) -> list[Path]:
    """Write diagnosis.json (and diagnosis.png) into ``out_dir``; return the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "diagnosis.json"]
    write_json_atomic(written[0], diagnosis.to_json())
    if plot and diagnosis.curves is not None:
        written.append(_plot(diagnosis, out / "diagnosis.png"))
    return written


def _plot(d: Diagnosis, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = d.curves
    ncol = len(d.columns)
    fig, axes = plt.subplots(ncol + 1, 1, figsize=(10, 2.0 * ncol + 3.2), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for i, name in enumerate(d.columns):
        ax = axes[i]
        unit = d.units.get(name, "")
        ax.plot(c.time, c.data[:, i], ".", ms=2, color="0.55", label="data (exchange.csv)")
        ax.plot(c.time, c.healthy[:, i], "-", lw=1.0, color="tab:blue", label="healthy model (run.json)")
        if d.best is not None:
            ax.plot(c.time, c.model[:, i], "-", lw=1.2, color="tab:red", label=f"best explanation: {d.best.parameter}")
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
    # Residuals against the healthy model and the best explanation, scaled by the noise.
    sigma = np.array([d.noise[n] for n in d.columns])
    ax = axes[-1]
    ax.plot(c.time, np.sqrt(np.mean(np.square((c.data - c.healthy) / sigma), axis=1)), lw=0.8, color="tab:blue",
            label="data − healthy")
    ax.plot(c.time, np.sqrt(np.mean(np.square((c.data - c.model) / sigma), axis=1)), lw=0.8, color="tab:red",
            label="data − best explanation")
    ax.set_yscale("log")
    ax.set_ylabel("residual / noise\n(RMS over columns)")
    ax.set_xlabel("time [s]")
    for ax in axes:
        ax.axvline(d.alarm_time, color="k", ls="--", lw=0.8)
        ax.axvspan(c.time[0], c.fit_from, color="0.92", lw=0)
        if d.best is not None:
            ax.axvline(d.best.change_time, color="tab:red", ls=":", lw=1.0)
            if d.best.kind == "ramp":
                ax.axvspan(d.best.change_time, d.best.end_time, color="tab:red", alpha=0.08, lw=0)
    axes[0].legend(loc="upper left", fontsize=8, ncol=3)
    axes[-1].legend(loc="upper left", fontsize=8)
    axes[0].text(d.alarm_time, 1.02, " alarm", transform=axes[0].get_xaxis_transform(), fontsize=8)
    axes[0].text(c.time[0], 1.02, " noise estimate", transform=axes[0].get_xaxis_transform(), fontsize=8)
    title = {"explained": "Diagnosis", "unexplained": "Not explained by one parameter",
             "no_change": "No change found"}[d.verdict]
    fig.suptitle(f"{title} — {d.case}\n{_wrap(d.message)}", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _wrap(text: str, width: int = 150) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))
