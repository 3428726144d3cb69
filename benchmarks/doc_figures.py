#!/usr/bin/env python3
"""The figures quoted in README.md and docs/, measured afresh and compared with the text.

Every figure below is declared once: the file it is quoted in, a regular expression that
finds it there, and the measurement that produces it.  ``--check`` measures and lists each
figure with its quoted and fresh values (exit 1 when any differs, or when a quote is no
longer found); ``--write`` puts the fresh values into the files.  ``tests/test_doc_figures.py``
runs the check, so a change of code that moves a figure fails the suite until the docs are
rewritten with ``python benchmarks/doc_figures.py --write``.

Only figures that a rerun reproduces are here (detection, accuracy, FMU outputs).  Timings
depend on load and live in docs/benchmarks.md, written by ``make benchmarks``.

Measured: Case 1 and Case 2 from fourbar-run, clean and with σ = 5 mm on x2 (5 seeds), both
monitor models at default settings (``benchmarks/monitor_replay.py`` makes and scores the
runs); Case 2 through ``fmpy.simulate_fmu`` as docs/fmi_hosts.md shows it.  About a minute
on 2 cores.

Usage: python benchmarks/doc_figures.py [--check | --write] [--data DIR]
"""
from __future__ import annotations

import argparse
import math
import re
import statistics
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

SEEDS = 5
FAULT_TIME = 10.0        # s, Case 2
#: Rows of Case 2 quoted in docs/fmi_hosts.md, compared to this relative tolerance, Table 1's
#: rtol: the model's linear solves and the integrator's stage sums go through OpenBLAS
#: kernels chosen per CPU, so the last bits may differ between machines, and an adaptive
#: step taken or rejected differently moves the output by up to about the tolerance.  A
#: change of the model or the integrator moves it by more: an earlier build differed by
#: 3e-8 at 10 s.
FMPY_ROWS = (0.0, 10.0, 10.01)
ROW_RTOL = 1e-9


@dataclass(frozen=True)
class Quote:
    """Where a figure is quoted: ``pattern`` has one group per key in ``keys``."""

    file: str
    pattern: str
    keys: tuple[str, ...]


def sig(value: float, digits: int = 2) -> str:
    """``value`` in compact scientific notation with ``digits`` significant digits: 2.6e-4."""
    mantissa, exponent = f"{value:.{digits - 1}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def sig_up(value: float) -> str:
    """One significant digit, rounded up (for "within"/"at most" quotes): 1.3e-8 -> 2e-8."""
    exponent = math.floor(math.log10(value))
    digit = math.ceil(value / 10 ** exponent - 1e-9)
    if digit == 10:
        digit, exponent = 1, exponent + 1
    return f"{digit}e{exponent}"


def spread(values: list[float]) -> tuple[str, str, str]:
    return f"{min(values):.2f}", f"{max(values):.2f}", f"{statistics.median(values):.2f}"


def same(per_model: dict[str, str]) -> str:
    """One text when both models give it, else both, so the quote cannot match."""
    texts = set(per_model.values())
    return texts.pop() if len(texts) == 1 else " / ".join(f"{m} {v}" for m, v in per_model.items())


QUOTES = (
    # README: results table
    Quote("README.md", r"CUSUM \(default\): \*\*(\S+) s \(latency (\S+) s\)\*\*, (\S+) alarm episode; the paper's "
                       r"MAE rule \(`--detector mae`\): \*\*(\S+) s \(latency (\S+) s\)\*\*; Prophet and harmonic alike",
          ("cusum_first_alarm", "cusum_latency_clean", "cusum_episodes_case2_clean", "first_alarm", "latency_clean")),
    Quote("README.md", r"\(5 seeds\) \| — \| CUSUM: latency (\S+)–(\S+) s \(median (\S+)\); MAE rule: latency "
                       r"(\S+)–(\S+) s \(median (\S+)\)",
          ("cusum_latency_noisy_min", "cusum_latency_noisy_max", "cusum_latency_noisy_median",
           "latency_noisy_min", "latency_noisy_max", "latency_noisy_median")),
    Quote("README.md", r"CUSUM: \*\*(\S+)\*\*, clean and noisy, both models; largest statistic/limit in Case 1: (\S+) "
                       r"clean, (\S+) noisy\. MAE rule: \*\*(\d+)\*\*, clean and noisy, both models; largest "
                       r"MAE/threshold in Case 1: (\S+) clean, (\S+) noisy",
          ("cusum_false_alarms", "cusum_ratio_clean", "cusum_ratio_noisy", "false_alarms", "ratio_clean",
           "ratio_noisy")),
    Quote("README.md", r"FFT (\S+) s \(bin (\S+) Hz\) → least squares (\S+) s ± (\S+) s \(Case 1, 0–100 s: (\S+) s\)",
          ("fft_period", "fft_bin", "period", "period_stderr", "period_whole_run")),
    Quote("README.md", r"MAE (\S+) m in the first 0\.5 s window after training, ≤ (\S+) m over all of Case 1 "
                       r"\((\S+) × the 5 mm threshold\); Prophet and harmonic forecasts within (\S+) m over 91 s",
          ("mae_first_window", "mae_max_case1", "ratio_clean", "models_apart")),
    # docs/monitor.md: detection table
    *(Quote("docs/monitor.md", rf"\| {model} \| none \| (\S+) s \| (\d+) \| (\d+) \| (\S+) \|",
            (f"latency_clean.{model}", f"false_alarms_case2_clean.{model}", f"alarms_case1_clean.{model}",
             f"ratio_clean.{model}")) for model in ("prophet", "harmonic")),
    *(Quote("docs/monitor.md", rf"\| {model} \| σ = 5 mm \| (\S+)–(\S+) s \(median (\S+)\) \| (\d+) \| (\d+) \| (\S+) \|",
            (f"latency_noisy_min.{model}", f"latency_noisy_max.{model}", f"latency_noisy_median.{model}",
             f"false_alarms_case2_noisy.{model}", f"alarms_case1_noisy.{model}", f"ratio_noisy.{model}"))
      for model in ("prophet", "harmonic")),
    # docs/fmi_hosts.md: rows of fmpy simulate's Case 2 output
    *(Quote("docs/fmi_hosts.md", rf"(?m)^{re.escape(repr(t))},((?:[-+0-9.e]+,){{5}}[-+0-9.e]+)$",
            (f"fmpy_row.{t!r}",)) for t in FMPY_ROWS),
)


