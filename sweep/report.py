"""What a sweep found: per-group detection figures, the headline, and the plots.

Groups ("series") are the settings a reader compares: noise level, monitor model and
threshold -- and the changed parameter, the fault kind (and ramp duration) when the sweep
has more than one.  Fault-free runs change no parameter: each group is judged with the
fault-free runs of its noise level, model and threshold.
Fault sizes are the absolute relative change ``|relative_change|``; when a sweep samples
more than ``MAX_EXACT_SIZES`` distinct sizes they are pooled into log-spaced bins.

Headline (per group): the smallest fault size ``s`` such that *every* finished scenario of
the group with a size ``>= s`` was detected within ``latency_limit`` seconds and raised no
false alarm.  Failed scenarios are not counted (their number is reported).

ROC (per group, scikit-learn ``roc_curve``): a scenario's ``score_pre`` / ``score_early``
(:mod:`sweep.scenario`) is the largest factor ``c`` by which its threshold could be
multiplied and the detector's rule (``persistence`` consecutive windows above) would
still fire before the fault / within ``latency_limit`` after it.  Negatives: every
finished scenario's pre-fault span (``score_pre``; for a fault-free scenario the whole
run); positives: every fault scenario's first ``latency_limit`` seconds after the fault
(``score_early``; 0 when no evaluation fell in them).  Sweeping ``c`` traces the curve;
the marked point is ``c = 1``, the threshold actually used.

Delay against ARL0 (cusum only, :func:`delay_curves`): for each false-alarm level the
delay the same run would have had with the CUSUM limit ``h(ARL0)``.  At the designed
ARL0 (the run's own ``h``) that is the run's alarm latency, sample by sample -- the
latency detection.png shows.  Below it the statistic is known only as the largest value
of each evaluation interval (``every``, 0.1 s), so the delay is the first evaluation
after the fault at or above ``h(ARL0)``, or the alarm when that is earlier (a limit below
``h`` is reached no later than ``h``): exact within one evaluation interval, never early.
(:func:`sweep.scenario.delays_at_arl0` gives the evaluation-grid delays, which alone put
Case 2's designed-ARL0 delay at 0.1 s against an alarm latency of 0.01 s.)

Series are labelled by the detector actually used (:class:`DetectorDesign`): the CUSUM
with its limit ``h`` and designed ARL0, or the MAE rule with its threshold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

__all__ = ["DetectorDesign", "MAX_EXACT_SIZES", "delay_arl0_figure", "delay_curves", "detection_figure",
           "plot_delay_arl0", "plot_detection", "plot_roc", "run_delays", "series_of", "summarize"]

MAX_EXACT_SIZES = 12
_GROUP = ("noise_std", "model", "threshold")
_FAULT_EXTRA = ("variable", "kind", "ramp_duration")


@dataclass(frozen=True)
class DetectorDesign:
    """The detector a sweep's monitor ran, for labels: ``name`` (``cusum``, ``mae``, ...),
    ``arl0_hours`` (cusum: the designed mean hours between false alarms, 1 / false_alarm_rate)
    and ``every`` (s between evaluations)."""

    name: str
    arl0_hours: float | None = None
    every: float | None = None

    @classmethod
    def from_options(cls, options: Mapping[str, Any]) -> "DetectorDesign":
        """From a sweep's fixed monitor options (``MonitorSpec.options``; defaults from
        :class:`monitor.MonitorOptions` and the detector's own settings for what it does not set)."""
        from monitor import MonitorOptions

        opts = MonitorOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in options.items()})
        return cls(opts.detector, opts.detector_class.designed_arl0_hours(opts.settings), float(opts.every))

    @classmethod
    def inferred(cls, table) -> "DetectorDesign | None":
        """Without the options: the first registered detector with delay-vs-ARL0 curves (the
        cusum) when a row has a delay-vs-ARL0 value (only such detectors write them), else
        unknown (None)."""
        from monitor.detectors import detector_class, detector_names

        from .scenario import ARL0_HOURS, delay_column

        cols = [delay_column(h) for h in ARL0_HOURS if delay_column(h) in table.columns]
        if cols and table[cols].notna().any().any():
            return cls(next(n for n in detector_names() if detector_class(n).arl0_curve))
        return None


