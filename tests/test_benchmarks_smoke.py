"""Smoke tests of the scripts ``make benchmarks`` runs, each on its smallest setting: it runs
to the end (exit 0) and prints its table.  The figures themselves are the benchmarks' job.

``make benchmarks`` runs ``benchmarks/run_all.py`` (fmu_speed, native_fmu --sweep,
fmu_accuracy, orchestrator_overhead, monitor_replay, sweep_scaling) and
``benchmarks/doc_figures.py --write`` (tested by tests/test_doc_figures.py).  Not smoke-tested
here, because no small setting of theirs is cheap: ``native_fmu.py`` (its tolerance study
alone takes most of a minute), ``sweep_scaling.py`` (starts Dask clusters cold and warm:
most of a minute even for 2 scenarios on 1 worker) and ``run_all.py`` itself (it runs all
of them at full size).
"""
from __future__ import annotations

import subprocess
import sys

import pytest

from support import REPO


def _bench(script: str, *args: str, timeout: float = 600) -> str:
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / script), *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)
    assert proc.returncode == 0, f"{script} exit {proc.returncode}:\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    assert "Traceback" not in proc.stderr, proc.stderr
    return proc.stdout


def _rows(text: str, first_cell: str) -> list[list[str]]:
    """The markdown table rows whose first cell is ``first_cell``, split into cells."""
    return [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
            if line.startswith("|") and line.strip("|").split("|")[0].strip() == first_cell]


@pytest.mark.slow
def test_monitor_replay_benchmark(native_fmu):
    """It crashed on the CUSUM detector (``'CusumDesign' object has no attribute 'base'``)."""
    out = _bench("monitor_replay.py", "--quick", "--fmu", str(native_fmu))
    speed = _rows(out, "harmonic")
    assert len(speed) == 3, out                      # the speed row and the two detection rows
    detection = speed[1:]
    assert [r[1] for r in detection] == ["none", "σ = 5 mm, 1 seeds"], out
    # Case 2's fault is detected (a latency, not "missed") and the limit column is a number
    for row in detection:
        assert float(row[2]) >= 0.0 and float(row[6]) > 0.0, row


def test_orchestrator_overhead_benchmark(native_fmu):
    out = _bench("orchestrator_overhead.py", "--repeat", "1", "--fmu", str(native_fmu))
    assert "ratio of medians (orchestrator / FMPy): **" in out, out
    assert float(_rows(out, "`run_case` (fourbar-run), incl. exchange.csv + run.json")[0][1]) > 0, out


@pytest.mark.slow
def test_fmu_accuracy_benchmark(native_fmu):
    """Four rows (Cases 1 and 2, two tolerances); at 1e-12 the FMU is within 1e-6 m of the reference."""
    out = _bench("fmu_accuracy.py", "--fmu", str(native_fmu))
    rows = _rows(out, "Case 1") + _rows(out, "Case 2")
    assert len(rows) == 4, out
    tight = [r for r in rows if r[1].startswith("rtol = atol = 1e-12")]
    # a loose bound (the issue-2 target is 1e-6 m): the smoke test checks the script, not the FMU
    assert len(tight) == 2 and all(float(r[2]) < 1e-6 for r in tight), out


@pytest.mark.slow
def test_fmu_speed_benchmark(fourbar_fmu):
    out = _bench("fmu_speed.py", "--repeat", "1", "--fmu", str(fourbar_fmu))
    assert len(_rows(out, "FourBar Case 1")) == 2 and len(_rows(out, "FourBar Case 2")) == 2, out