def detection_figures(c1, c2, n1, n2) -> dict[str, str]:
    """Case 1/2 detection figures of one detector from the clean (c1, c2) and noisy (n1, n2) summaries."""
    lat = [s.detection_latency for s in n2]
    if any(v is None for v in lat):
        lat_min = lat_max = lat_med = "missed"
    else:
        lat_min, lat_max, lat_med = spread(lat)
    return {
        "latency_clean": f"{c2.detection_latency:.2f}",
        "first_alarm": f"{round(c2.score.detection_time, 2):g}",
        "false_alarms_case2_clean": str(c2.false_alarms),
        "alarms_case1_clean": str(c1.alarms),
        "episodes_case2_clean": str(c2.alarms),
        "ratio_clean": f"{c1.max_statistic_over_threshold:.2f}",
        "latency_noisy_min": lat_min, "latency_noisy_max": lat_max, "latency_noisy_median": lat_med,
        "false_alarms_case2_noisy": str(sum(s.false_alarms for s in n2)),
        "alarms_case1_noisy": str(sum(s.alarms for s in n1)),
        "ratio_noisy": f"{max(s.max_statistic_over_threshold for s in n1):.2f}",
    }


def measure(data: Path) -> dict[str, str]:
    """Every figure, formatted as quoted."""
    import numpy as np
    from fmpy import simulate_fmu
    from monitor import dominant_period, read_exchange, replay
    from monitor_replay import MODELS, make_runs

    from orchestrator import install_pythonfmu_exit_guard

    install_pythonfmu_exit_guard()
    fmu = REPO / "build" / "FourBar.fmu"
    paths = make_runs(data, fmu, SEEDS)
    figures: dict[str, str] = {}
    noisy_keys = [f"_noise{s}" for s in range(1, SEEDS + 1)]
    per: dict[str, dict[str, str]] = {}
    histories = {}
    false_alarms = 0           # Case 1 alarms and Case 2 alarms before the fault, every run (mae)
    cusum_false = 0            # the same for the cusum detector
    for model in MODELS:
        c1 = replay(paths["case1"], model=model, detector="mae")
        c2 = replay(paths["case2"], model=model, detector="mae")
        histories[model] = c2.history
        n1 = [replay(paths["case1" + k], model=model, detector="mae").summary for k in noisy_keys]
        n2 = [replay(paths["case2" + k], model=model, detector="mae").summary for k in noisy_keys]
        values = detection_figures(c1.summary, c2.summary, n1, n2)
        values.update({
            "mae_first_window": sig(float(c1.evaluations.statistic.iloc[0]), 1),
            "mae_max_case1": sig(float(c1.evaluations.statistic.max())),
        })
        # the sequential detector (the default) on the same runs
        q1 = replay(paths["case1"], model=model).summary
        q2 = replay(paths["case2"], model=model).summary
        m1 = [replay(paths["case1" + k], model=model).summary for k in noisy_keys]
        m2 = [replay(paths["case2" + k], model=model).summary for k in noisy_keys]
        values.update({f"cusum_{k}": v for k, v in detection_figures(q1, q2, m1, m2).items()})
        false_alarms += (c1.summary.alarms + c2.summary.false_alarms + sum(s.false_alarms for s in n2)
                         + sum(s.alarms for s in n1))
        cusum_false += q1.alarms + q2.false_alarms + sum(s.false_alarms for s in m2) + sum(s.alarms for s in m1)
        for key, text in values.items():
            figures[f"{key}.{model}"] = text
            per.setdefault(key, {})[model] = text
        estimate = c2.summary.fits[0].estimate
        per.setdefault("fft_period", {})[model] = f"{estimate.fft_period:.3f}"
        per.setdefault("fft_bin", {})[model] = f"{estimate.fft_bin_width:.2f}"
        per.setdefault("period", {})[model] = f"{estimate.period:.7f}"
        per.setdefault("period_stderr", {})[model] = sig(estimate.period_stderr)
    for key, by_model in per.items():
        figures[key] = same(by_model)
    figures["false_alarms"] = str(false_alarms)
    figures["cusum_false_alarms"] = str(cusum_false)
    a, b = (histories[m].forecast.to_numpy() for m in MODELS)
    figures["models_apart"] = sig_up(float(np.nanmax(np.abs(a - b))))
    whole = read_exchange(paths["case1"])
    figures["period_whole_run"] = f"{dominant_period(whole.time.to_numpy(), whole.x2.to_numpy()).period:.7f}"

    l2 = np.array([(0.0, 1.0), (FAULT_TIME, 1.0), (FAULT_TIME, 1.1)], dtype=[("time", float), ("L2", float)])
    result = simulate_fmu(str(fmu), stop_time=100.0, output_interval=0.01, input=l2,
                          output=["x2", "y2", "x3", "y3", "x4", "y4"])
    for t in FMPY_ROWS:
        row = result[int(round(t / 0.01))]
        figures[f"fmpy_row.{t!r}"] = ",".join(repr(float(row[name])) for name in ("x2", "y2", "x3", "y3", "x4", "y4"))
    return figures


