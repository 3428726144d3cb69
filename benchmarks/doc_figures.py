#!/usr/bin/env python3
"""The figures quoted in README.md and docs/, measured afresh and compared with the text.

Every figure below is declared once: the file it is quoted in, a regular expression that
finds it there, and the measurement that produces it.  ``--check`` measures and lists each
figure with its quoted and fresh values (exit 1 when any differs, or when a quote is no
longer found); ``--write`` puts the fresh values into the files.  ``tests/test_doc_figures.py``
runs the check, so a change of code that moves a figure fails the suite until the docs are
rewritten with ``python benchmarks/doc_figures.py --write``.

Two kinds of figure:

- **measured** (``measure``): what a rerun reproduces.  Case 1 and Case 2 from fourbar-run,
  clean and with σ = 5 mm on x2 (5 seeds), both monitor models and both detectors
  (``benchmarks/monitor_replay.py`` makes the runs); ``make demo``'s verdict and diagnosis
  (``scripts/demo.py`` run in full, as ``make demo`` runs it), whose history plot is also the
  README's image (``--write`` copies it to docs/img/monitor_case2.png); the text
  ``fourbar-monitor`` prints for Case 2; Case 2 through the ``fmpy.simulate_fmu`` code that
  docs/fmi_hosts.md shows (the block itself is executed) and through
  ``examples/libcosim_case2.py``; docs/orchestrator.md's size of the longest run
  ``exchange.max_rows`` allows by default (from Case 1's exchange file) and the refusal
  ``fourbar-run`` prints for a longer one.  Printed wall times are masked in the comparison.
  About two minutes on 2 cores.
- **copied** (``copied_figures``, no run, a second): timings and counts that the README and
  docs/ quote from the files the benchmarks generate (docs/benchmarks.md from ``make
  benchmarks``, docs/detection.md from ``benchmarks/detection.py``) and the scenario counts
  of the shipped sweep files.  Timings depend on load, so they are measured only by the
  benchmarks; this check keeps every copy equal to its source.

``--root DIR`` compares (and ``--write`` rewrites) the quotes in DIR's copy of README.md and
docs/ instead of this repository's; ``--figures FILE`` takes the fresh figures from a JSON
object (key: text) instead of measuring, and ``--quoted`` prints the figures as the files
quote them now (JSON): with them, tests/test_doc_figures.py and tests/test_docs.py show on a
copy that the check notices a changed or lost quote, running this script as a program.

Usage: python benchmarks/doc_figures.py [--check | --write | --quoted] [--copied | --figures FILE] [--data DIR] [--root DIR]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import re
import shutil
import statistics
import subprocess
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
#: Printed text quoted whole, compared with its wall-clock times masked (they vary with load).
MASKED = {"monitor_replay_text": re.compile(r"fitted in [0-9.]+ s"),
          "libcosim_text": re.compile(r"[0-9.]+ s wall")}
DEMO_CASE = "case2_fault_L2"
DEMO_IMAGE = "docs/img/monitor_case2.png"     # make demo's history plot
#: The shipped mechanisms in docs/benchmarks.md's table against the Reference-FMUs' VanDerPol.
SPEED_MECHANISMS = ("slider_crank", "fourbar", "fourbar_driven", "watt_sixbar", "fivebar")


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
    # README: the image's caption, the opening, make demo's output
    Quote("README.md", r"grows at 10 s; first alarm at (\S+) s\]\(docs/img/monitor_case2\.png\)", ("cusum_first_alarm",)),
    Quote("README.md", r"This monitor alarms at \*\*t = (\S+) s\*\*", ("cusum_first_alarm",)),
    Quote("README.md", r"(?s)```\n(== verdict ==\n.*?\ndiagnosis: [^\n]*)\n  \.\.\.\n```", ("demo_block",)),
    # docs/monitor.md: the opening, a replay's printed text, the detection table
    Quote("docs/monitor.md", r"this monitor alarms (\S+) s after the fault \(clean data\) and (\S+)–(\S+) s after it",
          ("cusum_latency_clean", "cusum_latency_noisy_min", "cusum_latency_noisy_max")),
    Quote("docs/monitor.md", r"(?s)```\n(fourbar-monitor: replaying .*?)\n```", ("monitor_replay_text",)),
    *(Quote("docs/monitor.md", rf"\| {det} \| {model} \| none \| (\S+) s \| (\d+) \| (\d+) \| (\S+) \|",
            (f"{pre}latency_clean.{model}", f"{pre}false_alarms_case2_clean.{model}", f"{pre}alarms_case1_clean.{model}",
             f"{pre}ratio_clean.{model}"))
      for det, pre in (("cusum", "cusum_"), ("mae", "")) for model in ("prophet", "harmonic")),
    *(Quote("docs/monitor.md", rf"\| {det} \| {model} \| σ = 5 mm \| (\S+)–(\S+) s \(median (\S+)\) \| (\d+) \| (\d+) \| (\S+) \|",
            (f"{pre}latency_noisy_min.{model}", f"{pre}latency_noisy_max.{model}", f"{pre}latency_noisy_median.{model}",
             f"{pre}false_alarms_case2_noisy.{model}", f"{pre}alarms_case1_noisy.{model}", f"{pre}ratio_noisy.{model}"))
      for det, pre in (("cusum", "cusum_"), ("mae", "")) for model in ("prophet", "harmonic")),
    # docs/orchestrator.md: what the default exchange.max_rows allows, and the refusal of a longer run
    Quote("docs/orchestrator.md", r"\(default 10,000,000: (\d+) hours at a 0\.01 s step, about (\S+) GB of exchange\.csv "
                                  r"with Case 1's (\d+)\s+outputs", ("max_rows_hours", "max_rows_gb", "case1_outputs")),
    Quote("docs/orchestrator.md", r"(?s)```\n(fourbar-run: error: invalid case huge\.toml: .*?)\n```", ("huge_text",)),
    # docs/fmi_hosts.md: what examples/libcosim_case2.py prints
    Quote("docs/fmi_hosts.md", r"(?s)```\n(libcosim: \d+ samples.*?\nwrote \S+)\n```", ("libcosim_text",)),
    # README: timings and counts copied from the generated docs and the sweep files
    Quote("README.md", r"\| Case 2 through FMPy \| (\S+) s \| (\S+) s, (\S+)× FMPy's own floor",
          ("pythonfmu_s_case2_short", "native_s_case2_short", "native_floor_case2_short")),
    Quote("README.md", r"sweeps/l2_step\.toml`: (\d+) scenarios of 30 s, [^;]*; (\d+) s on 2 cores on the pythonfmu FMU, "
                       r"(\d+) s on the native FMU", ("scenarios.l2_step", "sweep_pythonfmu_s", "sweep_native_s")),
    Quote("README.md", r"identical in all (\d+) pairs\)\. None of the (\d+)\s+runs raised",
          ("fault_runs_per_model.l2_step", "scenarios.l2_step")),
    Quote("README.md", r"CUSUM: median (\S+) s \((\S+)–(\S+) s\), (\S+) alarm episode per run; MAE rule: median (\S+) s, "
                       r"(\d+) episodes per run",
          ("seeds_cusum_median", "seeds_cusum_min", "seeds_cusum_max", "seeds_cusum_episodes", "seeds_mae_median",
           "seeds_mae_episodes")),
    Quote("README.md", r"no false alarm \(sweep of (\d+) runs\)", ("scenarios.l2_step",)),
    Quote("README.md", r"σ = 5 mm, (\d+) seeds \| — \| CUSUM: first alarm (\S+)–(\S+) s after the ramp starts \(median "
                       r"(\S+); target ≤ 2 s: at the limit\), \*\*(\S+)\*\* episode per run; MAE rule: (\S+)–(\S+) s, "
                       r"(\S+) episodes",
          ("case3_n", "case3_cusum_min", "case3_cusum_max", "case3_cusum_median", "case3_cusum_episodes",
           "case3_mae_min", "case3_mae_max", "case3_mae_episodes")),
    Quote("README.md", r"\| (\S+) m \(Case 1\), (\S+) m \(Case 2\) at rtol = atol = 1e-12; (\S+) m / (\S+) m at Table 1's "
                       r"tolerances \|", ("acc_pos_tight_case1", "acc_pos_tight_case2", "acc_pos_table1_case1",
                                          "acc_pos_table1_case2")),
    Quote("README.md", r"\| (\S+) J at 1e-12; (\S+) J at Table 1's tolerances", ("acc_energy_tight", "acc_energy_table1")),
    Quote("README.md", r"constraint residual at every output \| — \| ≤ (\S+) \|", ("acc_constraint",)),
    # (the native FMU's speed-up over the pythonfmu FMU is quoted in docs/benchmarks.md only;
    # tests/test_docs.py refuses a copy of it anywhere else)
    Quote("README.md", r"native (\S+) s / (\S+) s \(Case 1 / 2\) = \*\*(\S+)× / (\S+)× the floor\*\* \(target ≤ 1\.5×\); "
                       r"pythonfmu (\S+) s / (\S+) s \(the speed-up[^|]*is 1/(\S+) of the pythonfmu time",
          ("native_s_case1", "native_s_case2", "native_floor_case1", "native_floor_case2", "pythonfmu_s_case1",
           "pythonfmu_s_case2", "floor_share_case2")),
    Quote("README.md", r"\| (\S+) ms, (\S+) RHS evaluations \(Case 1\), (\S+) µs per evaluation all work included; "
                       r"pythonfmu's model in-process (\S+) s \|", ("cmodel_ms", "cmodel_rhs", "cmodel_us", "replay_model_s")),
    Quote("README.md", r"\| native (\S+) s \(rtol = atol = (\S+); \*\*(\S+)×\*\* faster than 38 s\), pythonfmu (\S+) s \|",
          ("to1e6_native_s", "to1e6_tol", "to1e6_exudyn", "to1e6_pythonfmu_s")),
    Quote("README.md", r"\| (\S+) m at rtol = atol = 1e-12; up to (\S+) m at Table 1's", ("agree_tight", "agree_table1")),
    Quote("README.md", r"\| (\S+) s vs (\S+) s: (\S+)× \(Case 1\), (\S+)× \(Case 2\); scipy's DOP853 stepping alone "
                       r"\(replay with the model's arithmetic removed\) already makes (\S+)× / (\S+)×; (\S+) RHS evaluations",
          ("speed_wall_case1", "speed_floor_case1", "speed_ratio_case1", "speed_ratio_case2", "replay_ratio_case1",
           "replay_ratio_case2", "speed_rhs_range")),
    Quote("README.md", r"plain `fmpy.simulate_fmu` \| — \| (\S+)× \(target ≤ 1\.2×\)", ("overhead_ratio",)),
    Quote("README.md", r"the native FMUs take (\S+)× \(slider-crank\), (\S+)× \(four-bar\), (\S+)× \(driven\s+four-bar\), "
                       r"(\S+)× \(Watt six-bar\) and (\S+)× \(five-bar\) the Reference-FMUs' VanDerPol; at Table 1's\s+"
                       r"tolerances (\S+)×, (\S+)×, (\S+)×, (\S+)× and (\S+)×",
          tuple(f"vdp_{tolerance}.{mechanism}" for tolerance in ("default", "table1") for mechanism in SPEED_MECHANISMS)),
    Quote("README.md", r"\| Prophet (\d+)× / (\d+)×, harmonic (\d+)× / (\d+)× \(targets",
          ("monitor_prophet", "monitor_prophet_outputs", "monitor_harmonic", "monitor_harmonic_outputs")),
    Quote("README.md", r"\| (\d+) scenarios/min on 1 worker, (\d+) on 2 \(×(\S+)\) \|", ("scaling_1", "scaling_2", "scaling_speedup")),
    Quote("README.md", r"\(248 scenarios, Prophet and harmonic\) \| — \| (\d+) s on the pythonfmu FMU, (\d+) s on the native FMU \|",
          ("sweep_pythonfmu_s", "sweep_native_s")),
    Quote("README.md", r"The pythonfmu FMU is (\S+)× slower than a trivial pythonfmu FMU", ("speed_ratio_range",)),
    Quote("README.md", r"over its\s+~(\S+) DOP853 evaluations per 100 s", ("rhs_fivebar",)),
    # README: the diagnosis targets copied from docs/diagnosis.md (benchmarks/classification.py)
    Quote("README.md", r"\| right parameter in ≥ 95 % of diagnosed faults \| (\d+) / (\d+) \(", ("diag_right", "diag_detected")),
    Quote("README.md", r"\| value within 0\.1 % noise-free \| largest error (\S+) %", ("diag_error_clean",)),
    Quote("README.md", r"\| value within 1 % with 5 mm noise \| largest error (\S+) %", ("diag_error_noisy",)),
    Quote("README.md", r"\| ≤ 10 s per diagnosis on 2 cores \| slowest (\S+) s", ("diag_slowest",)),
    Quote("README.md", r"fitted again on the 10 s after the alarm: (\S+)–(\S+), (\S+)–(\S+) and (\S+)–(\S+) s at (\S+), "
                       r"(\S+) and (\S+) mm/s", tuple(f"diag_ramp.{i}" for i in range(1, 10))),
    # README: the detection rows copied from docs/detection.md (benchmarks/detection.py)
    Quote("README.md", r"links: slowest (\S+) s \(target 2 s\); masses: slowest (\S+) s \(target 5 s\)",
          ("slowest_links", "slowest_masses")),
    Quote("README.md", r"median latency (\S+) s on x2 alone, (\S+) s on all six columns \((\S+)× faster\)",
          ("several_x2", "several_all", "several_gain")),
    Quote("README.md", r"mean latency (\S+) s after 10 s, (\S+) s after 500 s, (\S+) s after 3600 s \(within (\d+) %",
          ("late_mean_10", "late_mean_500", "late_mean_3600", "late_within")),
    Quote("README.md", r"default 0\.01/h \| — \| \*\*(\d+)\*\* in (\S+) h before the late faults; at a design of 10/h: "
                       r"(\d+) alarms? in (\S+) fault-free h \((\S+) expected",
          ("late_false", "late_hours", "calib10_alarms", "calib_hours", "calib10_expected")),
    Quote("README.md", r"following an hour of the four-bar at 100 Hz it\s+went from (\d+) to (\d+) MB",
          ("view_memory_first", "view_memory_last")),
    Quote("README.md", r"scipy's own stepping alone already costs (\S+)×", ("replay_ratio_range",)),
    Quote("README.md", r"beyond Table 1: (\d+) generated configurations .*? false alarms per healthy hour: (\S+) clean, "
          r"(\S+) noisy \((\S+) h in all\); median delay of a 1 % length step (\S+) s clean, (\S+) s noisy, of a "
          r"10 % mass step (\S+) s / (\S+) s; right parameter named for (\S+) % / (\S+) %",
          ("robust_configs", "robust_fa_clean", "robust_fa_noisy", "robust_hours", "robust_length_clean",
           "robust_length_noisy", "robust_mass_clean", "robust_mass_noisy", "robust_right_clean", "robust_right_noisy")),
    Quote("docs/monitor.md", r"at the defaults, (\S+) per healthy hour clean and (\S+)\s+with noise \((\S+) h in all",
          ("robust_fa_clean", "robust_fa_noisy", "robust_hours")),
    # docs/sweep.md: counts, timings and the headline table, copied
    Quote("docs/sweep.md", r"# (\d+) scenarios, each a 20 s run", ("scenarios.smoke",)),
    Quote("docs/sweep.md", r"the headline sweep: (\d+) scenarios \((\d+) s on 2 cores in docs/benchmarks\.md\)",
          ("scenarios.l2_step", "sweep_pythonfmu_s")),
    Quote("docs/sweep.md", r"took (\d+) s on it against (\d+) s on the pythonfmu FMU", ("sweep_native_s", "sweep_pythonfmu_s")),
    Quote("docs/sweep.md", r"From the same (\d+) runs:", ("scenarios.l2_step",)),
    Quote("docs/sweep.md", r"none of the (\d+) runs raised a false alarm", ("scenarios.l2_step",)),
    Quote("docs/sweep.md", r"in all (\d+) pairs of", ("fault_runs_per_model.l2_step",)),
    Quote("docs/sweep.md", r"Command \((\d+) s on 2 cores on the pythonfmu FMU, (\d+) s on the native FMU",
          ("sweep_pythonfmu_s", "sweep_native_s")),
    Quote("docs/sweep.md", r"(\d+) scenarios/min on 1 worker,\s+(\d+) on 2 \(×(\S+)\) in the last run",
          ("scaling_1", "scaling_2", "scaling_speedup")),
    *(Quote("docs/sweep.md", rf"\| {noise} \| {model} \| \*\*(\S+) %\*\*(?: \([^)]*\))? \| (\S+) s \| (\d+) / (\d+) \|",
            tuple(f"l2table.{4 * row + i}" for i in range(1, 5)))
      for row, (noise, model) in enumerate((("none", "Prophet"), ("none", "harmonic"), ("σ = 5 mm", "Prophet"),
                                            ("σ = 5 mm", "harmonic")))),
    # docs/fmi_hosts.md: rows of fmpy simulate's Case 2 output
    *(Quote("docs/fmi_hosts.md", rf"(?m)^{re.escape(repr(t))},((?:[-+0-9.e]+,){{5}}[-+0-9.e]+)$",
            (f"fmpy_row.{t!r}",)) for t in FMPY_ROWS),
)


#: Figures the README and docs copy from generated files: (key prefix, file, pattern), each
#: group of the pattern a figure ``<prefix>.<i>`` (1-based), formatted by ``copied_figures``.
SOURCES = (
    ("fmpy", "docs/benchmarks.md", r"\| Case 1 \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+)x \| ([\d.]+)x \|\n"
                                   r"\| Case 2 \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+)x \| ([\d.]+)x \|"),
    ("cmodel", "docs/benchmarks.md", r"\| Case 1 \| 1e-9, 1e-6 \(Table 1\) \| ([\d.]+) \| ([\d,]+) \| \d+ \| ([\d.]+) \|"),
    ("to1e6", "docs/benchmarks.md", r"\| native \| ([\de.+-]+) \| [\de.+-]+ \| ([\d.]+) \| (\d+)x faster \|\n"
                                    r"\| pythonfmu \| [\de.+-]+ \| [\de.+-]+ \| ([\d.]+) \|"),
    ("agree", "docs/benchmarks.md", r"\| Case 1 \| Table 1 \(1e-9, 1e-6\) \| ([\de.+-]+) \|[^\n]*\n\| Case 1 \| 1e-12 \| ([\de.+-]+) \|"
                                    r"[^\n]*\n\| Case 2 \| Table 1 \(1e-9, 1e-6\) \| ([\de.+-]+) \|[^\n]*\n"
                                    r"\| Case 2 \| 1e-12 \| ([\de.+-]+) \|"),
    ("sweep", "docs/benchmarks.md", r"\| pythonfmu \| (\d+) \| (\d+) \| \d+ \|\n\| native \| \d+ \| (\d+) \| \d+ \|"),
    ("speed", "docs/benchmarks.md", r"\| FourBar Case 1 \| ([\d.]+) \| ([\d.]+) \| ([\d.]+)x \|[^\n]*\| (\d+) \|\n"
                                    r"\| FourBar Case 2 \| ([\d.]+) \| ([\d.]+) \| ([\d.]+)x \|[^\n]*\| (\d+) \|"),
    ("replay", "docs/benchmarks.md", r"\| FourBar Case 1 \| ([\d.]+) \| [\d.]+ \| ([\d.]+)x \|\n"
                                     r"\| FourBar Case 2 \| [\d.]+ \| [\d.]+ \| ([\d.]+)x \|"),
    ("accuracy", "docs/benchmarks.md", r"\| Case 1 \| Table 1: rtol 1e-9, atol 1e-6 \| ([\de.+-]+) \| ([\de.+-]+) \| ([\de.+-]+) \|\n"
                                       r"\| Case 1 \| rtol = atol = 1e-12 \| ([\de.+-]+) \| ([\de.+-]+) \| ([\de.+-]+) \|\n"
                                       r"\| Case 2 \| Table 1: rtol 1e-9, atol 1e-6 \| ([\de.+-]+) \| ([\de.+-]+) \| ([\de.+-]+) \|\n"
                                       r"\| Case 2 \| rtol = atol = 1e-12 \| ([\de.+-]+) \| ([\de.+-]+) \| ([\de.+-]+) \|"),
    ("slowest", "docs/detection.md", r"- L1 \+1 %, σ = 3 mm: slowest ([\d.]+) s[^\n]*\n- L2 \+1 %, σ = 3 mm: slowest ([\d.]+) s"
                                     r"[^\n]*\n- L3 \+1 %, σ = 3 mm: slowest ([\d.]+) s[^\n]*\n- L4 \+1 %, σ = 3 mm: slowest "
                                     r"([\d.]+) s[^\n]*\n- m2 \+10 %, σ = 3 mm: slowest ([\d.]+) s[^\n]*\n- m3 \+10 %, σ = 3 mm: "
                                     r"slowest ([\d.]+) s[^\n]*\n- m4 \+10 %, σ = 3 mm: slowest ([\d.]+) s"),
    ("several", "docs/detection.md", r"\| L1 \| ([\d.]+) s \(median[^|]*\| ([\d.]+) s \(median[^|]*\| ([\d.]+)× \|\n"
                                     r"\| L3 \| ([\d.]+) s \(median[^|]*\| ([\d.]+) s \(median[^|]*\| ([\d.]+)× \|\n"
                                     r"\| L4 \| ([\d.]+) s \(median[^|]*\| ([\d.]+) s \(median[^|]*\| ([\d.]+)× \|"),
    ("late", "docs/detection.md", r"\| 10 s \| [^|]+ \| ([\d.]+) s \| [\d.]+ \| \d+ \| ([\d.]+) \| (\d+) \|\n"
                                  r"\| 500 s \| [^|]+ \| ([\d.]+) s \| ([\d.]+) \| \d+ \| ([\d.]+) \| (\d+) \|\n"
                                  r"\| 3600 s \| [^|]+ \| ([\d.]+) s \| ([\d.]+) \| \d+ \| ([\d.]+) \| (\d+) \|"),
    ("calib", "docs/detection.md", r"\| 10 /h \| ([\d.]+) \| (\d+) \| ([\d.]+) \|"),
    ("diag", "docs/diagnosis.md", r"\| right parameter >= 95 % of the diagnosed faults \| (\d+) / (\d+) = [^\n]*\n[^\n]*\n"
                                  r"\| value within 0\.1 % noise-free \| largest error ([\d.e+-]+) % \|[^\n]*\n"
                                  r"\| value within 1 % with 5 mm noise \| largest error ([\d.]+) % \|[^\n]*\n[^\n]*\n"
                                  r"\| <= 10 s per diagnosis[^|]*\| slowest ([\d.]+) s \|"),
    ("ramps", "docs/diagnosis.md", r"\| 1 \| [\d.]+ s \| L2 \| ramp \| ([\d.]+) s \| ([\d.]+) s \| ([\d.]+) mm/s \|[^\n]*\n"
                                   r"\| 2 \| [\d.]+ s \| L2 \| ramp \| ([\d.]+) s \| ([\d.]+) s \| ([\d.]+) mm/s \|[^\n]*\n"
                                   r"\| 3 \| [\d.]+ s \| L2 \| ramp \| ([\d.]+) s \| ([\d.]+) s \| ([\d.]+) mm/s \|"),
    ("rhs5", "docs/benchmarks.md", r"\| fivebar \| 1e-10, 1e-10 \(default\) \|(?: [^|]+ \|){5} ([\d,]+) \|"),
    ("viewmem", "docs/benchmarks.md", r"\| server resident memory \(MB\) \| (\d+) \| (\d+) \| \d+ \|"),
    ("overhead", "docs/benchmarks.md", r"ratio of medians \(orchestrator / FMPy\): \*\*([\d.]+)\*\*"),
    ("monitor", "docs/benchmarks.md", r"\| prophet \|(?: [^|]+ \|){5} \*\*(\d+)×\*\* \| [\d.]+ / (\d+)× \|[^\n]*\n"
                                      r"\| harmonic \|(?: [^|]+ \|){5} \*\*(\d+)×\*\* \| [\d.]+ / (\d+)× \|"),
    ("scaling", "docs/benchmarks.md", r"\| 1 \| ([\d.]+) \([^)]*\) \|[^\n]*\n\| 2 \| ([\d.]+) \([^)]*\) \| ([\d.]+) \|"),
    # the every-mechanism table: native / VanDerPol at the default tolerance, then at Table 1's
    *((f"vdp_{mechanism}", "docs/benchmarks.md",
       rf"\| {mechanism} \| 1e-10, 1e-10 \(default\) \|(?: [^|]+ \|){{4}} ([\d.]+)x [^|]*\|[^\n]*\n"
       rf"\| {mechanism} \| 1e-9, 1e-6 \(Table 1\) \|(?: [^|]+ \|){{4}} ([\d.]+)x [^|]*\|")
      for mechanism in SPEED_MECHANISMS),
    ("l2table", "docs/detection.md", r"\| none \| prophet \| (\S+) % \| (\S+) s \| (\d+)/(\d+) \|\n"
                                     r"\| none \| harmonic \| (\S+) % \| (\S+) s \| (\d+)/(\d+) \|\n"
                                     r"\| σ = 5 mm \| prophet \| (\S+) % \| (\S+) s \| (\d+)/(\d+) \|\n"
                                     r"\| σ = 5 mm \| harmonic \| (\S+) % \| (\S+) s \| (\d+)/(\d+) \|"),
    ("case2seeds", "docs/detection.md", r"\| cusum \| prophet \| \S+ s \| (\S+) s \(median; (\S+)–(\S+) s, n = (\d+)\) \| \d+ \| (\d+) \|"
                                        r"(?:\n[^\n]*)*?\n\| mae \| prophet \| \S+ s \| (\S+) s \(median; [^)]*\) \| \d+ \| (\d+) \|"),
    # docs/robustness.md's per-family table, in its order (family × clean/noisy): per row the
    # false alarms per healthy hour, the median delays of the 1 % length and 10 % mass steps,
    # and the share of right diagnoses
    ("robust", "docs/robustness.md", r"\| table1_swing \| none \| \d+ \| [\d.]+ \| \d+ \(([\d.]+)\) \| [\d.]+ \| ([\d.]+) / [\d.]+ s[^|]* \| ([\d.]+) / [\d.]+ s[^|]* \| \d+/\d+ \((\d+) %\) \|[^\n]*\n"
                                     r"\| table1_swing \| σ = 3–5 mm \| \d+ \| [\d.]+ \| \d+ \(([\d.]+)\) \| [\d.]+ \| ([\d.]+) / [\d.]+ s[^|]* \| ([\d.]+) / [\d.]+ s[^|]* \| \d+/\d+ \((\d+) %\) \|[^\n]*\n" 
                                     r"\| rotating \| none \| \d+ \| [\d.]+ \| \d+ \(([\d.]+)\) \| [\d.]+ \| ([\d.]+) / [\d.]+ s[^|]* \| ([\d.]+) / [\d.]+ s[^|]* \| \d+/\d+ \((\d+) %\) \|[^\n]*\n" 
                                     r"\| rotating \| σ = 3–5 mm \| \d+ \| [\d.]+ \| \d+ \(([\d.]+)\) \| [\d.]+ \| ([\d.]+) / [\d.]+ s[^|]* \| ([\d.]+) / [\d.]+ s[^|]* \| \d+/\d+ \((\d+) %\) \|[^\n]*\n" 
                                     r"\| other_swing \| none \| \d+ \| [\d.]+ \| \d+ \(([\d.]+)\) \| [\d.]+ \| ([\d.]+) / [\d.]+ s[^|]* \| ([\d.]+) / [\d.]+ s[^|]* \| \d+/\d+ \((\d+) %\) \|[^\n]*\n" 
                                     r"\| other_swing \| σ = 3–5 mm \| \d+ \| [\d.]+ \| \d+ \(([\d.]+)\) \| [\d.]+ \| ([\d.]+) / [\d.]+ s[^|]* \| ([\d.]+) / [\d.]+ s[^|]* \| \d+/\d+ \((\d+) %\) \|"),
    ("robusth", "docs/robustness.md", r"\(do not edit by hand\): (\d+) configurations \((?s:.*?)up to the fault "
                                      r"\(or the end\): ([\d.]+) h in all"),
    ("case3", "docs/detection.md", r"\| cusum \| (\S+) s \(median; (\S+)–(\S+) s, n = (\d+)\) \| (\d+) \| \d+ \|\n"
                                   r"\| mae \| \S+ s \(median; (\S+)–(\S+) s, n = \d+\) \| (\d+), (\d+) \| \d+ \|"),
)


def copied_figures(root: Path = REPO) -> dict[str, str]:
    """The figures quoted from generated files and counted from the sweep files, as quoted (no runs)."""
    raw: dict[str, str] = {}
    for prefix, file, pattern in SOURCES:
        match = re.search(pattern, (root / file).read_text(encoding="utf-8"))
        for i in range(1, re.compile(pattern).groups + 1):
            raw[f"{prefix}.{i}"] = match.group(i) if match else None
    figures: dict[str, str] = {}

    def put(key: str, parts: tuple[str, ...], fmt) -> None:
        if any(raw[p] is None for p in parts):
            figures[key] = f"(not found in {next(f for p_, f, _ in SOURCES if p_ == parts[0].split('.')[0])})"
        else:
            figures[key] = fmt(*(raw[p] for p in parts))

    f2, f1, f0 = (lambda v: f"{float(v):.2f}"), (lambda v: f"{float(v):.1f}"), (lambda v: f"{float(v):.0f}")
    ratio = lambda a, b: float(a) / float(b)                                   # noqa: E731
    put("native_s_case1", ("fmpy.1",), str)
    put("native_s_case2", ("fmpy.6",), str)
    put("native_floor_case1", ("fmpy.4",), f2)
    put("native_floor_case2", ("fmpy.9",), f2)
    put("pythonfmu_s_case1", ("fmpy.2",), f2)
    put("pythonfmu_s_case2", ("fmpy.7",), f2)
    put("floor_share_case2", ("fmpy.7", "fmpy.8"), lambda a, b: f"{ratio(a, b):.1f}")
    put("pythonfmu_s_case2_short", ("fmpy.7",), f1)
    put("native_s_case2_short", ("fmpy.6",), f2)
    put("native_floor_case2_short", ("fmpy.9",), f1)
    put("cmodel_ms", ("cmodel.1",), f0)
    put("cmodel_rhs", ("cmodel.2",), str)
    put("cmodel_us", ("cmodel.3",), str)
    put("to1e6_tol", ("to1e6.1",), lambda v: sig_up(float(v)))
    put("to1e6_native_s", ("to1e6.2",), str)
    put("to1e6_exudyn", ("to1e6.3",), str)
    put("to1e6_pythonfmu_s", ("to1e6.4",), f1)
    put("agree_tight", ("agree.2", "agree.4"), lambda a, b: sig(max(float(a), float(b))))
    put("agree_table1", ("agree.1", "agree.3"), lambda a, b: sig(max(float(a), float(b))))
    put("sweep_scenarios_bm", ("sweep.1",), str)
    put("sweep_pythonfmu_s", ("sweep.2",), str)
    put("sweep_native_s", ("sweep.3",), str)
    put("speed_wall_case1", ("speed.1",), f2)
    put("speed_floor_case1", ("speed.2",), f2)
    put("speed_ratio_case1", ("speed.3",), f1)
    put("speed_ratio_case2", ("speed.7",), f1)
    put("speed_ratio_range", ("speed.3", "speed.7"),
        lambda a, b: f"{min(float(a), float(b)):.1f}–{max(float(a), float(b)):.1f}")
    put("speed_rhs_range", ("speed.4", "speed.8"), lambda a, b: f"{min(int(a), int(b))}–{max(int(a), int(b))}")
    put("replay_model_s", ("replay.1",), f2)
    put("replay_ratio_case1", ("replay.2",), f1)
    put("replay_ratio_case2", ("replay.3",), f1)
    put("replay_ratio_range", ("replay.2", "replay.3"),
        lambda a, b: f"{min(float(a), float(b)):.1f}–{max(float(a), float(b)):.1f}")
    put("acc_pos_tight_case1", ("accuracy.4",), lambda v: sig(float(v)))
    put("acc_pos_tight_case2", ("accuracy.10",), lambda v: sig(float(v)))
    put("acc_pos_table1_case1", ("accuracy.1",), lambda v: sig(float(v)))
    put("acc_pos_table1_case2", ("accuracy.7",), lambda v: sig(float(v)))
    put("acc_energy_tight", ("accuracy.5",), lambda v: sig(float(v)))
    put("acc_energy_table1", ("accuracy.2",), lambda v: sig(float(v)))
    put("acc_constraint", ("accuracy.3", "accuracy.6", "accuracy.9", "accuracy.12"),
        lambda *v: sig(max(float(x) for x in v)))
    put("overhead_ratio", ("overhead.1",), f2)
    for mechanism in SPEED_MECHANISMS:
        put(f"vdp_default.{mechanism}", (f"vdp_{mechanism}.1",), f2)
        put(f"vdp_table1.{mechanism}", (f"vdp_{mechanism}.2",), f2)
    between = lambda *v: f"{min(v, key=float)}–{max(v, key=float)}"          # noqa: E731
    put("diag_right", ("diag.1",), str)
    put("diag_detected", ("diag.2",), str)
    put("diag_error_clean", ("diag.3",), lambda v: sig(float(v), 1))
    put("diag_error_noisy", ("diag.4",), lambda v: f"{float(v):.2f}")
    put("diag_slowest", ("diag.5",), str)
    for i, raw_i in enumerate((1, 2, 4, 5, 7, 8, 3, 6, 9), start=1):      # the starts and ends, then the rates
        put(f"diag_ramp.{i}", (f"ramps.{raw_i}",), str)
    put("slowest_links", tuple(f"slowest.{i}" for i in (1, 2, 3, 4)), between)
    put("slowest_masses", tuple(f"slowest.{i}" for i in (5, 6, 7)), between)
    put("several_x2", ("several.1", "several.4", "several.7"), between)
    put("several_all", ("several.2", "several.5", "several.8"), between)
    put("several_gain", ("several.3", "several.6", "several.9"), between)
    put("late_mean_10", ("late.1",), str)
    put("late_mean_500", ("late.4",), str)
    put("late_mean_3600", ("late.8",), str)
    put("late_within", ("late.5", "late.9"), lambda a, b: f"{max(abs(float(a) - 1), abs(float(b) - 1)) * 100:.0f}")
    put("late_false", ("late.3", "late.7", "late.11"), lambda *v: str(sum(int(x) for x in v)))
    put("late_hours", ("late.2", "late.6", "late.10"), lambda *v: f"{sum(float(x) for x in v):.1f}")
    put("calib_hours", ("calib.1",), str)
    put("calib10_alarms", ("calib.2",), str)
    put("calib10_expected", ("calib.3",), lambda v: f"{float(v):.0f}")
    put("rhs_fivebar", ("rhs5.1",), lambda v: f"{round(int(v.replace(',', '')), -3):,}")
    put("view_memory_first", ("viewmem.1",), str)
    put("view_memory_last", ("viewmem.2",), str)
    put("monitor_prophet", ("monitor.1",), str)
    put("monitor_prophet_outputs", ("monitor.2",), str)
    put("monitor_harmonic", ("monitor.3",), str)
    put("monitor_harmonic_outputs", ("monitor.4",), str)
    put("scaling_1", ("scaling.1",), f0)
    put("scaling_2", ("scaling.2",), f0)
    put("scaling_speedup", ("scaling.3",), str)
    put("seeds_cusum_median", ("case2seeds.1",), str)
    put("seeds_cusum_min", ("case2seeds.2",), str)
    put("seeds_cusum_max", ("case2seeds.3",), str)
    put("seeds_n", ("case2seeds.4",), str)
    put("seeds_cusum_episodes", ("case2seeds.5",), lambda v: "one" if v == "1" else v)
    put("seeds_mae_median", ("case2seeds.6",), str)
    put("seeds_mae_episodes", ("case2seeds.7",), str)
    put("case3_cusum_median", ("case3.1",), str)
    put("case3_cusum_min", ("case3.2",), str)
    put("case3_cusum_max", ("case3.3",), str)
    put("case3_n", ("case3.4",), str)
    put("case3_cusum_episodes", ("case3.5",), lambda v: "one" if v == "1" else v)
    put("case3_mae_min", ("case3.6",), f1)
    put("case3_mae_max", ("case3.7",), f1)
    put("case3_mae_episodes", ("case3.8", "case3.9"), lambda a, b: f"{a}–{b}")
    for i in range(1, 17):
        put(f"l2table.{i}", (f"l2table.{i}",), str)
    # robustness: ranges over the three families, clean rows (0, 2, 4) and noisy rows (1, 3, 5)
    span = lambda *v: (lambda lo, hi: lo if lo == hi else f"{lo}–{hi}")(min(v, key=float), max(v, key=float))  # noqa: E731
    for noise, rows in (("clean", (0, 2, 4)), ("noisy", (1, 3, 5))):
        for field, col in (("fa", 1), ("length", 2), ("mass", 3), ("right", 4)):
            put(f"robust_{field}_{noise}", tuple(f"robust.{4 * r + col}" for r in rows), span)
    put("robust_configs", ("robusth.1",), str)
    put("robust_hours", ("robusth.2",), str)
    figures.update(sweep_counts(root))
    return figures


def sweep_counts(root: Path = REPO) -> dict[str, str]:
    """Scenario counts of the shipped sweep files, as ``fourbar-sweep`` plans them."""
    from sweep import load_sweep, plan_scenarios

    counts = {}
    for name in ("smoke", "l2_step"):
        plan = plan_scenarios(load_sweep(root / "sweeps" / f"{name}.toml"))
        counts[f"scenarios.{name}"] = str(len(plan))
        models = {s.model for s in plan}
        counts[f"fault_runs_per_model.{name}"] = str(sum(1 for s in plan if s.kind != "none") // len(models))
    return counts


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

    # docs/fmi_hosts.md's FMPy example, executed as written (its paths are relative to the repository)
    result = run_python_block("docs/fmi_hosts.md", "### Python API")["result"]
    for t in FMPY_ROWS:
        row = result[int(round(t / 0.01))]
        figures[f"fmpy_row.{t!r}"] = ",".join(repr(float(row[name])) for name in ("x2", "y2", "x3", "y3", "x4", "y4"))

    figures.update(exchange_size(paths["case1"]))
    figures["huge_text"] = refusal_of_a_huge_run(data, fmu)
    figures["monitor_replay_text"] = monitor_text(paths["case2"])
    figures["demo_block"] = demo_block(data)
    figures["libcosim_text"] = printed(data, [sys.executable, str(REPO / "examples" / "libcosim_case2.py"),
                                              "--out", "case2_libcosim.csv"]).strip()
    return figures


def all_figures(data: Path) -> dict[str, str]:
    """Every figure: the copied ones and the measured ones (runs in ``data``)."""
    return {**copied_figures(), **measure(data)}


def python_blocks(text: str) -> list[str]:
    """The ```python blocks of a markdown text, in order."""
    return re.findall(r"(?ms)^```python\n(.*?)^```", text)


def run_python_block(file: str, heading: str) -> dict:
    """Execute the first python block after ``heading`` in ``file`` from the repository's folder; its names."""
    text = (REPO / file).read_text(encoding="utf-8")
    start = text.index(heading)
    block = python_blocks(text[start:])[0]
    names: dict = {"__name__": "__doc_example__"}
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        exec(compile(block, f"{file} ({heading})", "exec"), names)
    finally:
        os.chdir(cwd)
    return names


def printed(cwd: Path, command: list[str]) -> str:
    """What ``command`` prints on stdout (run in ``cwd``); a failure stops the measurement."""
    proc = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=900)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    return proc.stdout


def exchange_size(exchange: Path) -> dict[str, str]:
    """docs/orchestrator.md's size of the longest run allowed by default: the default
    ``exchange.max_rows`` rows of Case 1's exchange file (its mean bytes per row)."""
    from fourbar_common.contract.run_record import read_run_record
    from orchestrator.case import DEFAULT_MAX_ROWS

    record = read_run_record(exchange.parent / "run.json")
    bytes_per_row = exchange.stat().st_size / (record.rows_written + 1)       # the header counted as a row
    return {"max_rows_hours": f"{DEFAULT_MAX_ROWS * record.experiment.step / 3600:.0f}",
            "max_rows_gb": f"{DEFAULT_MAX_ROWS * bytes_per_row / 1e9:.1f}",
            "case1_outputs": str(len(record.outputs))}


def refusal_of_a_huge_run(data: Path, fmu: Path) -> str:
    """What ``fourbar-run huge.toml`` prints (docs/orchestrator.md): Case 1 to 1e15 s, more rows
    than ``exchange.max_rows``; nothing is run."""
    text = (REPO / "cases" / "case1_normal.toml").read_text(encoding="utf-8")
    text = re.sub(r"(?m)^fmu\s*=.*$", f'fmu = "{fmu.as_posix()}"', text)
    (data / "huge.toml").write_text(re.sub(r"(?m)^stop\s*=.*$", "stop = 1e15", text), encoding="utf-8")
    proc = subprocess.run([str(Path(sys.executable).parent / "fourbar-run"), "huge.toml"], cwd=data,
                          capture_output=True, text=True, timeout=300)
    if proc.returncode != 2:
        raise RuntimeError(f"fourbar-run huge.toml exited {proc.returncode}, not 2:\n{proc.stderr[-2000:]}")
    return proc.stderr.strip()


def monitor_text(exchange: Path) -> str:
    """What ``fourbar-monitor out/case2_fault_L2/exchange.csv`` prints (in-process, same code as the command)."""
    from monitor import cli

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = cli.main([str(exchange), "--no-plots"])
    if code not in (0, 1):
        raise RuntimeError(f"fourbar-monitor {exchange} exited {code}")
    return buffer.getvalue().strip().replace(str(exchange.parent), f"out/{DEMO_CASE}")


def demo_block(data: Path) -> str:
    """``make demo``'s verdict and the first line of its diagnosis (scripts/demo.py as ``make demo``
    runs it, 10x real time: at much higher speeds the run can end before the monitor, still
    importing, looks for it)."""
    out = data / "demo"
    text = printed(REPO, [sys.executable, str(REPO / "scripts" / "demo.py"), "--speedup", "10", "--out", str(out)])
    text = text.replace(str(out), f"out/{DEMO_CASE}")
    start = text.index("== verdict ==")
    end = text.index("\n", text.index("\ndiagnosis: ", start) + 1)
    return text[start:end]


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
        if self.key in MASKED:
            mask = MASKED[self.key]
            return mask.sub("…", self.quoted) == mask.sub("…", self.fresh)
        if self.key.startswith("fmpy_row."):
            a = [float(v) for v in self.quoted.split(",")]
            b = [float(v) for v in self.fresh.split(",")]
            return len(a) == len(b) and all(math.isclose(x, y, rel_tol=ROW_RTOL) for x, y in zip(a, b))
        return self.quoted == self.fresh


def compare(figures: dict[str, str], root: Path = REPO, *, partial: bool = False) -> list[Finding]:
    """Each quote's text against the fresh figures (a quote found in no place is a finding).

    ``partial``: compare only the quotes whose figures are all in ``figures`` (the copied ones)."""
    findings = []
    for quote in QUOTES:
        if partial and not set(quote.keys) <= set(figures):
            continue
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
    """Put the fresh figures into the files (the quotes whose figures are known); returns the files changed."""
    changed = []
    for file in sorted({q.file for q in QUOTES}):
        path = root / file
        text = original = path.read_text(encoding="utf-8")
        for quote in (q for q in QUOTES if q.file == file and set(q.keys) <= set(figures)):
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
    mode.add_argument("--write", action="store_true", help="write the fresh figures into the files "
                      f"(and make demo's history plot into {DEMO_IMAGE}, its animation and live-page "
                      "screenshot into docs/img/case2.gif and docs/img/view.png)")
    mode.add_argument("--quoted", action="store_true",
                      help="print the figures as the files quote them now, as JSON (key: text); exit 1 if a quote "
                           "is not found")
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--copied", action="store_true",
                        help="only the figures copied from generated files and sweep files (no runs; a second)")
    source.add_argument("--figures", type=Path, metavar="FILE",
                        help="the fresh figures from this JSON object (key: text) instead of measuring them")
    parser.add_argument("--data", type=Path, help="folder for the runs (reused when present); default: a temp dir")
    parser.add_argument("--root", type=Path, default=REPO,
                        help="the folder whose README.md and docs/ hold the quotes (default: this repository)")
    args = parser.parse_args(argv)
    if args.quoted:
        return print_quoted(args.root)
    if args.figures:
        figures = json.loads(args.figures.read_text(encoding="utf-8"))
    else:
        with tempfile.TemporaryDirectory(prefix="doc_figures_") as tmp:
            data = args.data or Path(tmp)
            data.mkdir(parents=True, exist_ok=True)
            figures = copied_figures(args.root) if args.copied else all_figures(data)
            if not args.copied:
                if args.write:
                    shutil.copyfile(data / "demo" / "monitor" / "history.png", REPO / DEMO_IMAGE)
                    # the README's animation and live-page screenshot, from the same demo run
                    subprocess.run([sys.executable, str(REPO / "scripts" / "readme_media.py"), str(data / "demo")],
                                   check=True)
    findings = compare(figures, args.root, partial=args.copied)
    if args.write:
        missing = [f for f in findings if f.quoted is None]
        for f in missing:
            print(f"{f.file}: the quote of {f.key} was not found; edit the text or its pattern in "
                  f"benchmarks/doc_figures.py", file=sys.stderr)
        changed = rewrite(figures, args.root)
        print(f"rewrote {', '.join(changed) if changed else 'nothing (all figures current)'}")
        return 1 if missing else 0
    width = max(len(f.key) for f in findings)
    for f in findings:
        mark = "ok   " if f.ok else "STALE"
        quoted = f.quoted if f.quoted is not None else "(not found)"
        print(f"{mark} {f.file:<18} {f.key:<{width}}  quoted {_one_line(quoted)}"
              f"{'' if f.ok else f'  fresh {_one_line(f.fresh)}'}")
    stale = [f for f in findings if not f.ok]
    if args.check:
        print(f"{len(findings) - len(stale)} of {len(findings)} quoted figures current"
              + ("; rewrite with: python benchmarks/doc_figures.py --write" if stale else ""))
        return 1 if stale else 0
    return 0


def print_quoted(root: Path) -> int:
    """``--quoted``: the figures as the files under ``root`` quote them now, as JSON on stdout."""
    findings = compare({key: "" for q in QUOTES for key in q.keys}, root)
    missing = [f for f in findings if f.quoted is None]
    for f in missing:
        print(f"{f.file}: the quote of {f.key} was not found", file=sys.stderr)
    print(json.dumps({f.key: f.quoted for f in findings if f.quoted is not None}, indent=1, ensure_ascii=False))
    return 1 if missing else 0


def _one_line(text: str) -> str:
    return text if "\n" not in text else text.replace("\n", " ⏎ ")


if __name__ == "__main__":
    sys.exit(main())
