"""Smoke tests of the scripts ``make benchmarks`` runs, each on its smallest setting: it runs
to the end (exit 0, no traceback), prints its tables with the expected rows, and leaves no
process behind.  The figures themselves are the benchmarks' job.

``make benchmarks`` runs ``benchmarks/run_all.py`` (fmu_speed, native_fmu --sweep,
fmu_accuracy, orchestrator_overhead, monitor_replay, sweep_scaling, view_load, startup) and
``benchmarks/doc_figures.py --write`` (tested by tests/test_doc_figures.py).  Every one of
those scripts is smoke-tested here (``native_fmu.py`` and ``sweep_scaling.py`` with their
``--quick`` setting; native_fmu's ``--sweep`` part, which runs ``fourbar-sweep`` on a toml of
the repository, is not); ``run_all.py`` itself is not, because it runs all of them at full size.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import time

import psutil                  # a dependency of dask.distributed
import pytest

from support import REPO


def _session(sid: int) -> list[psutil.Process]:
    """The processes still alive in session ``sid`` (a benchmark's own, see ``_bench``)."""
    left = []
    for proc in psutil.process_iter():
        try:
            if os.getsid(proc.pid) == sid and proc.status() != psutil.STATUS_ZOMBIE:
                left.append(proc)
        except (OSError, psutil.Error):          # gone meanwhile, or not ours to ask
            pass
    return left


def _bench(script: str, *args: str, timeout: float = 600) -> str:
    """Run ``benchmarks/<script>`` in a session of its own; check exit 0, no traceback, and that
    nothing it started (Dask workers, a compiled driver) outlives it."""
    # files, not pipes: a process left behind holding a pipe would keep the test waiting
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, str(REPO / "benchmarks" / script), *args], cwd=REPO, text=True,
                                stdout=out, stderr=err, start_new_session=True)
        try:
            proc.wait(timeout=timeout)
        finally:
            if proc.poll() is None:              # timed out (or the test was interrupted)
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    # multiprocessing's resource tracker leaves when its pipe closes, shortly after the
    # script: 10 s of grace is ample on a loaded machine
    deadline = time.monotonic() + 10.0
    while (left := _session(proc.pid)) and time.monotonic() < deadline:
        time.sleep(0.2)
    names = []
    for p in left:                               # do not leave them to the next test either
        try:
            names.append(" ".join(p.cmdline()[:4]))
            p.kill()
        except psutil.Error:
            pass
    assert not left, f"{script} left processes behind: {names}"
    assert proc.returncode == 0, f"{script} exit {proc.returncode}:\n{stdout[-2000:]}\n{stderr[-4000:]}"
    assert "Traceback" not in stderr, stderr
    return stdout


def _rows(text: str, first_cell: str) -> list[list[str]]:
    """The markdown table rows whose first cell is ``first_cell``, split into cells."""
    return [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
            if line.startswith("|") and line.strip("|").split("|")[0].strip() == first_cell]


def _section(text: str, heading: str) -> str:
    """The part of ``text`` under the markdown heading ``### heading``, up to the next one."""
    match = re.search(rf"^### {re.escape(heading)}\n(.*?)(?=^### |\Z)", text, re.M | re.S)
    assert match, f"no section '### {heading}' in:\n{text}"
    return match.group(1)


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
    """Four rows (Cases 1 and 2, two tolerances); at 1e-12 the FMU is within 1e-6 m of the reference.
    ``--quick``: 12 s runs, Case 2's step at 10 s included (the 100 s accuracy of both FMUs against
    the same reference is asserted by test_fmu_physics.py)."""
    out = _bench("fmu_accuracy.py", "--quick", "--fmu", str(native_fmu))
    rows = _rows(out, "Case 1") + _rows(out, "Case 2")
    assert len(rows) == 4, out
    tight = [r for r in rows if r[1].startswith("rtol = atol = 1e-12")]
    # a loose bound (the issue-2 target is 1e-6 m): the smoke test checks the script, not the FMU
    assert len(tight) == 2 and all(float(r[2]) < 1e-6 for r in tight), out