def _detector_text(design: DetectorDesign | None, threshold: Any, limits, unit: str = "") -> str:
    """The series' detector (the detector's :meth:`~monitor.detector.Detector.series_text`):
    ``CUSUM h 30.86 (ARL0 100 h)``, ``MAE threshold auto``, ..."""
    if design is None:
        return f"threshold {threshold}"
    from monitor.detectors import detector_class, detector_names

    if design.name not in detector_names():
        return f"{design.name}, threshold {threshold}"
    return detector_class(design.name).series_text(threshold, list(limits), design.arl0_hours, unit)


def _label_parts(key: dict[str, Any], unit: str = "", detector: str | None = None) -> str:
    parts = []
    if key.get("variable") is not None:
        parts.append(str(key["variable"]))
    if "kind" in key and key["kind"] is not None:
        kind = key["kind"]
        if kind == "ramp" and key.get("ramp_duration") is not None:
            kind = f"ramp {key['ramp_duration']:g} s"
        parts.append(kind)
    std = key["noise_std"]
    if std == 0:
        parts.append("no noise")
    elif unit == "m":
        parts.append(f"noise σ = {std * 1000:g} mm")
    else:
        parts.append(f"noise σ = {std:g}{' ' + unit if unit else ''}")
    parts.append(f"{key['model']}, {detector or 'threshold ' + str(key['threshold'])}")
    return ", ".join(parts)


def series_of(table) -> tuple[list[str], list[str]]:
    """(group columns that vary, fault-only columns that vary) of the finished rows."""
    ok = table[table["status"] == "ok"]
    faults = ok[ok["has_fault"].astype(bool)]
    group = list(_GROUP)
    extra = [c for c in _FAULT_EXTRA if faults[c].nunique(dropna=False) > 1]
    return group, extra


def _size_bins(sizes) -> tuple[Any, Any]:
    """(bin index per size, representative size per bin)."""
    import numpy as np

    sizes = np.asarray(sizes, dtype=float)
    unique = np.unique(sizes)
    if unique.size <= MAX_EXACT_SIZES:
        return np.searchsorted(unique, sizes), unique
    lo, hi = float(unique[0]), float(unique[-1])
    edges = np.geomspace(lo, hi * (1 + 1e-12), 9) if lo > 0 else np.linspace(lo, hi * (1 + 1e-12), 9)
    idx = np.clip(np.searchsorted(edges, sizes, side="right") - 1, 0, len(edges) - 2)
    centers = np.sqrt(edges[:-1] * edges[1:]) if lo > 0 else 0.5 * (edges[:-1] + edges[1:])
    return idx, centers


def _groups(table):
    """Yield (key dict, fault rows, fault-free rows, failed count) per series."""
    group, extra = series_of(table)
    ok = table[table["status"] == "ok"]
    failed = table[table["status"] != "ok"]
    has_fault = ok["has_fault"].astype(bool)
    faults, clean = ok[has_fault], ok[~has_fault]
    keys = faults[group + extra].drop_duplicates(ignore_index=True)
    if keys.empty:            # fault-free sweep: one group per setting
        keys = clean[group].drop_duplicates(ignore_index=True)
    for _, key in keys.iterrows():
        k = {c: (None if _isna(key[c]) else key[c]) for c in key.index}
        fmask = _match(faults, k)
        cmask = _match(clean, {c: k[c] for c in group})
        nfail = int(_match(failed, k).sum())
        yield k, faults[fmask], clean[cmask], nfail


def _isna(v) -> bool:
    import pandas as pd

    return v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v))


