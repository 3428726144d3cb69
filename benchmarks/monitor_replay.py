#!/usr/bin/env python3
"""Speed and detection performance of the monitor on orchestrator-produced exchange files.

Speed (Case 2: 100 s, 10,001 rows), per model:
  - fit: the model fit alone, and the whole training (FFT + refined period, model fit,
    validation fit for the auto threshold);
  - time per evaluation: amortised in a replay (forecast + MAE, the file read at once) and
    live (rows fed in 0.1 s blocks, one evaluation each, as when following);
  - replay wall time and real-time factor = 100 s / wall time, in the same process after a
    warm-up replay (imports done), without and with the output files (events, evaluations,
    summary, three PNGs); and the cold ``fourbar-monitor`` command (new process, imports,
    outputs, plots).
Detection: Case 1 and Case 2, clean and with σ = 5 mm sensor noise on x2 (several noise
seeds), both models, default settings (the default detector): first-alarm latency after the
fault at 10 s, false alarms, and the largest statistic/limit ratio where there must be no
alarm; the paper's figure is a 4 s latency.

The exchange files come from ``fourbar-run`` (subprocess; the monitor never imports the
orchestrator).  Prints markdown.

Usage: python benchmarks/monitor_replay.py [--seeds 5] [--repeat 3] [--models prophet,harmonic] [--data DIR]
       python benchmarks/monitor_replay.py --quick --fmu build/FourBarNative.fmu    # the smoke test's setting
"""
from __future__ import annotations

import argparse
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
BIN = Path(sys.executable).parent
PAPER_LATENCY_S = 4.0      # the paper: fault at 10 s, "definitive defect at t = 14 s"
NOISE_STD = 0.005          # m
MODELS = ("prophet", "harmonic")



def case_text(name: str, fmu: Path, fault: bool) -> str:
    """Table 1's Case 1 or 2 from the shipped case file, renamed and pointed at ``fmu``."""
    text = (REPO / "cases" / ("case2_fault_L2.toml" if fault else "case1_normal.toml")).read_text()
    text = re.sub(r"(?m)^fmu\s*=.*$", f'fmu = "{fmu.as_posix()}"', text)
    return re.sub(r"(?m)^name\s*=.*$", f'name = "{name}"', text)


def make_runs(base: Path, fmu: Path, seeds: int) -> dict[str, Path]:
    """Run every needed case with fourbar-run (in parallel, two at a time); return exchange paths."""
    cases = {}
    for fault in (False, True):
        tag = "case2" if fault else "case1"
        cases[tag] = (False, 0, fault)
        for seed in range(1, seeds + 1):
            cases[f"{tag}_noise{seed}"] = (True, seed, fault)
    paths = {}
    jobs = []
    for name, (noisy, seed, fault) in cases.items():
        exchange = base / name / "exchange.csv"
        paths[name] = exchange
        if exchange.exists() and (exchange.parent / "run.json").exists():
            continue
        text = case_text(name, fmu, fault)
        if noisy:
            text += f"\n[noise]\nseed = {seed}\nstd = {{ x2 = {NOISE_STD!r} }}\n"
        case = base / f"{name}.toml"
        case.write_text(text)
        jobs.append([str(BIN / "fourbar-run"), str(case), "--out", str(exchange.parent), "--quiet"])
    running: list[subprocess.Popen] = []
    for cmd in jobs:
        while len(running) >= max(1, os.cpu_count() or 1):
            running.pop(0).wait()
        running.append(subprocess.Popen(cmd))
    for p in running:
        p.wait()
    for name, path in paths.items():
        if not path.exists():
            raise SystemExit(f"fourbar-run did not produce {path}")
    return paths


