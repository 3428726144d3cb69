#!/usr/bin/env python3
"""The detection targets, measured on real runs: latency, false alarms, episodes, calibration.

Every study is a sweep (``fourbar-sweep``, Dask, resumable) of the Table 1 mechanism on
the native FMU, so its rows can be inspected in ``DIR/<study>/results.csv`` and a rerun
skips what is done:

``case2``       the paper's Case 2 (L2 1.0 -> 1.1 m at 10 s, 100 s), noise-free and
                σ = 5 mm on x2 with 10 seeds; Prophet and harmonic; CUSUM and the MAE rule.
``case3``       Case 3's ramp (L2 +5 % over 20-30 s), σ = 5 mm, 10 seeds; both detectors.
``l2_step``     ``sweeps/l2_step.toml`` as shipped: the smallest L2 step detected within 2 s.
``parameters``  ``sweeps/parameters.toml`` as shipped: every tunable parameter.
``signals``     L1, L3, L4 +1 %, σ = 3 mm on every column, 3 seeds x 3 fault times: x2
                alone against all six columns monitored jointly (the gain of ``--signal``).
``late``        L2 +1 %, σ = 5 mm, at six phases of the swing after 10 s, 500 s and 3600 s
                (3 seeds each; runs end 15 s after the fault).  The 3600 s runs give an
                hour of healthy monitoring before each fault, and three fault-free hours.
``drift``       slow ramps of L2 by +1 % over 300, 1000 and 3000 s, σ = 5 mm, 3 seeds: how
                much has L2 changed when the alarm comes (is a slow drift absorbed?).
``calibration`` the fault-free hours replayed with the CUSUM designed for 1 and 10 false
                alarms per hour, where false alarms are frequent enough to count.
``speed``       the replay of Case 2 (100 s) with Prophet, CUSUM and MAE rule, in-process
                after a warm-up: the real-time factor.
``page_hinkley`` the page-hinkley detector (harmonic model) on Case 2 (noise-free and
                σ = 5 mm, 10 seeds) and on 600 s runs at σ = 5 mm, 3 seeds, with L2 +1 %
                at 600 s and without a fault: its delay and its false alarms.

Writes markdown to stdout, or the page ``docs/detection.md`` with ``--write``.  About 25
minutes on 2 cores from scratch.

Usage: python benchmarks/detection.py [--out DIR] [--only STUDY ...] [--write docs/detection.md]
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
BIN = Path(sys.executable).parent

from fourbar_common.contract.layout import SweepFolder  # noqa: E402  (after the path)
from fourbar_common.contract.sweep_results import read_sweep_summary  # noqa: E402

NATIVE = REPO / "build" / "FourBarNative.fmu"
CASES = REPO / "cases"
SEEDS10 = list(range(1, 11))
LATE_TIMES = (10.0, 500.0, 3600.0)
PERIOD = 3.06                 # s, about one swing of Table 1's mechanism: the phases are spread over it
PHASES = 6
#: The issue's targets, quoted with the figures.
TARGETS = {
    "case2_clean": 0.05, "case2_noisy": 0.2, "l2_clean": 0.002, "l2_noisy": 0.01, "case3": 2.0,
    "late": 0.20, "links": 2.0, "masses": 5.0, "false_alarm_rate": 0.01, "replay": 50.0,
}


def toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return repr(v)


def sweep_text(name: str, *, stop: float, fault: dict, noise: dict, monitor: dict, diagnose: bool = False) -> str:
    lines = [f"name = {toml_value(name)}", f"case = {toml_value(str(CASES / 'case1_normal.toml'))}",
             f"fmu = {toml_value(str(NATIVE))}", f"stop = {stop!r}"]
    for table, body in (("fault", fault), ("noise", noise), ("monitor", monitor)):
        lines.append(f"[{table}]")
        lines += [f"{k} = {toml_value(v)}" for k, v in body.items()]
    lines += ["[output]", "keep_exchange = true"]
    if diagnose:
        lines += ["[diagnose]", "enabled = true"]
    return "\n".join(lines) + "\n"


def run_sweep(path: Path, out: Path):
    """Run (or resume) one sweep with fourbar-sweep; return its results table."""
    import pandas as pd

    t0 = time.perf_counter()
    proc = subprocess.run([str(BIN / "fourbar-sweep"), str(path), "--out", str(out), "-q"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"fourbar-sweep {path} failed (exit {proc.returncode}):\n{proc.stderr}")
    print(f"  {path.name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    table = pd.read_parquet(out / "results.parquet")
    failed = table[table["status"] != "ok"]
    if len(failed):
        raise SystemExit(f"{out}: {len(failed)} scenarios failed, e.g. {failed['error'].iloc[0]}")
    return table


def study_sweep(out: Path, name: str, **body):
    path = out / f"{name}.toml"
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(sweep_text(name, **body))
    return run_sweep(path, out / name)


def shipped_sweep(out: Path, name: str):
    return run_sweep(REPO / "sweeps" / f"{name}.toml", out / name)


# ------------------------------------------------------------------------------ figures

@dataclass(frozen=True)
class Spread:
    """Median, smallest and largest of a set of latencies (None: some run missed; ``missed``
    counts them)."""

    n: int
    median: float | None
    low: float | None
    high: float | None
    missed: int = 0

    @classmethod
    def of(cls, values) -> "Spread":
        values = [float(v) for v in values]
        missed = sum(1 for v in values if math.isnan(v))
        if not values or missed:
            return cls(len(values), None, None, None, missed)
        return cls(len(values), statistics.median(values), min(values), max(values))

    def text(self) -> str:
        if self.median is None:
            return f"missed in all {self.n} runs" if self.missed == self.n else f"missed in {self.missed} of {self.n} runs"
        if self.n == 1:
            return f"{self.median:.2f} s"
        return f"{self.median:.2f} s (median; {self.low:.2f}–{self.high:.2f} s, n = {self.n})"


def mark(ok: bool) -> str:
    return "met" if ok else "**not met**"


def at_most(value: float | None, target: float, unit: str = " s") -> str:
    """``value`` against an upper target: "0.10 s (target ≤ 0.2 s, met)"; None (a miss) fails."""
    shown = "missed" if value is None else f"{value:.2f}{unit}"
    return f"{shown} (target ≤ {target:g}{unit}, {mark(value is not None and value <= target)})"


def case2(out: Path) -> list[str]:
    rows = ["| detector | model | noise-free latency | σ = 5 mm latency (10 seeds) | false alarms | alarm episodes per run |",
            "|---|---|---:|---:|---:|---:|"]
    verdict = []
    for detector in ("cusum", "mae"):
        t = study_sweep(out, f"case2_{detector}", stop=100.0,
                        fault={"variable": "L2", "relative": 0.1, "time": 10.0},
                        noise={"std": [0.0, 0.005], "seed": SEEDS10},
                        monitor={"model": ["prophet", "harmonic"], "detector": detector})
        for model in ("prophet", "harmonic"):
            m = t[t["model"] == model]
            clean, noisy = m[m["noise_std"] == 0], m[m["noise_std"] > 0]
            c, n = Spread.of(clean["latency"]), Spread.of(noisy["latency"])
            rows.append(f"| {detector} | {model} | {c.text()} | {n.text()} | {int(m['false_alarms'].sum())} | "
                        f"{int(m['alarms'].max())} |")
            if detector == "cusum":
                verdict.append(f"Case 2, {model}: noise-free {at_most(c.median, TARGETS['case2_clean'])}; "
                               f"σ = 5 mm median {at_most(n.median, TARGETS['case2_noisy'])}")
    return ["## Case 2: the paper's scenario", "",
            "L2 1.0 → 1.1 m at t = 10 s, 100 s runs; the paper's latency is 4 s.", "", *rows, "",
            *[f"- {v}" for v in verdict], ""]


def case3(out: Path) -> list[str]:
    rows = ["| detector | first alarm after the ramp starts | alarm episodes per run | false alarms |",
            "|---|---:|---:|---:|"]
    verdict = []
    for detector in ("cusum", "mae"):
        t = study_sweep(out, f"case3_{detector}", stop=100.0,
                        fault={"variable": "L2", "kind": "ramp", "relative": 0.05, "time": 20.0,
                               "ramp_duration": 10.0},
                        noise={"std": 0.005, "seed": SEEDS10}, monitor={"model": "harmonic", "detector": detector})
        s = Spread.of(t["latency"])
        episodes = sorted(set(int(v) for v in t["alarms"]))
        rows.append(f"| {detector} | {s.text()} | {', '.join(map(str, episodes))} | {int(t['false_alarms'].sum())} |")
        if detector == "cusum":
            verdict.append(f"Case 3: slowest first alarm after the ramp starts {at_most(s.high, TARGETS['case3'])}; "
                           f"episodes per run {', '.join(map(str, episodes))} (target exactly 1, "
                           f"{mark(episodes == [1])})")
    return ["## Case 3: a slow ramp", "",
            "L2 ramps 1.0 → 1.05 m over 20–30 s, σ = 5 mm on x2, 10 seeds, harmonic model.", "", *rows, "",
            *[f"- {v}" for v in verdict], ""]


def l2_step(out: Path) -> list[str]:
    shipped_sweep(out, "l2_step")
    summary = read_sweep_summary(SweepFolder(out / "l2_step").summary)
    rows = ["| noise on x2 | model | smallest L2 step detected within 2 s, no false alarm | slowest at that size | "
            "fault-free runs with an alarm |", "|---|---|---:|---:|---:|"]
    verdict = []
    for s in summary.series:
        size = s["smallest_reliable_change"]
        at = next((e for e in s["sizes"] if size is not None and math.isclose(e["relative_change"], size)), None)
        noise = "none" if s["noise_std"] == 0 else f"σ = {1000 * s['noise_std']:g} mm"
        nf = s["no_fault"]
        slowest = "—" if at is None else f"{at['max_latency']:.2f} s"
        rows.append(f"| {noise} | {s['model']} | {percent(size)} | {slowest} | {nf['runs_with_alarms']}/{nf['n']} |")
        target = TARGETS["l2_clean"] if s["noise_std"] == 0 else TARGETS["l2_noisy"]
        verdict.append(f"{noise}, {s['model']}: {percent(size)} (target ≤ {percent(target)}, "
                       f"{mark(size is not None and size <= target + 1e-12)})")
    return ["## Smallest L2 step (`sweeps/l2_step.toml`)", "",
            "Steps of +0.2 % … +10 % at 10, 11 and 12 s; noise-free and σ = 5 mm (3 seeds); 30 s runs.", "",
            *rows, "", *[f"- {v}" for v in verdict], ""]


def percent(x) -> str:
    return "none" if x is None else f"+{100 * x:.3g} %"


def parameters(out: Path) -> list[str]:
    t = shipped_sweep(out, "parameters")
    summary = read_sweep_summary(SweepFolder(out / "parameters").summary)
    rows = ["| parameter | smallest step within 2 s, noise-free | smallest step within 2 s, σ = 3 mm | "
            "latency of +1 % (σ = 3 mm) | latency of +10 % (σ = 3 mm) | episodes per run |",
            "|---|---:|---:|---:|---:|---:|"]
    verdict = []
    faults = t[t["has_fault"]]
    for variable in summary.variables:
        by = {s["noise_std"]: s for s in summary.series if s.get("variable") == variable}
        v = faults[faults["variable"] == variable]
        noisy = v[v["noise_std"] > 0]
        one = Spread.of(noisy[(noisy["relative_change"] - 0.01).abs() < 1e-9]["latency"])
        ten = Spread.of(noisy[(noisy["relative_change"] - 0.1).abs() < 1e-9]["latency"])
        episodes = int(v["alarms"].max())
        rows.append(f"| {variable} | {percent(by[0.0]['smallest_reliable_change'])} | "
                    f"{percent(by[0.003]['smallest_reliable_change'])} | {one.text()} | {ten.text()} | {episodes} |")
        if variable.startswith("L"):
            verdict.append(f"{variable} +1 %, σ = 3 mm: slowest {at_most(one.high, TARGETS['links'])}")
        elif variable.startswith("m"):
            verdict.append(f"{variable} +10 %, σ = 3 mm: slowest {at_most(ten.high, TARGETS['masses'])}")
    clean = t[~t["has_fault"]]
    verdict.append(f"alarm episodes per fault run: at most {int(faults['alarms'].max())} (target 1, "
                   f"{mark(int(faults['alarms'].max()) == 1)}); fault-free runs with an alarm: "
                   f"{int((clean['alarms'] > 0).sum())}/{len(clean)}")
    return ["## Every tunable parameter (`sweeps/parameters.toml`)", "",
            "Steps of +0.1 % … +10 % of each parameter at 10, 11 and 12 s, x2 monitored alone, noise-free and "
            "σ = 3 mm (3 seeds); 30 s runs. A uniform scaling of all three masses would not change the motion; "
            "one mass alone does.", "", *rows, "", *[f"- {v}" for v in verdict], ""]


ALL_COLUMNS = "x2,y2,x3,y3,x4,y4"


def signals(out: Path) -> list[str]:
    rows = ["| parameter (+1 %, σ = 3 mm) | x2 alone | all six columns jointly | gain (median) |",
            "|---|---:|---:|---:|"]
    tables = {}
    for tag, signal in (("x2", "x2"), ("all", ALL_COLUMNS)):
        tables[tag] = study_sweep(out, f"signals_{tag}", stop=30.0,
                                  fault={"variable": ["L1", "L3", "L4"], "relative": 0.01, "time": [10.0, 11.0, 12.0]},
                                  noise={"std": 0.003, "seed": [1, 2, 3]}, monitor={"model": "harmonic", "signal": signal})
    for variable in ("L1", "L3", "L4"):
        a = Spread.of(tables["x2"].query("variable == @variable")["latency"])
        b = Spread.of(tables["all"].query("variable == @variable")["latency"])
        gain = f"{a.median / b.median:.1f}×" if a.median and b.median else "—"
        rows.append(f"| {variable} | {a.text()} | {b.text()} | {gain} |")
    false = sum(int(t["false_alarms"].sum()) for t in tables.values())
    return ["## Several signals", "",
            f"`--signal {ALL_COLUMNS}` against x2 alone, with σ = 3 mm on every column (harmonic model, "
            f"3 seeds × fault times 10, 11, 12 s, 30 s runs). False alarms in these runs: {false}.", "", *rows, ""]


def late_times() -> dict[float, list[float]]:
    """Fault times: six phases of one swing after each start time, on the 0.01 s grid."""
    return {t0: [round(t0 + j * PERIOD / PHASES, 2) for j in range(PHASES)] for t0 in LATE_TIMES}


def late(out: Path) -> tuple[list[str], list[Path]]:
    rows = ["| fault after | latency (18 runs: 6 phases × 3 seeds) | mean | relative to 10 s | episodes per run | "
            "hours monitored before the faults | false alarms |", "|---|---:|---:|---:|---:|---:|---:|"]
    means = {}
    healthy_runs: list[Path] = []
    lines_verdict = []
    for t0, times in late_times().items():
        name = f"late_{int(t0)}"
        t = study_sweep(out, name, stop=round(times[-1] + 15.0, 2),
                        fault={"variable": "L2", "relative": 0.01, "time": times, "no_fault": t0 == LATE_TIMES[-1]},
                        noise={"std": 0.005, "seed": [1, 2, 3]}, monitor={"model": "harmonic"})
        f = t[t["has_fault"]]
        s = Spread.of(f["latency"])
        means[t0] = float(f["latency"].mean())
        hours = float((f["fault_time"] - 9.0).sum() / 3600.0)
        clean = t[~t["has_fault"]]
        hours += float(len(clean) * (t["stop"].iloc[0] - 9.0) / 3600.0)
        false = int(f["false_alarms"].sum() + clean["alarms"].sum())
        rel = means[t0] / means[LATE_TIMES[0]]
        rows.append(f"| {t0:g} s | {s.text()} | {means[t0]:.2f} s | {rel:.2f} | {int(f['alarms'].max())} | "
                    f"{hours:.1f} | {false} |")
        if t0 != LATE_TIMES[0]:
            lines_verdict.append(f"fault after {t0:g} s: mean latency {rel:.2f} × that after 10 s (target within "
                                 f"±{100 * TARGETS['late']:.0f} %, {mark(abs(rel - 1) <= TARGETS['late'])})")
        healthy_runs += [out / name / "runs" / sid / "exchange.csv" for sid in clean["scenario_id"]]
    return (["## Late faults: no loss of sensitivity with time", "",
             "L2 +1 %, σ = 5 mm on x2, harmonic model. Fault times at six phases of one swing after 10 s, 500 s and "
             "3600 s (runs end 15 s after the fault). The phase tracker keeps the forecast locked, so the latency "
             "does not grow with the time since training. The hours before the late faults are healthy "
             "monitoring: every alarm there is false.", "", *rows, "", *[f"- {v}" for v in lines_verdict], ""],
            healthy_runs)


DRIFT_DURATIONS = (300.0, 1000.0, 3000.0)


def drift(out: Path) -> list[str]:
    t = study_sweep(out, "drift", stop=DRIFT_DURATIONS[-1] + 60.0,
                    fault={"variable": "L2", "kind": "ramp", "relative": 0.01, "time": 10.0,
                           "ramp_duration": list(DRIFT_DURATIONS)},
                    noise={"std": 0.005, "seed": [1, 2, 3]}, monitor={"model": "harmonic"})
    rows = ["| ramp of L2 by +1 % over | first alarm after the ramp starts | L2 change at the alarm | "
            "episodes per run | false alarms |", "|---:|---:|---:|---:|---:|"]
    missed = 0
    for duration in DRIFT_DURATIONS:
        d = t[(t["ramp_duration"] - duration).abs() < 1e-9]
        s = Spread.of(d["latency"])
        change = [0.01 * min(1.0, v / duration) for v in d["latency"]] if s.median is not None else []
        change_text = (f"+{100 * statistics.median(change):.2f} % (median; +{100 * min(change):.2f} … "
                       f"+{100 * max(change):.2f} %)") if change else "—"
        rows.append(f"| {duration:g} s | {s.text()} | {change_text} | {int(d['alarms'].max())} | "
                    f"{int(d['false_alarms'].sum())} |")
        missed += s.missed
    study = (f"L2 drifting by +1 % over 300 s to 50 minutes, then held there until {DRIFT_DURATIONS[-1] + 60.0:g} s "
             "(σ = 5 mm on x2, 3 seeds, harmonic model).")
    if missed:
        verdict = (f"{missed} of {len(t)} runs never alarmed, even with L2 held at +1 % afterwards: a change this "
                   "slow is absorbed. The phase tracker follows the period (15 s time constant) and the shape "
                   "correction the waveform (60 s), both learnt from quiet data, so a drift slower than about a "
                   "minute never leaves a residual for the CUSUM (docs/monitor.md, Limitations).")
    else:
        verdict = "Every run alarmed before the drift was complete; the table gives how far L2 had moved."
    return ["## Slow drifts", "", study + " " + verdict, "", *rows, ""]


def calibration(healthy: list[Path]) -> list[str]:
    from monitor import replay

    rows = ["| designed false-alarm rate | hours replayed | false alarms | expected at the design rate | "
            "largest statistic / limit |", "|---:|---:|---:|---:|---:|"]
    for rate in (10.0, 1.0, 0.01):
        alarms, hours, ratio = 0, 0.0, 0.0
        for path in healthy:
            r = replay(path, model="harmonic", false_alarm_rate=rate, plots=False)
            alarms += r.summary.alarms
            ratio = max(ratio, r.summary.max_statistic_over_threshold)
            hours += (r.summary.last_time - 9.0) / 3600.0
        rows.append(f"| {rate:g} /h | {hours:.2f} | {alarms} | {rate * hours:.2f} | {ratio:.2f} |")
    return ["## False-alarm calibration", "",
            "The fault-free hours of the late-fault study (σ = 5 mm), replayed with the CUSUM limit designed for "
            "10, 1 and 0.01 false alarms per hour (Siegmund's approximation, union bound over the two one-sided "
            "statistics). Fewer alarms than designed means the design is conservative: the noise scale is "
            "raised to its upper confidence limit, and the union bound counts the two sides as if they never "
            "alarmed together.", "", *rows, ""]


def speed(out: Path) -> list[str]:
    from monitor import replay
    from monitor.session import warm_up

    import pandas as pd

    table = pd.read_parquet(out / "case2_cusum" / "results.parquet")
    sid = table[table["noise_std"] == 0]["scenario_id"].iloc[0]
    clean = out / "case2_cusum" / "runs" / sid / "exchange.csv"
    warm_up("prophet")
    rows = ["| detector | wall time (s) | real-time factor |", "|---|---:|---:|"]
    verdict = []
    for detector in ("cusum", "mae"):
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            replay(clean, model="prophet", detector=detector, plots=False)
            best = min(best, time.perf_counter() - t0)
        rows.append(f"| {detector} | {best:.2f} | {100.0 / best:.0f}× |")
        if detector == "cusum":
            verdict.append(f"Prophet replay of 100 s with the CUSUM: {100.0 / best:.0f}× real time (target ≥ "
                           f"{TARGETS['replay']:g}×, {mark(100.0 / best >= TARGETS['replay'])})")
    return ["## Replay speed with Prophet", "",
            "Case 2 (100 s, noise-free), best of three in-process replays after a warm-up, no files written.", "",
            *rows, "", *[f"- {v}" for v in verdict], ""]


PH_STOP = 609.0      # s: 600 s of healthy monitoring after the 9 s training window


def page_hinkley(out: Path) -> list[str]:
    """The page-hinkley detector on Case 2 and on long fault-free runs (docs/detection.md)."""
    t = study_sweep(out, "case2_page_hinkley", stop=100.0,
                    fault={"variable": "L2", "relative": 0.1, "time": 10.0},
                    noise={"std": [0.0, 0.005], "seed": SEEDS10},
                    monitor={"model": "harmonic", "detector": "page-hinkley"})
    clean, noisy = t[t["noise_std"] == 0], t[t["noise_std"] > 0]
    c, n = Spread.of(clean["latency"]), Spread.of(noisy["latency"])
    rows = ["| runs | delay | false alarms | alarm episodes per run |", "|---|---:|---:|---:|",
            f"| Case 2 noise-free | {c.text()} | {int(clean['false_alarms'].sum())} | {int(clean['alarms'].max())} |",
            f"| Case 2 σ = 5 mm (10 seeds) | {n.text()} | {int(noisy['false_alarms'].sum())} | "
            f"{int(noisy['alarms'].max())} |"]
    h = study_sweep(out, "healthy_page_hinkley", stop=PH_STOP,
                    fault={"variable": "L2", "relative": 0.01, "time": PH_STOP - 9.0, "no_fault": True},
                    noise={"std": 0.005, "seed": [1, 2, 3]},
                    monitor={"model": "harmonic", "detector": "page-hinkley"})
    f, free = h[h["has_fault"]], h[~h["has_fault"]]
    hours = float((f["fault_time"] - 9.0).sum() + len(free) * (PH_STOP - 9.0)) / 3600.0
    false = int(f["false_alarms"].sum() + free["alarms"].sum())
    s = Spread.of(f["latency"])
    rows.append(f"| L2 +1 % at {PH_STOP - 9.0:g} s, σ = 5 mm (3 seeds) | {s.text()} | "
                f"{int(f['false_alarms'].sum())} | {int(f['alarms'].max())} |")
    first = Spread.of(free["first_alarm_time"].fillna(math.inf)) if free["alarms"].sum() else None
    when = f" (first false alarm at {first.text()})" if first is not None else ""
    rows.append(f"| fault-free {PH_STOP:g} s, σ = 5 mm (3 seeds) | —{when} | {int(free['alarms'].sum())} | "
                f"{int(free['alarms'].max())} |")
    how = [
        "`--detector page-hinkley` (`monitor/page_hinkley.py`, one file and one line in the registry) watches one "
        "column. The forecast model (`--model`) is fitted on the training window at the refined period, as for the "
        "other detectors, but not phase-tracked: the residual `x − f(t)` is divided by `σ_t`, the noise scale σ "
        "learnt from held-out training data (the cusum detector's rule: a model fitted on the first 2/3 forecasts "
        "the rest; long-run standard deviation at its upper confidence limit, at least `ph_noise_floor` × the "
        "amplitude) widened by the forecast's timing error (below). A two-sided Page–Hinkley test (river's `drift.PageHinkley`) accumulates "
        "`m = Σ (z − z̄ − δ)` for each side, `z̄` the running mean of the standardised residuals since the test "
        "(re)started, and alarms when `m − min m` exceeds `h`. After an alarm the test restarts (running mean "
        "included), so it learns the new level: one change, one alarm episode, which clears after "
        "`--ph-clear-after` s without a crossing.",
        "",
        "Calibration: with the running mean settled each side is a CUSUM with reference δ on N(0, 1), so `h` is "
        "solved from Siegmund's approximation of the in-control run length, the two sides sharing "
        "`--ph-false-alarm-rate` (per hour of data). Options: `--ph-false-alarm-rate` (0.01 /h), `--ph-delta` "
        "(0.25 σ per sample: mean shifts above about 2δ = 0.5 σ are detected), `--ph-clear-after` (30 s), "
        "`ph_noise_floor` (library only, 0.001). There is no phase tracker: the forecast's timing error, "
        "bounded by 4 σ_P/P per second from the training window's centre (σ_P the period's standard error, as "
        "in the MAE rule's auto threshold), widens the scale where the waveform is steep, "
        "`σ_t = sqrt(σ² + (f'(t) · 4 σ_P/P · |t − t_c|)²)`, so the design holds as the run goes on while the "
        "sensitivity slowly falls.",
    ]
    return ["## The Page–Hinkley detector", "", *how, "",
            "Measured with the harmonic model at the defaults; this section alone: "
            "`python benchmarks/detection.py --only page_hinkley`.", "", *rows, "",
            f"- {hours:.2f} hours of healthy monitoring (the faulted runs before their fault and the fault-free "
            f"runs): {false} false alarm(s), against {0.01 * hours:.3f} expected at the design rate.",
            f"- L2 +1 % after {PH_STOP - 9.0:g} s: "
            + (f"detected in {s.n - s.missed} of {s.n} runs. " if s.missed else f"{s.text()}. ")
            + "The scale's timing term grows with the time since training, so a change this small is hidden by "
              "then: the price of holding the design without a phase tracker. The cusum detector (the default) "
              "tracks the phase and keeps its sensitivity (the late-fault study above).", ""]


STUDIES = ("case2", "speed", "case3", "l2_step", "parameters", "signals", "late", "drift", "calibration",
           "page_hinkley")  # speed first: a fresh process


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "out" / "benchmarks" / "detection",
                        help="folder of the studies' sweeps (reused: a rerun skips what is done); "
                             "default: out/benchmarks/detection")
    parser.add_argument("--only", nargs="+", choices=STUDIES, help="run these studies only")
    parser.add_argument("--write", type=Path, help="write the page to this file (e.g. docs/detection.md)")
    args = parser.parse_args(argv)
    if not NATIVE.exists():
        print(f"error: {NATIVE} not found; build it with: make fmu", file=sys.stderr)
        return 2
    chosen = args.only or STUDIES
    if "calibration" in chosen and "late" not in chosen:
        chosen = [*chosen, "late"]
    t0 = time.perf_counter()
    parts = ["# Detection benchmark", "",
             "Generated by `python benchmarks/detection.py --write docs/detection.md` (do not edit by hand). "
             "Every figure is from runs of the native FMU and the monitor at default settings unless a column says "
             "otherwise. Latency is the detection delay: the first alarm's evaluation time minus the fault time.", ""]
    healthy: list[Path] = []
    for study in STUDIES:
        if study not in chosen:
            continue
        print(f"{study} ...", file=sys.stderr)
        if study == "late":
            text, healthy = late(args.out)
            parts += text
        elif study == "calibration":
            parts += calibration(healthy)
        elif study in ("l2_step", "parameters", "case2", "case3", "drift", "signals", "page_hinkley"):
            parts += globals()[study](args.out)
        elif study == "speed":
            if not (args.out / "case2_cusum" / "results.parquet").exists():
                case2(args.out)                  # the speed study replays Case 2's clean run
            parts += speed(args.out)
    parts.append(f"Measured in {time.perf_counter() - t0:.0f} s (studies already in `{args.out.name}` are reused).")
    page = "\n".join(parts) + "\n"
    if args.write:
        args.write.write_text(page, encoding="utf-8")
        print(f"wrote {args.write}", file=sys.stderr)
    else:
        print(page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