def _match(df, key: dict[str, Any]):
    import numpy as np

    mask = np.ones(len(df), dtype=bool)
    for c, v in key.items():
        col = df[c]
        if v is None:
            mask &= col.isna().to_numpy()
        else:
            mask &= (col == v).fillna(False).to_numpy(dtype=bool)
    return mask


def _series_label(key: dict[str, Any], rows, unit: str, design: DetectorDesign | None) -> str:
    limits = rows["threshold_base"].tolist() if "threshold_base" in rows.columns else []
    return _label_parts(key, unit, _detector_text(design, key.get("threshold"), limits, unit))


def _design(table, detector: DetectorDesign | None) -> DetectorDesign | None:
    return detector if detector is not None else DetectorDesign.inferred(table)


def summarize(table, latency_limit: float, *, unit: str = "", detector: DetectorDesign | None = None) -> dict[str, Any]:
    """Per-series detection figures and the headline (definitions in the module docstring).

    ``unit`` is the monitored signal's unit (for the series labels); ``detector`` the sweep's
    detector (:meth:`DetectorDesign.from_options`; without it, inferred from the table).
    """
    import numpy as np

    design = _design(table, detector)
    variables = [str(v) for v in table["variable"].dropna().unique()] if len(table) else []
    groups = []
    for key, faults, clean, nfail in _groups(table):
        entry: dict[str, Any] = {"series": _series_label(key, faults if len(faults) else clean, unit, design),
                                 **{k: _py(v) for k, v in key.items()}, "failed": nfail}
        sizes = np.abs(faults["relative_change"].to_numpy(dtype=float))
        per_size = []
        reliable_from = None
        if sizes.size:
            idx, centers = _size_bins(sizes)
            ok_flags = []
            for b, center in enumerate(centers):
                sel = faults[idx == b]
                if sel.empty:
                    continue
                detected = sel["detected"].fillna(False).to_numpy(dtype=bool)
                latency = sel["latency"].to_numpy(dtype=float)
                within = detected & (latency <= latency_limit + 1e-9)
                false = sel["false_alarms"].fillna(0).to_numpy(dtype=int)
                good = within & (false == 0)
                per_size.append({
                    "relative_change": float(center), "n": int(len(sel)),
                    "p_detected": float(detected.mean()), "p_within_limit": float(within.mean()),
                    "median_latency": float(np.median(latency[detected])) if detected.any() else None,
                    "max_latency": float(np.max(latency[detected])) if detected.any() else None,
                    "runs_with_false_alarms": int((false > 0).sum()),
                    "all_within_limit_no_false_alarm": bool(good.all()),
                })
                ok_flags.append((float(center), bool(good.all())))
            for center, good in reversed(ok_flags):
                if not good:
                    break
                reliable_from = center
        entry["sizes"] = per_size
        entry["smallest_reliable_change"] = reliable_from
        alarms = clean["alarms"].fillna(0).to_numpy(dtype=int)
        entry["no_fault"] = {"n": int(len(clean)), "runs_with_alarms": int((alarms > 0).sum()),
                             "alarms": int(alarms.sum())}
        groups.append(entry)
    counts = table["status"].value_counts().to_dict()
    return {"variable": variables[0] if len(variables) == 1 else None, "variables": variables, "unit": unit,
            "detector": None if design is None else {"name": design.name, "arl0_hours": design.arl0_hours,
                                                     "every": design.every},
            "latency_limit": latency_limit, "scenarios": int(len(table)),
            "ok": int(counts.get("ok", 0)), "failed": int(len(table) - counts.get("ok", 0)), "series": groups}


def _py(v):
    if _isna(v):
        return None
    return v.item() if hasattr(v, "item") else v


# --------------------------------------------------------------------------------- plots