@pytest.mark.slow
def test_fmu_speed_benchmark(fourbar_fmu):
    """``--quick``: 12 s runs (Case 2's L2 step at 10 s included, so the in-process model and its
    replay go through the parameter change), one round: every run and table of the full size,
    whose 100 s runs are 8x this (252 s of the suite's wall under load, before --quick)."""
    out = _bench("fmu_speed.py", "--quick", "--fmu", str(fourbar_fmu))
    assert "| run (12 s, step 0.01 s, rtol 1e-9, atol 1e-6) |" in out, out
    assert len(_rows(out, "FourBar Case 1")) == 2 and len(_rows(out, "FourBar Case 2")) == 2, out
    for row in _rows(out, "FourBar Case 1") + _rows(out, "FourBar Case 2"):
        # seconds, ratios and RHS evaluations per simulated second: all measured, all positive
        assert all(float(c.rstrip("x")) > 0 for c in row[1:]), row


@pytest.mark.slow
def test_native_fmu_benchmark(native_fmu, fourbar_fmu):
    """``--quick``: all four tables (FMPy speed, C model in-process, accuracy per wall second,
    agreement of the two FMUs), one round, 12 s runs (``QUICK_STOP``: Case 2's step at 10 s
    included, so the C model's restart and the FMUs' agreement through the step are gone through)."""
    out = _bench("native_fmu.py", "--quick", "--native", str(native_fmu), "--fmu", str(fourbar_fmu))
    fmpy = _section(out, "Through FMPy (simulate_fmu)")
    assert "| run (12 s, step 0.01 s," in fmpy, fmpy
    for case in ("Case 1", "Case 2"):
        (row,) = _rows(fmpy, case)
        # native, pythonfmu and floor seconds, then the two ratios
        assert all(float(c) > 0 for c in row[1:4]) and all(float(c.rstrip("x")) > 0 for c in row[4:6]), row

    c_model = _section(out, "The C model in-process")
    rows = _rows(c_model, "Case 1") + _rows(c_model, "Case 2")
    assert sorted(r[1] for r in rows) == ["1e-9, 1e-6 (Table 1)"] * 2 + ["2e-10, 2e-10"] * 2, c_model
    for row in rows:
        # total ms, RHS evaluations, µs per evaluation; Case 2's step at 10 s restarts the integrator once
        assert float(row[2]) > 0 and int(row[3].replace(",", "")) > 0 and float(row[5]) > 0, row
        assert row[4] == ("1" if row[0] == "Case 1" else "2"), row

    accuracy = _section(out, "Accuracy per wall second")
    for fmu in ("native", "pythonfmu"):
        (row,) = _rows(accuracy, fmu)
        # found within the quick search (1e-8, 1e-9), within the 1e-6 m it searched for, timed
        assert row[1] in ("1e-08", "1e-09") and float(row[2]) <= 1e-6 and float(row[3]) > 0, row
        assert row[4] == "not comparable (12 s run)", row      # Exudyn's 38 s is for 100 s
    agreement = _rows(accuracy, "Case 1") + _rows(accuracy, "Case 2")
    assert sorted(r[1] for r in agreement) == ["1e-12"] * 2 + ["Table 1 (1e-9, 1e-6)"] * 2, accuracy
    for row in agreement:
        if row[1] == "1e-12":
            # at rtol = atol = 1e-12 the two FMUs integrate the same equations with the same
            # method and agree to round-off (~5e-13 m measured); 1e-6 m is the issue-2 accuracy
            # target, loose on purpose: the smoke test checks the script, not the FMUs
            assert all(float(c) < 1e-6 for c in row[2:5]), row
        else:
            # at Table 1's atol = 1e-6 they differ by ~1e-3 m (the script's note): only a
            # finite figure below the mechanism's own size (links of 1-4 m) is checked
            assert all(0 <= float(c) < 1.0 for c in row[2:5]), row