@dataclass(frozen=True)
class Finding:
    file: str
    key: str
    quoted: str | None       # None: the quote was not found
    fresh: str

    @property
    def ok(self) -> bool:
        if self.quoted is None:
            return False
        if self.key.startswith("fmpy_row."):
            a = [float(v) for v in self.quoted.split(",")]
            b = [float(v) for v in self.fresh.split(",")]
            return len(a) == len(b) and all(math.isclose(x, y, rel_tol=ROW_RTOL) for x, y in zip(a, b))
        return self.quoted == self.fresh


def compare(figures: dict[str, str], root: Path = REPO) -> list[Finding]:
    """Each quote's text against the fresh figures (a quote found in no place is a finding)."""
    findings = []
    for quote in QUOTES:
        text = (root / quote.file).read_text(encoding="utf-8")
        matches = list(re.finditer(quote.pattern, text))
        if not matches:
            findings += [Finding(quote.file, key, None, figures[key]) for key in quote.keys]
            continue
        for match in matches:
            findings += [Finding(quote.file, key, match.group(i + 1), figures[key])
                         for i, key in enumerate(quote.keys)]
    return findings


def rewrite(figures: dict[str, str], root: Path = REPO) -> list[str]:
    """Put the fresh figures into the files; returns the files changed."""
    changed = []
    for file in sorted({q.file for q in QUOTES}):
        path = root / file
        text = original = path.read_text(encoding="utf-8")
        for quote in (q for q in QUOTES if q.file == file):
            def fill(match: re.Match, quote: Quote = quote) -> str:
                out, last = [], match.start()
                for i, key in enumerate(quote.keys):
                    out += [match.string[last:match.start(i + 1)], figures[key]]
                    last = match.end(i + 1)
                out.append(match.string[last:match.end()])
                return "".join(out)
            text = re.sub(quote.pattern, fill, text)
        if text != original:
            path.write_text(text, encoding="utf-8")
            changed.append(file)
    return changed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     epilog="Without --check or --write: print the fresh figures.")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true", help="compare the quotes with fresh figures (exit 1 if stale)")
    mode.add_argument("--write", action="store_true", help="write the fresh figures into the files")
    parser.add_argument("--data", type=Path, help="folder for the runs (reused when present); default: a temp dir")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="doc_figures_") as tmp:
        data = args.data or Path(tmp)
        data.mkdir(parents=True, exist_ok=True)
        figures = measure(data)
    findings = compare(figures)
    if args.write:
        missing = [f for f in findings if f.quoted is None]
        for f in missing:
            print(f"{f.file}: the quote of {f.key} was not found; edit the text or its pattern in "
                  f"benchmarks/doc_figures.py", file=sys.stderr)
        changed = rewrite(figures)
        print(f"rewrote {', '.join(changed) if changed else 'nothing (all figures current)'}")
        return 1 if missing else 0
    width = max(len(f.key) for f in findings)
    for f in findings:
        mark = "ok   " if f.ok else "STALE"
        print(f"{mark} {f.file:<18} {f.key:<{width}}  quoted {f.quoted if f.quoted is not None else '(not found)'}"
              f"{'' if f.ok else f'  fresh {f.fresh}'}")
    stale = [f for f in findings if not f.ok]
    if args.check:
        print(f"{len(findings) - len(stale)} of {len(findings)} quoted figures current"
              + ("; rewrite with: python benchmarks/doc_figures.py --write" if stale else ""))
        return 1 if stale else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