def _figure(ncols: int, width: float = 6.0, nrows: int = 1):
    """A figure drawn with the Agg canvas, without pyplot (no global backend, nothing to close);
    its axes as one flat array, row by row."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, 4.6 * nrows))
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return matplotlib.rcParams, fig, axes.ravel()


_MARKERS = ("o", "x", "s", "^", "D", "v", "P", "*")
_DASHES = ("-", "--", ":", "-.")


class _Styles:
    """Colour by noise level; marker (detection plot) and line style (ROC) by the rest of the
    series key (model, threshold, fault kind).  Series that coincide (e.g. every one at a
    detection rate of 1.0) stay visible because they are layered: the first series is drawn
    widest and lowest, each later one narrower and on top, with smaller markers, so equal
    curves show as nested lines and concentric rings, at their exact values."""

    def __init__(self, rc, keys: list[dict[str, Any]]):
        self.colors = rc["axes.prop_cycle"].by_key()["color"]
        self.noise = sorted({k["noise_std"] for k in keys})
        rest = []
        for k in keys:
            r = self._rest(k)
            if r not in rest:
                rest.append(r)
        self.rest = rest

    @staticmethod
    def _rest(key: dict[str, Any]) -> tuple:
        return tuple((c, key.get(c)) for c in ("variable", "model", "threshold", "kind", "ramp_duration"))

    def color(self, key):
        return self.colors[self.noise.index(key["noise_std"]) % len(self.colors)]

    def marker(self, key):
        return _MARKERS[self.rest.index(self._rest(key)) % len(_MARKERS)]

    def dash(self, key):
        return _DASHES[self.rest.index(self._rest(key)) % len(_DASHES)]

    @staticmethod
    def layer(i: int, n: int) -> dict[str, float]:
        """Line width, marker size and z-order of series ``i`` of ``n``."""
        f = 1.0 - i / (n - 1) if n > 1 else 0.0       # 1 for the first, 0 for the last
        return {"lw": 1.5 + 3.0 * f, "markersize": 6.0 + 6.0 * f, "zorder": 2 + i}


def _key(series: dict[str, Any]) -> dict[str, Any]:
    return {c: series.get(c) for c in ("noise_std", "model", "threshold", "variable", "kind", "ramp_duration")}


def plot_detection(summary: dict[str, Any], path, *, title: str = "") -> Any:
    """Detection probability (left) and median latency (right) against the fault size; written to ``path``."""
    detection_figure(summary, title=title).savefig(path, dpi=120, bbox_inches="tight")
    return path


def detection_figure(summary: dict[str, Any], *, title: str = "") -> Any:
    """:func:`plot_detection`'s Figure: the series legend (below the panels) names each series'
    detector; the right panel's line of a series' median alarm latencies has gid ``latency: <series>``."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    rc, fig, (ax_p, ax_l) = _figure(2)
    limit = summary["latency_limit"]
    variable = summary.get("variable")
    series = [s for s in summary["series"] if s["sizes"]]
    styles = _Styles(rc, [_key(s) for s in series])
    any_latency = False
    for i, s in enumerate(series):
        key = _key(s)
        color, marker = styles.color(key), styles.marker(key)
        hollow = {"markerfacecolor": "none"} if marker in ("o", "s", "^", "D", "v") else {}
        layer = styles.layer(i, len(series))
        x = [100 * e["relative_change"] for e in s["sizes"]]
        nf = s["no_fault"]
        note = f" (fault-free runs with an alarm: {nf['runs_with_alarms']}/{nf['n']})" if nf["n"] else ""
        ax_p.plot(x, [e["p_detected"] for e in s["sizes"]], "-", marker=marker, color=color,
                  label=s["series"] + note, **layer, **hollow)
        ax_p.plot(x, [e["p_within_limit"] for e in s["sizes"]], "--", marker=marker, color=color, alpha=0.6,
                  **dict(layer, lw=max(1.0, layer["lw"] - 1.0), markersize=layer["markersize"] - 2), **hollow)
        lat = [(xi, e["median_latency"]) for xi, e in zip(x, s["sizes"]) if e["median_latency"] is not None]
        if lat:
            any_latency = True
            ax_l.plot(*zip(*lat), "-", marker=marker, color=color, gid=f"latency: {s['series']}", **layer, **hollow)
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    for ax in (ax_p, ax_l):
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(plain)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(f"fault size |Δ{variable}| / {variable} (%)" if variable
                      else "fault size |Δp| / p of the changed parameter p (%)")
        ax.grid(True, which="both", alpha=0.3)
    ax_p.set_ylim(-0.03, 1.03)
    ax_p.set_ylabel("fraction of runs")
    ax_p.set_title(f"detected at all (solid), detected within {limit:g} s (dashed)", fontsize=10)
    ax_l.set_ylabel("median alarm latency after the fault (s)")
    ax_l.set_title(f"latency of the detected runs (dotted: {limit:g} s)", fontsize=10)
    ax_l.axhline(limit, color="grey", lw=1, ls=":")
    if any_latency:
        ax_l.set_yscale("log")
        ax_l.yaxis.set_major_formatter(plain)
        ax_l.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax_l.yaxis.set_minor_formatter(NullFormatter())
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    handles, labels = ax_p.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=1, fontsize=8,
                   frameon=False)
    return fig