def test_native_fmu_benchmark_refuses_wrong_vanderpol3(native_fmu, fourbar_fmu, tmp_path):
    """``--vanderpol3`` takes VanDerPol's FMI 3.0 build only: an FMI 2.0 FMU (the native FMU) or a
    missing file is refused up front, exit 2, with a message naming the option and the path."""
    base = [sys.executable, str(REPO / "benchmarks" / "native_fmu.py"), "--quick", "--native", str(native_fmu),
            "--fmu", str(fourbar_fmu)]
    env = {k: v for k, v in os.environ.items() if k not in ("FOURBAR_VANDERPOL", "FOURBAR_VANDERPOL3")}
    missing = tmp_path / "VanDerPol3.fmu"
    for path, why in ((native_fmu, "an FMI 2.0 FMU, not FMI 3.0"), (missing, "no such file")):
        proc = subprocess.run([*base, "--vanderpol3", str(path)], cwd=REPO, env=env, capture_output=True,
                              text=True, timeout=120)
        assert proc.returncode == 2, (proc.returncode, proc.stdout[-2000:], proc.stderr[-2000:])
        assert f"error: --vanderpol3 {path}: {why}" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
        assert "build_vanderpol.sh --fmi 3" in proc.stderr, proc.stderr     # says how to build the right one
    # the environment variable is read the same way as the option
    proc = subprocess.run(base, cwd=REPO, env={**env, "FOURBAR_VANDERPOL3": str(missing)}, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and f"error: --vanderpol3 {missing}: no such file" in proc.stderr, proc.stderr


def _table(section: str) -> tuple[list[str], list[list[str]]]:
    """The header cells and the body rows (cells) of the one markdown table in ``section``."""
    lines = [line for line in section.splitlines() if line.startswith("|")]
    split = [[c.strip() for c in line.strip("|").split("|")] for line in lines]
    return split[0], split[2:]


@pytest.mark.slow
def test_native_fmu_benchmark_vanderpol3(native_fmu, fourbar_fmu):
    """``--quick --vanderpol3 $FOURBAR_VANDERPOL3``: the FMI 3.0 co-simulation table gains
    VanDerPol FMI 3.0's seconds and the native FMU's ratio to them (labelled informative), and the
    FMI 3.0 Model Exchange table VanDerPol FMI 3.0's Model Exchange seconds.  Skipped without that
    FMU (benchmarks/native/build_vanderpol.sh --fmi 3 SRC_DIR PATH builds it)."""
    vanderpol3 = os.environ.get("FOURBAR_VANDERPOL3")
    if not vanderpol3:
        pytest.skip("FOURBAR_VANDERPOL3 not set (benchmarks/native/build_vanderpol.sh --fmi 3 SRC_DIR PATH)")
    out = _bench("native_fmu.py", "--quick", "--native", str(native_fmu), "--fmu", str(fourbar_fmu),
                 "--vanderpol3", vanderpol3)
    ratio_head = "FMI 3.0 / VanDerPol FMI 3.0 (informative, not a target)"
    head, rows = _table(_section(out, "Every mechanism in FMI 3.0 co-simulation"))
    assert "VanDerPol FMI 3.0 s" in head and ratio_head in head, head
    (row,) = rows
    fmi3, vdp3 = float(row[head.index("FMI 3.0 s")]), float(row[head.index("VanDerPol FMI 3.0 s")])
    ratio = float(row[head.index(ratio_head)].rstrip("x"))
    assert fmi3 > 0 and vdp3 > 0, row
    # one round: the ratio is FMI 3.0 s / VanDerPol FMI 3.0 s before both were rounded to 3
    # decimals (each off by <= 5e-4 s) and it to 2 (<= 5e-3): the bound of that rounding
    slack = 5e-4 * (1 + fmi3 / vdp3) / (vdp3 - 5e-4) + 5e-3
    assert abs(ratio - fmi3 / vdp3) <= slack, (row, slack)

    head, rows = _table(_section(out, "Every mechanism in FMI 3.0 Model Exchange (FMPy's CVode)"))
    assert "VanDerPol FMI 3.0 ME s" in head and "ME / VanDerPol ME" in head, head
    assert [r[0] for r in rows] == ["fourbar", "fourbar"], rows          # default and tight CVode rtol
    vdp = {r[head.index("VanDerPol FMI 3.0 ME s")] for r in rows}
    assert len(vdp) == 1 and float(vdp.pop()) > 0, rows                  # measured once, for both rows


@pytest.mark.slow
def test_sweep_scaling_benchmark(native_fmu):
    """``--quick``: 2 scenarios of 12 s on 1 worker, one warm cluster and one cold
    ``run_sweep``; the clusters are closed (``_bench`` checks no process is left).  Measured on
    2 cores busy with another benchmark (load average 4-5): 15-18 s wall, ~10 s of CPU."""
    out = _bench("sweep_scaling.py", "--quick", "--fmu", str(native_fmu))
    assert "### Sweep throughput (2 scenarios: L2 step, stop 12 s, harmonic model" in out, out
    (row,) = _rows(out, "1")
    assert _rows(out, "2") == [], out                # one worker count only
    warm = re.fullmatch(r"([\d.]+) \(([\d.]+)-([\d.]+)\)", row[1])
    assert warm and float(warm[1]) > 0, row          # scenarios/min, median (min-max) of one run
    # speed-ups against the only (base) worker count are 1 by construction; cold rate, task
    # wall and CPU seconds are positive
    assert row[2] == row[4] == "1.00" and all(float(c) > 0 for c in (row[3], row[5], row[6])), row


def test_view_load_benchmark(tmp_path):
    """``--quick``: 60 s of run written at 20x real time while fourbar-view and a headless
    Chromium page follow it; the table's figures are read back and must be plausible."""
    from view.headless import chromium_path

    if chromium_path() is None:
        pytest.skip("no Chromium: `make browser` installs it (make test does)")
    out = _bench("view_load.py", "--quick", "--out", str(tmp_path))
    (memory,) = _rows(out, "server resident memory (MB)")
    (held,) = _rows(out, "rows held by the page's plots")
    # a Panel server is ~100-300 MB resident; the page holds at most the recent window
    # (20 s at 100 Hz, signal and forecast: 2,001 rows each), the statistic's (10 Hz: 201) and
    # the 1,500 bins, one more when the run's end starts a bin
    assert 50 < float(memory[3]) < 1000, memory
    assert 0 < int(held[3].replace(",", "")) <= 2 * 2001 + 201 + 1501, held
    latency = re.search(r"median (\d+) ms, 95th percentile (\d+) ms, largest (\d+) ms", out)
    assert latency and int(latency[1]) < 5000, out       # drawn within seconds, not never
    assert "Page errors: 0." in out, out


@pytest.mark.slow
def test_startup_benchmark(native_fmu):
    """``--quick``: every command once as a new process; each row of the table is there, with
    a CPU time, and the two rows with a target say whether each time met it."""
    out = _bench("startup.py", "--quick", "--fmu", str(native_fmu))
    labels = ["python -c pass", "fourbar-monitor --help", "harmonic replay of Case 2",
              "harmonic replay of Case 2, `--no-plots`", "Prophet replay of Case 2",
              *(f"fourbar-{name} --help" for name in ("run", "diagnose", "view", "sweep"))]
    for label in labels:
        (row,) = _rows(out, label)
        assert float(row[3]) > 0, row                    # CPU s, median
    for label, target in (("fourbar-monitor --help", "<= 0.5"), ("harmonic replay of Case 2", "<= 2")):
        (row,) = _rows(out, label)
        assert row[5] == target and re.fullmatch(r"(yes|\*\*no\*\*) / (yes|\*\*no\*\*)", row[6]), row


def test_native_fmu_forces_refuses_without_vanderpol(native_fmu, fourbar_fmu, tmp_path):
    """``--forces`` measures against VanDerPol only: without ``--vanderpol`` it stops up front (exit
    2, saying how to build it); ``--write`` without ``--forces`` is a usage error; a page without
    the section's marker lines is refused before anything runs, and left as it was."""
    base = [sys.executable, str(REPO / "benchmarks" / "native_fmu.py"), "--native", str(native_fmu),
            "--fmu", str(fourbar_fmu)]
    env = {k: v for k, v in os.environ.items() if k not in ("FOURBAR_VANDERPOL", "FOURBAR_VANDERPOL3")}
    proc = subprocess.run([*base, "--forces"], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--forces needs --vanderpol PATH" in proc.stderr, proc.stderr
    assert "build_vanderpol.sh" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    page = tmp_path / "page.md"
    page.write_text("no markers here\n", encoding="utf-8")
    proc = subprocess.run([*base, "--write", str(page)], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and "--write goes with --forces" in proc.stderr, proc.stderr
    proc = subprocess.run([*base, "--forces", "--vanderpol", str(native_fmu), "--write", str(page)], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "not the Reference-FMUs' VanDerPol" in proc.stderr, proc.stderr
    assert page.read_text(encoding="utf-8") == "no markers here\n"


@pytest.mark.slow
def test_native_fmu_forces_table(native_fmu, fourbar_fmu, tmp_path):
    """``--forces --quick --repeat 1 --vanderpol $FOURBAR_VANDERPOL --write PAGE``: the press's two
    rows (default and Table 1 tolerances) with a ratio to VanDerPol, Andrews' squeezer's two rows
    with its steps, written between the marker lines and nowhere else.  Skipped without that FMU
    (benchmarks/native/build_vanderpol.sh SRC_DIR PATH builds it)."""
    vanderpol = os.environ.get("FOURBAR_VANDERPOL")
    if not vanderpol:
        pytest.skip("FOURBAR_VANDERPOL not set (benchmarks/native/build_vanderpol.sh SRC_DIR PATH)")
    # the section's marker lines, as the page docs/benchmarks.md has them (tests do not import benchmarks/)
    markers = [line for line in (REPO / "docs" / "benchmarks.md").read_text(encoding="utf-8").splitlines()
               if line.startswith(("<!-- BEGIN", "<!-- END")) and "native_fmu.py --forces" in line]
    FORCES_BEGIN, FORCES_END = markers

    page = tmp_path / "page.md"
    page.write_text(f"before\n{FORCES_BEGIN}\nold\n{FORCES_END}\nafter\n", encoding="utf-8")
    _bench("native_fmu.py", "--forces", "--quick", "--repeat", "1", "--vanderpol", vanderpol, "--native",
           str(native_fmu), "--fmu", str(fourbar_fmu), "--write", str(page))
    text = page.read_text(encoding="utf-8")
    assert text.startswith(f"before\n{FORCES_BEGIN}\n") and text.endswith(f"{FORCES_END}\nafter\n"), text
    assert "\nold\n" not in text
    press = _rows(text, "fourbar_press")
    assert [r[1] for r in press] == ["1e-10, 1e-10 (default)", "1e-9, 1e-6 (Table 1)"], press
    for row in press:
        assert float(row[2]) > 0 and float(row[3]) > 0 and re.fullmatch(r"[\d.]+x \((met|\*\*not met\*\*)\)", row[4])
    andrews = _rows(text, "andrews_squeezer")
    assert len(andrews) == 2, andrews
    for row in andrews:
        # native evaluations and the in-process model's: the same integrator, within a few attempts
        native, steps, python = (int(c.replace(",", "")) for c in row[4:7])
        assert steps > 0 and abs(native - python) <= 5 * 12, row


def test_coupling_error_benchmark(bench_ssp):
    """A 12.8 ms span at three macro steps: the benchmark runs the four masters and the monolithic
    reference on the bench and prints both tables with an observed order for every master."""
    out = _bench("coupling_error.py", "--ssp", str(bench_ssp), "--stop", "0.0128", "--steps", "0.4", "0.8", "1.6")
    orders = re.findall(r"^\| observed order.*$", out, re.M)
    assert len(orders) == 2, out                          # fourbar.omega2's table and motor.current's
    for row in orders:
        values = [float(v) for v in re.findall(r"\*\*(-?[0-9.]+)\*\*", row)]
        assert len(values) == 4 and all(v == v for v in values), row     # four masters, each a number