def time_replays(path: Path, model: str, repeat: int, out_dir: Path) -> dict[str, float]:
    from monitor import replay

    replay(path, model=model)                      # warm-up: imports, Stan binary in the page cache
    walls, results = [], []
    for _ in range(repeat):
        start = time.perf_counter()
        r = replay(path, model=model)
        walls.append(time.perf_counter() - start)
        results.append(r)
    outs = []
    for i in range(repeat):
        start = time.perf_counter()
        replay(path, model=model, out_dir=out_dir / f"{model}{i}")
        outs.append(time.perf_counter() - start)
    r = results[len(results) // 2]
    t = r.summary.timing
    fit = r.fits[0]
    span = r.summary.last_time - 0.0
    n_eval = r.summary.evaluations
    return {
        "fit": statistics.median(x.fits[0].forecaster.fit_seconds for x in results),
        "train": statistics.median(x.summary.timing.train for x in results),
        "per_eval_batch": statistics.median((x.summary.timing.forecast + x.summary.timing.evaluate)
                                            / x.summary.evaluations for x in results),
        "wall": statistics.median(walls),
        "wall_out": statistics.median(outs),
        "rtf": span / statistics.median(walls),
        "rtf_out": span / statistics.median(outs),
        "n_eval": n_eval,
        "order": fit.forecaster.order,
        "first_alarm": r.first_alarm_time,
        "read": t.read,
    }


def time_live_evaluations(path: Path, model: str) -> float:
    """Median wall time of one evaluation when rows arrive in 0.1 s blocks (after training)."""
    from monitor import Monitor, MonitorOptions, read_exchange

    df = read_exchange(path, columns=["x2"])
    t = df["time"].to_numpy()
    x = df["x2"].to_numpy()
    mon = Monitor(MonitorOptions(model=model, signal="x2"))
    costs = []
    for start in range(0, t.size, 10):
        before = mon.n_evaluations
        t0 = time.perf_counter()
        mon.feed(t[start:start + 10], x[start:start + 10])
        dt = time.perf_counter() - t0
        if mon.trained and mon.n_evaluations == before + 1 and mon.fits and t[start] > mon.fits[0].end + 1.0:
            costs.append(dt)
    return statistics.median(costs)


def time_cli(path: Path, model: str, out_dir: Path) -> float:
    start = time.perf_counter()
    subprocess.run([str(BIN / "fourbar-monitor"), str(path), "--model", model, "--quiet", "--out", str(out_dir)],
                   check=False, capture_output=True)
    return time.perf_counter() - start


def detection_table(paths: dict[str, Path], seeds: int, models: tuple[str, ...] = MODELS) -> list[dict]:
    from monitor import replay

    rows = []
    for model in models:
        for noisy in (False, True):
            keys = [""] if not noisy else [f"_noise{s}" for s in range(1, seeds + 1)]
            lat, fa2, fa1, ratio1, thr = [], [], [], [], []
            for key in keys:
                r2 = replay(paths["case2" + key], model=model).summary
                r1 = replay(paths["case1" + key], model=model).summary
                lat.append(r2.detection_latency)
                fa2.append(r2.false_alarms)
                fa1.append(r1.alarms)
                ratio1.append(r1.max_statistic_over_threshold)
                thr.append(detection_limit(r2.fit.rule))
            rows.append({"model": model, "noise": f"σ = {NOISE_STD * 1000:g} mm, {len(keys)} seeds" if noisy else "none",
                         "latency": lat, "fa2": sum(fa2), "fa1": sum(fa1), "ratio1": max(ratio1),
                         "thr": (min(thr), max(thr))})
    return rows


def detection_limit(rule) -> float:
    """The alarm level of a fitted detector: the CUSUM's limit h (in noise units) or the MAE
    threshold's base (in the signal's unit)."""
    for name in ("h", "base"):
        value = getattr(rule, name, None)
        if value is not None:
            return float(value)
    raise TypeError(f"{type(rule).__name__}: no alarm level (expected a CUSUM design or a threshold rule)")


def fmt_lat(values: list) -> str:
    if any(v is None for v in values):
        return "missed in " + str(sum(v is None for v in values))
    if len(values) == 1:
        return f"{values[0]:.2f}"
    return f"{min(values):.2f} – {max(values):.2f} (median {statistics.median(values):.2f})"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--fmu", type=Path, default=REPO / "build" / "FourBar.fmu")
    p.add_argument("--seeds", type=int, default=5, help="noise seeds per case (default 5)")
    p.add_argument("--repeat", type=int, default=3, help="timed replays per model (median; default 3)")
    p.add_argument("--models", default=",".join(MODELS), help="models, comma-separated (default %(default)s)")
    p.add_argument("--data", type=Path, help="directory for the runs (reused when present); default: a temp dir")
    p.add_argument("--quick", action="store_true",
                   help="smallest setting (smoke test): --seeds 1 --repeat 1 --models harmonic")
    args = p.parse_args(argv)
    if args.quick:
        args.seeds, args.repeat, args.models = 1, 1, "harmonic"
    models = tuple(m.strip() for m in args.models.split(",") if m.strip())
    unknown = sorted(set(models) - set(MODELS))
    if unknown or not models or args.seeds < 1 or args.repeat < 1:
        p.error(f"--models: expected some of {', '.join(MODELS)}; --seeds and --repeat: at least 1")
    from monitor import MonitorOptions

    defaults = MonitorOptions()

    with tempfile.TemporaryDirectory(prefix="monitor_bench_") as tmp:
        base = args.data or Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        paths = make_runs(base, args.fmu.resolve(), args.seeds)
        runs_s = time.perf_counter() - t0
        speed = {m: time_replays(paths["case2"], m, args.repeat, Path(tmp) / "out") for m in models}
        live = {m: time_live_evaluations(paths["case2"], m) for m in models}
        cli = {m: time_cli(paths["case2"], m, Path(tmp) / f"cli_{m}") for m in models}
        table = detection_table(paths, args.seeds, models)

    import sklearn
    versions = f"scikit-learn {sklearn.__version__}"
    if "prophet" in models:
        import prophet
        versions = f"prophet {prophet.__version__}, {versions}"
    if defaults.detector == "cusum":
        setting = (f"detector cusum, {defaults.settings.false_alarm_rate:g} false alarms/h designed, statistic recorded every "
                   f"{defaults.every:g} s")
        limit = "CUSUM limit h"
    else:
        own = defaults.settings
        setting = (f"detector mae, window {own.window:g} s every {defaults.every:g} s, persistence "
                   f"{own.persistence}, threshold {own.threshold}")
        limit = "auto threshold base (m)"

    print("## Monitor: replay speed and detection (benchmarks/monitor_replay.py)\n")
    print(f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
          f"{platform.python_version()}, {versions}. "
          f"Exchange files from fourbar-run ({runs_s:.0f} s for {2 + 2 * args.seeds} runs). "
          f"Default settings: training {defaults.train[0]:g}–{defaults.train[1]:g} s, Fourier order {defaults.order}, "
          f"{setting}.\n")
    print("### Speed: replay of Case 2 (100 s of data, 10,001 rows, "
          f"{speed[models[0]]['n_eval']} evaluations)\n")
    print("| model | model fit (s) | training: period + fit + validation (s) | per evaluation, replay (ms) "
          "| per evaluation, live 0.1 s blocks (ms) | replay wall (s) | real-time factor | "
          "with outputs + plots: wall (s) / factor | cold command `fourbar-monitor` (s) | target |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    targets = {"prophet": "≥ 50×", "harmonic": "≥ 1000×"}
    for m in models:
        s = speed[m]
        print(f"| {m} | {s['fit']:.3f} | {s['train']:.3f} | {1e3 * s['per_eval_batch']:.4f} | "
              f"{1e3 * live[m]:.2f} | {s['wall']:.3f} | **{s['rtf']:.0f}×** | {s['wall_out']:.2f} / "
              f"{s['rtf_out']:.0f}× | {cli[m]:.1f} | {targets[m]} |")
    print("\nReplay wall = in-process `monitor.replay()` after a warm-up replay (imports done), median of "
          f"{args.repeat}; it includes reading and parsing the file, training and every evaluation. "
          "The cold command adds the interpreter start, imports (pandas, scipy, scikit-learn, matplotlib, "
          "and Prophet/cmdstanpy for prophet) and writing the three PNGs.\n")
    print("### Detection: Case 2 latency after the fault at 10 s, and false alarms\n")
    print("| model | sensor noise on x2 | Case 2 first alarm − 10 s (s) | false alarms before the fault "
          f"(Case 2) | alarms in Case 1 (100 s) | largest statistic/limit in Case 1 | {limit} | "
          "paper |")
    print("|---|---|---|---|---|---|---|---|")
    for row in table:
        thr = row["thr"]
        thr_s = f"{thr[0]:.4g}" if abs(thr[1] - thr[0]) <= 1e-6 * abs(thr[0]) else f"{thr[0]:.4g} – {thr[1]:.4g}"
        print(f"| {row['model']} | {row['noise']} | {fmt_lat(row['latency'])} | {row['fa2']} | {row['fa1']} | "
              f"{row['ratio1']:.2f} | {thr_s} | {PAPER_LATENCY_S:g} s |")
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