def roc_points(table, unit: str = "", detector: DetectorDesign | None = None) -> list[dict[str, Any]]:
    """Per series: (fpr, tpr, auc, operating point at c = 1, counts) from sklearn's roc_curve."""
    import numpy as np
    from sklearn.metrics import auc, roc_curve

    design = _design(table, detector)
    out = []
    for key, faults, clean, _ in _groups(table):
        neg = np.concatenate([faults["score_pre"].to_numpy(dtype=float), clean["score_pre"].to_numpy(dtype=float)])
        pos = faults["score_early"].to_numpy(dtype=float)
        neg = neg[np.isfinite(neg)]
        pos = np.where(np.isfinite(pos), pos, 0.0)     # no evaluation within the limit: never detected in time
        if neg.size == 0 or pos.size == 0:
            continue
        y = np.concatenate([np.zeros(neg.size), np.ones(pos.size)])
        scores = np.concatenate([neg, pos])
        fpr, tpr, thr = roc_curve(y, scores)
        out.append({"series": _series_label(key, faults, unit, design), "key": key, "fpr": fpr, "tpr": tpr, "c": thr,
                    "auc": float(auc(fpr, tpr)), "n_neg": int(neg.size), "n_pos": int(pos.size),
                    "operating": (float((neg > 1).mean()), float((pos > 1).mean()))})
    return out


def plot_roc(table, path, *, title: str = "", unit: str = "", latency_limit: float | None = None,
             detector: DetectorDesign | None = None) -> Any:
    """ROC curves over threshold multipliers (construction in the module docstring)."""
    rc, fig, (ax,) = _figure(1, width=7.0)
    curves = roc_points(table, unit, detector)
    styles = _Styles(rc, [dict(r["key"]) for r in curves])
    for i, r in enumerate(curves):
        key = dict(r["key"])
        color = styles.color(key)
        layer = styles.layer(i, len(curves))
        ax.step(r["fpr"], r["tpr"], where="post", color=color, ls=styles.dash(key), lw=layer["lw"],
                zorder=layer["zorder"],
                label=f"{r['series']}: AUC {r['auc']:.3f} ({r['n_pos']} faulty / {r['n_neg']} healthy spans)")
        ax.plot(*r["operating"], marker=styles.marker(key), color=color, markersize=layer["markersize"] + 3,
                markerfacecolor="none", markeredgewidth=2, ls="none", zorder=10 + i)
    ax.plot([0, 1], [0, 1], color="grey", lw=1, ls=":")
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    within = f" within {latency_limit:g} s" if latency_limit else " within the latency limit"
    ax.set_xlabel("false-alarm rate (healthy spans with an alarm)")
    ax.set_ylabel(f"detection rate (faults detected{within})")
    ax.set_title(title or "ROC over threshold multipliers c (markers: c = 1, the threshold used)", fontsize=10)
    ax.grid(True, alpha=0.3)
    if curves:
        ax.legend(loc="lower right", fontsize=7)
    else:
        ax.text(0.5, 0.5, "no ROC: needs finished runs with and without a fault", ha="center", va="center")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


def run_delays(table) -> Any:
    """The delay-vs-ARL0 columns of ``table`` as defined in the module docstring: each
    evaluation-grid delay capped by the run's alarm latency (a DataFrame, same index and columns;
    None where the grid has none).  At the run's designed ARL0 this is the alarm latency."""
    import numpy as np
    import pandas as pd

    from .scenario import ARL0_HOURS, delay_column

    cols = [delay_column(h) for h in ARL0_HOURS if delay_column(h) in table.columns]
    grid = table[cols].astype(float)
    latency = table["latency"].astype(float).to_numpy() if "latency" in table.columns else np.full(len(table), np.nan)
    capped = np.fmin(grid.to_numpy(), latency[:, None])           # fmin: a missing latency leaves the grid value
    return pd.DataFrame(np.where(np.isfinite(grid.to_numpy()), capped, np.nan), index=grid.index, columns=cols)


def delay_curves(table, unit: str = "", detector: DetectorDesign | None = None) -> list[dict[str, Any]]:
    """Per series and fault size: the median detection delay at each ARL0 level (:func:`run_delays`).

    Only the cusum detector fills the delay columns (:func:`sweep.scenario.delays_at_arl0`);
    a level where fewer than half the runs of a size detected the fault after it (missed,
    or alarmed before it) has no median and is left out.
    """
    import numpy as np

    from .scenario import ARL0_HOURS, delay_column

    cols = [delay_column(h) for h in ARL0_HOURS]
    if not set(cols) <= set(table.columns):
        return []
    design = _design(table, detector)
    delays_all = run_delays(table)
    out = []
    for key, faults, _, _ in _groups(table):
        if faults.empty or faults[cols].isna().all().all():
            continue
        sizes = np.abs(faults["relative_change"].to_numpy(dtype=float))
        idx, centers = _size_bins(sizes)
        for b, center in enumerate(centers):
            sel = faults[idx == b]
            if sel.empty:
                continue
            hours, delays = [], []
            for h, c in zip(ARL0_HOURS, cols):
                d = delays_all.loc[sel.index, c].to_numpy(dtype=float)
                if np.isfinite(d).sum() * 2 > d.size:
                    hours.append(h)
                    delays.append(float(np.median(np.where(np.isfinite(d), d, np.inf))))
            if hours:
                out.append({"series": _series_label(key, faults, unit, design), "key": key,
                            "relative_change": float(center), "arl0_hours": hours, "median_delay": delays,
                            "n": int(len(sel))})
    return out


def plot_delay_arl0(table, path, *, title: str = "", unit: str = "", detector: DetectorDesign | None = None) -> Any:
    """Median detection delay against the false-alarm level (ARL0, hours), one line per fault size;
    the designed ARL0 (``detector``) is marked: its delays are detection.png's latencies."""
    delay_arl0_figure(table, title=title, unit=unit, detector=detector).savefig(path, dpi=120)
    return path


def delay_arl0_figure(table, *, title: str = "", unit: str = "", detector: DetectorDesign | None = None) -> Any:
    """:func:`plot_delay_arl0`'s Figure: one panel per series (titled with its label), one line
    per fault size (gid ``delay: <relative change>``), the designed ARL0 a vertical line (gid
    ``designed-arl0``)."""
    import matplotlib

    design = _design(table, detector)
    curves = delay_curves(table, unit, design)
    series = []
    for c in curves:
        if c["series"] not in series:
            series.append(c["series"])
    ncols = min(4, max(1, len(series)))
    nrows = max(1, math.ceil(len(series) / ncols))
    rc, fig, axes = _figure(ncols, width=5.5, nrows=nrows)
    for ax in axes[len(series or [""]):]:
        ax.set_visible(False)
    sizes = sorted({c["relative_change"] for c in curves})
    cmap = matplotlib.colormaps["viridis"]
    every = f"{design.every:g} s" if design is not None and design.every else "one evaluation interval"
    for ax, name in zip(axes, series or [""]):
        mine = [c for c in curves if c["series"] == name]
        for j, c in enumerate(mine):
            i = sizes.index(c["relative_change"])
            color = cmap(i / max(1, len(sizes) - 1))
            layer = _Styles.layer(j, len(mine))      # equal curves stay visible as nested lines
            ax.plot(c["arl0_hours"], c["median_delay"], marker="o", color=color, lw=layer["lw"] / 1.5,
                    markersize=layer["markersize"] / 2, zorder=layer["zorder"], gid=f"delay: {c['relative_change']!r}",
                    label=f"{100 * c['relative_change']:.3g} % (n = {c['n']})")
        if curves and design is not None and design.arl0_hours:
            ax.axvline(design.arl0_hours, color="grey", ls=":", lw=1.2, gid="designed-arl0",
                       label=f"designed ARL0 {design.arl0_hours:.3g} h: the alarm latency (detection.png)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ARL0: mean hours of healthy operation between false alarms")
        ax.set_ylabel(f"median detection delay (s)\nbelow the designed ARL0: at most {every} late")
        ax.set_title(name or "no delay curves (cusum detector only)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        if curves:
            # below the axes: inside, it hid curves (they span the whole panel)
            ax.legend(fontsize=7, title="fault size", title_fontsize=7, loc="upper center",
                      bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)
        else:
            ax.text(0.5, 0.5, "needs fault runs monitored by the cusum detector", ha="center", va="center",
                    transform=ax.transAxes)
    fig.suptitle(title or "detection delay against false-alarm rate (the CUSUM limit set for each ARL0)", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.04 / nrows))      # room for the title above the top row
    return fig


def classification(table) -> list[dict[str, Any]]:
    """How well the diagnosis named each fault: one row per variable, size and noise level.

    ``faults`` runs with that fault; ``detected`` those the monitor alarmed on (the only ones
    diagnosed); ``right`` diagnoses naming the changed parameter as an explanation; ``accuracy``
    = right / detected.  Among the right ones: ``value_error`` the largest relative error of the
    new value (a step's value, or a ramp's final value) and ``time_error`` the largest error of
    the change time in s (a ramp's start).
    """
    import numpy as np

    if "diagnosis" not in table.columns:
        return []
    faults = table[(table["has_fault"] == True) & (table["status"] == "ok")]   # noqa: E712 (nullable booleans)
    out = []
    for (variable, size, noise), g in faults.groupby(["variable", "relative_change", "noise_std"], sort=True):
        detected = g[g["detected"] == True]                                      # noqa: E712
        right = detected[(detected["diagnosis"] == "explained") & (detected["diagnosed_variable"] == variable)]
        value_err = (right["diagnosed_value"] / right["fault_value"] - 1.0).abs()
        time_err = (right["diagnosed_time"] - right["fault_time"]).abs()
        out.append({
            "variable": variable, "relative_change": float(size), "noise_std": float(noise), "faults": int(len(g)),
            "detected": int(len(detected)), "right": int(len(right)),
            "accuracy": float(len(right) / len(detected)) if len(detected) else None,
            "unexplained": int((detected["diagnosis"] == "unexplained").sum()),
            "value_error": float(value_err.max()) if len(right) else None,
            "time_error": float(time_err.max()) if len(right) else None,
            "seconds_max": float(np.nanmax(detected["diagnosis_seconds"])) if len(detected) else None,
        })
    return out
