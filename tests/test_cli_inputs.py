"""What fourbar-monitor, fourbar-diagnose and fourbar-sweep do with the inputs and signals a
new user tried (issue 23, "Inputs and signals"): each gets one clear line and its exit code,
never a traceback, and nothing already written is lost.

Signals are sent to real subprocesses while they work: Ctrl-C as a terminal sends it (SIGINT
to the command's process group), SIGTERM as ``kill PID`` does.  Exit codes: 130 for Ctrl-C,
143 for SIGTERM (128 + the signal's number, as fourbar-run).
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import pytest

from support import FOURBAR_MONITOR, FOURBAR_RUN, REPO, case_file, unwritable_folder

BIN = Path(sys.executable).parent
FOURBAR_DIAGNOSE = str(BIN / "fourbar-diagnose")
FOURBAR_SWEEP = str(BIN / "fourbar-sweep")
EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}
REASON = {signal.SIGINT: "interrupted by Ctrl-C", signal.SIGTERM: "terminated by SIGTERM"}


def _run_folder(tmp: Path, fmu: Path, name: str, *, case: str = "case2_fault_L2", stop: float = 16.0,
                monitor: bool = True) -> Path:
    """A fourbar-run folder (and its monitor/ outputs, harmonic model, x2) for ``case``."""
    path = case_file(case, fmu, tmp / f"{name}.toml", name=name)
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp / name), "--stop", repr(stop), "--quiet"],
                   check=True, timeout=300)
    if monitor:
        from monitor import replay

        replay(tmp / name / "exchange.csv", out_dir=tmp / name / "monitor", model="harmonic", plots=False)
    return tmp / name


@pytest.fixture(scope="module")
def native_run(tmp_path_factory, native_fmu) -> Path:
    """Case 2 on the native FMU, 16 s, monitored: the fault at 10 s is alarmed at 10.01 s."""
    return _run_folder(tmp_path_factory.mktemp("native"), native_fmu, "case2")


@pytest.fixture(scope="module")
def pythonfmu_run(tmp_path_factory, fourbar_fmu) -> Path:
    """The same run on the pythonfmu FMU (diagnosed with --use-run-fmu: minutes of Python FMU calls)."""
    return _run_folder(tmp_path_factory.mktemp("pythonfmu"), fourbar_fmu, "case2")


def _start(argv: list[str], cwd: Path) -> subprocess.Popen:
    """A command in its own session (process group), as a shell job."""
    return subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def _wait(proc: subprocess.Popen, ready: Callable[[], bool], what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not ready():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the command ended (exit {proc.returncode}) before {what}:\n{out}\n{err}")
        if time.monotonic() > deadline:
            _kill(proc)
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.02)


def _kill(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def _send(proc: subprocess.Popen, signum: int) -> tuple[str, str]:
    """Ctrl-C to the process group (a terminal's), SIGTERM to the process (``kill PID``); the outputs."""
    try:
        if signum == signal.SIGINT:
            os.killpg(proc.pid, signum)
        else:
            os.kill(proc.pid, signum)
        return proc.communicate(timeout=120)
    finally:
        _kill(proc)


def _no_traceback(*texts: str) -> None:
    for text in texts:
        assert "Traceback" not in text and "Error:" not in text.replace("error:", ""), text


# -- fourbar-diagnose --out --------------------------------------------------------------------------

@pytest.mark.slow
def test_diagnose_out_that_cannot_take_the_outputs_is_refused_before_the_diagnosis(pythonfmu_run, tmp_path):
    """--out on a file, under a file, or in a read-only place: exit 2 at once with the path named.

    The pythonfmu run diagnosed with its own FMU takes minutes, so a refusal within the
    60 s timeout shows the check comes before the diagnosis."""
    a_file = tmp_path / "verdict.json"
    a_file.write_text("keep me\n")
    locked = unwritable_folder(tmp_path)
    for out, expected in ((a_file, f"--out {a_file}: exists and is not a folder"),
                          (a_file / "sub", f"--out {a_file / 'sub'}: {a_file} is not a folder"),
                          (locked, f"--out {locked}: cannot write there"),
                          (locked / "diagnosis", f"--out {locked / 'diagnosis'}: cannot create the folder")):
        proc = subprocess.run([FOURBAR_DIAGNOSE, str(pythonfmu_run), "--use-run-fmu", "--out", str(out)],
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert expected in proc.stderr and proc.stdout == "", proc.stderr
        _no_traceback(proc.stderr)
    assert a_file.read_text() == "keep me\n"                       # untouched
    assert not (pythonfmu_run / "diagnosis").exists()


@pytest.mark.slow
def test_diagnose_verdict_is_printed_when_its_files_cannot_be_written(native_run, tmp_path):
    """A file that cannot be written once the diagnosis is done (here: diagnosis.png became a
    folder meanwhile): the verdict is printed, diagnosis.json kept, the failure named, exit 4."""
    out = tmp_path / "diag"
    proc = _start([FOURBAR_DIAGNOSE, str(native_run), "--out", str(out)], tmp_path)
    try:
        _wait(proc, out.is_dir, "the output folder was checked")
        time.sleep(0.3)      # past the check (microseconds); the diagnosis itself takes seconds
        (out / "diagnosis.png").mkdir()
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        _kill(proc)
    assert proc.returncode == 4, stdout + stderr
    assert stdout.startswith("diagnosis: L2 changed 1.000000 → 1.100000 m"), stdout
    assert f"cannot write {out / 'diagnosis.png'}" in stderr and f"written: {out / 'diagnosis.json'}" in stderr
    assert (out / "diagnosis.json").is_file()
    _no_traceback(stderr)


# -- signals during a diagnosis ------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("fmu, signum", [("native", signal.SIGINT), ("native", signal.SIGTERM),
                                         ("pythonfmu", signal.SIGINT), ("pythonfmu", signal.SIGTERM)])
def test_a_signal_stops_a_diagnosis_with_one_line(request, tmp_path, fmu, signum):
    """Mid-diagnosis (the output folder is made just before the long part): exit 130 / 143, one
    line, no traceback, nothing written.  With --use-run-fmu on the pythonfmu FMU the signal
    arrives while the FMU's own Python code runs; raised there it ended in SIGSEGV (exit -11)."""
    run = request.getfixturevalue(f"{fmu}_run")
    out = tmp_path / "diag"
    extra = ["--use-run-fmu"] if fmu == "pythonfmu" else []
    proc = _start([FOURBAR_DIAGNOSE, str(run), "--out", str(out), *extra], tmp_path)
    _wait(proc, out.is_dir, "the diagnosis began")
    # native: the healthy pass and first branches (the whole diagnosis takes ~2 s after this);
    # pythonfmu: inside its minutes of FMU calls
    time.sleep(0.3 if fmu == "native" else 2.0)
    stdout, stderr = _send(proc, signum)
    assert proc.returncode == EXIT[signum], (proc.returncode, stdout, stderr)
    assert stderr.strip().splitlines() == [f"fourbar-diagnose: {REASON[signum]} before the diagnosis was complete; "
                                           "nothing was written"], stderr
    assert stdout == "" and not out.exists()        # the folder made by the check is removed again


@pytest.mark.slow
def test_ctrl_c_in_the_python_api_is_a_keyboardinterrupt_not_a_crash(pythonfmu_run, tmp_path):
    """``diagnose.diagnose`` called from a script (Python's own Ctrl-C handler, no command): Ctrl-C
    during the pythonfmu FMU's calls is raised between two of them, as a KeyboardInterrupt the
    caller may catch; raised inside the FMU it crashed the process (SIGSEGV)."""
    script = tmp_path / "api.py"
    script.write_text("import sys\nfrom diagnose import diagnose\ntry:\n"
                      f"    diagnose({str(pythonfmu_run)!r}, use_run_fmu=True)\n"
                      "except KeyboardInterrupt:\n    print('caught KeyboardInterrupt')\n    sys.exit(7)\n")
    proc = _start([sys.executable, str(script)], tmp_path)
    time.sleep(6.0)          # imports (~2 s), then the healthy pass and branches: minutes of FMU calls
    stdout, stderr = _send(proc, signal.SIGINT)
    assert proc.returncode == 7 and stdout.strip() == "caught KeyboardInterrupt", (proc.returncode, stdout, stderr)


# -- signals during monitoring -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def long_run(tmp_path_factory, native_fmu) -> Path:
    """1200 s of Table 1's healthy swing (native FMU, ~1 s): a replay takes seconds."""
    return _run_folder(tmp_path_factory.mktemp("long"), native_fmu, "case1", case="case1_normal", stop=1200.0,
                       monitor=False)


def _rows(path: Path) -> int:
    return path.read_text().count("\n") - 1 if path.is_file() else 0


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_a_replay_and_says_what_is_kept(long_run, tmp_path, signum):
    out = tmp_path / "monitor"
    (out).mkdir()
    (out / "summary.json").write_text("{}\n")            # an earlier session's: not to be taken for this one's
    proc = _start([FOURBAR_MONITOR, str(long_run / "exchange.csv"), "--model", "harmonic", "--quiet", "--no-plots",
                   "--out", str(out)], tmp_path)
    _wait(proc, lambda: _rows(out / "evaluations.csv") >= 200, "200 evaluations were written")
    stdout, stderr = _send(proc, signum)
    assert proc.returncode == EXIT[signum], (proc.returncode, stdout, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"fourbar-monitor: {REASON[signum]} at t = "), stderr
    assert f"kept events.jsonl, evaluations.csv, forecast.csv in {out} (up to then; no summary.json" in lines[0]
    assert not (out / "summary.json").exists()
    text = (out / "evaluations.csv").read_text()
    assert text.endswith("\n") and 200 <= text.count("\n") - 1 < 11_910     # whole lines; stopped before the end
    _no_traceback(stdout, stderr)


@pytest.mark.slow
def test_sigterm_stops_a_follower_which_writes_its_summary(tmp_path, native_fmu):
    """--follow on a live run (5x real time): SIGTERM ends it like Ctrl-C, summary and verdict written, exit 143."""
    case = case_file("case1_normal", native_fmu, tmp_path / "live.toml", name="live")
    run_dir = tmp_path / "live"
    writer = _start([FOURBAR_RUN, str(case), "--out", str(run_dir), "--stop", "60", "--realtime", "5", "--quiet"],
                    tmp_path)
    try:
        out = run_dir / "monitor"
        proc = _start([FOURBAR_MONITOR, str(run_dir / "exchange.csv"), "--follow", "--model", "harmonic", "--quiet",
                       "--no-plots", "--timeout", "60"], tmp_path)
        _wait(proc, lambda: _rows(out / "evaluations.csv") >= 10, "the follower monitored a second of data")
        stdout, stderr = _send(proc, signal.SIGTERM)
        assert writer.poll() is None                    # the run goes on: only the monitor was stopped
    finally:
        _kill(writer)
    assert proc.returncode == 143, (stdout, stderr)
    assert stdout.strip().splitlines()[-1].startswith("verdict: terminated by SIGTERM; no alarm"), stdout
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["evaluations"] >= 10
    _no_traceback(stdout, stderr)


# -- monitor options -----------------------------------------------------------------------------------

def test_every_shorter_than_the_sample_step_is_refused_naming_the_step(native_run, tmp_path):
    """--every 1e-9 on a 0.01 s grid (ten million evaluations per sample, minutes without
    output): exit 2 once the step is known, nothing written; the step itself is accepted."""
    out = tmp_path / "m"
    proc = subprocess.run([FOURBAR_MONITOR, str(native_run / "exchange.csv"), "--model", "harmonic", "--every",
                           "1e-9", "--out", str(out), "--no-plots"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "every (--every) = 1e-09 s is shorter than the data's sample step 0.01 s; expected every ≥ 0.01 s" \
        in proc.stderr
    assert not out.exists()
    _no_traceback(proc.stderr)
    from monitor import replay

    fine = replay(native_run / "exchange.csv", model="harmonic", every=0.01, plots=False).summary
    coarse = replay(native_run / "exchange.csv", model="harmonic", every=0.1, plots=False).summary
    assert fine.evaluations == 10 * coarse.evaluations > 0       # the same span, ten times the cadence


def test_an_option_of_the_other_detector_is_refused_everywhere(native_run, tmp_path):
    """--window with the CUSUM, --false-alarm-rate with MAE: one rule for the command line, the
    Python API and sweep files (defaults given explicitly stay accepted)."""
    from monitor import MonitorOptions, OptionError, replay
    from monitor.options import detector_options
    from sweep import SweepError, load_sweep

    exchange = str(native_run / "exchange.csv")
    for argv, name in ((["--window", "0.3"], "window"), (["--persistence", "3"], "persistence"),
                       (["--detector", "mae", "--false-alarm-rate", "0.1"], "false_alarm_rate"),
                       (["--detector", "mae", "--guard", "1"], "guard")):
        proc = subprocess.run([FOURBAR_MONITOR, exchange, "--model", "harmonic", "--out", str(tmp_path / "m"), *argv],
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2 and f"  {name}: " in proc.stderr and "is an option of detector" in proc.stderr, \
            proc.stderr
        assert not (tmp_path / "m").exists()
        _no_traceback(proc.stderr)
    with pytest.raises(OptionError, match=r"window: 0.3 is an option of detector mae only; detector cusum"):
        replay(exchange, window=0.3)
    MonitorOptions(detector="cusum", window=0.5, threshold="auto").validated()      # the defaults, spelled out
    MonitorOptions(detector="mae", window=0.3, threshold=0.01).validated()
    sweep = tmp_path / "s.toml"
    case = REPO / "cases" / "case1_normal.toml"
    for table, key in (("window = 0.3", "monitor.window = 0.3"), ('threshold = [0.01, "auto"]', "monitor.threshold"),
                       ('detector = "mae"\nclear_after = 5.0', "monitor.clear_after = 5.0")):
        sweep.write_text(f'case = "{case}"\nstop = 12.0\n[fault]\nvariable = "L2"\nvalue = [1.05]\ntime = 10.0\n'
                         f'[monitor]\nmodel = "harmonic"\n{table}\n')
        with pytest.raises(SweepError, match=f"{key}.*is an option of detector"):
            load_sweep(sweep)
    for shipped in sorted((REPO / "sweeps").glob("*.toml")):      # every shipped sweep file still loads
        if shipped.name.startswith("motor_fourbar"):   # on the bench's .ssp: tests/test_sweep_system.py, which builds it
            continue
        load_sweep(shipped)
    # the one table: each detector's own options are disjoint, and every help text that says
    # "cusum:" or "mae:" belongs to an option tagged with that detector
    assert not set(detector_options("cusum")) & set(detector_options("mae"))
    from dataclasses import fields

    from monitor.detectors import detector_class, detector_names

    owner = {f.name: None for f in fields(MonitorOptions)}
    for name in detector_names():
        owner.update({f.name: name for f in fields(detector_class(name).Settings)})
    helps = {f.name: f.metadata.get("help", "") for f in fields(MonitorOptions)}
    for name in detector_names():
        helps.update({f.name: f.metadata["help"] for f in fields(detector_class(name).Settings)})
    for field_name, help_text in helps.items():
        if field_name == "detector":          # its help describes every detector
            continue
        prefix = help_text.split(":")[0]
        if prefix in detector_names():
            assert owner[field_name] == prefix, field_name


# -- fourbar-sweep -------------------------------------------------------------------------------------

def test_sweep_out_that_is_a_file_is_refused(tmp_path, capsys):
    from sweep.cli import main

    a_file = tmp_path / "results"
    a_file.write_text("keep me\n")
    smoke = str(REPO / "sweeps" / "smoke.toml")
    for argv, expected in (([smoke, "--out", str(a_file), "--quiet"], f"--out {a_file}: exists and is not a folder"),
                           ([smoke, "--out", str(a_file), "--dry-run"], f"--out {a_file}: exists and is not a folder"),
                           ([smoke, "--out", str(a_file / "x"), "--quiet"], f"--out {a_file / 'x'}: {a_file} is not a "
                                                                            "folder")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert expected in err, err
        _no_traceback(err)
    assert a_file.read_text() == "keep me\n"


@pytest.mark.slow
def test_sigterm_stops_a_sweep_and_keeps_its_rows(tmp_path):
    """SIGTERM to fourbar-sweep while Dask runs: the finished rows are kept and said, exit 143."""
    out = tmp_path / "sweep"
    csv = out / "results.csv"
    proc = _start([FOURBAR_SWEEP, str(REPO / "sweeps" / "smoke.toml"), "--workers", "1", "--out", str(out),
                   "--quiet"], tmp_path)
    _wait(proc, lambda: _rows(csv) >= 1, "a scenario finished", timeout=300)
    stdout, stderr = _send(proc, signal.SIGTERM)
    assert proc.returncode == 143, (stdout, stderr)
    assert "smoke: terminated by SIGTERM: " in stderr and "run the same command again to resume" in stderr, stderr
    import pandas as pd

    kept = pd.read_parquet(out / "results.parquet")
    assert 1 <= len(kept) < 8 and (out / "summary.json").is_file()
    assert "Traceback" not in stderr, stderr


# ------------------------------------------------------------------ a reader that stops early

def _piped_into_head(argv: list[str], cwd: Path) -> tuple[int, str]:
    """``argv | head -1``: the first line is read, then the reader goes away; (exit code, stderr)."""
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = proc.stdout.readline()
    proc.stdout.close()                      # as head does after its line
    _, err = proc.communicate(timeout=300)
    assert first, f"{argv[0]} printed nothing"
    return proc.returncode, err


@pytest.mark.slow
def test_output_piped_into_head_neither_fails_nor_loses_the_files(native_run, tmp_path):
    """`fourbar-monitor ... | head -1` exited 2 with 'error: : Broken pipe' and wrote no outputs;
    `fourbar-diagnose ... | head -1` ended in a BrokenPipeError traceback."""
    folder = tmp_path / "run"
    shutil.copytree(native_run, folder)
    shutil.rmtree(folder / "monitor")
    code, err = _piped_into_head([FOURBAR_MONITOR, "exchange.csv", "--model", "harmonic"], folder)
    _no_traceback(err)
    # the verdict's code (1: Case 2's fault is alarmed), and every output written
    assert code == 1 and "Broken pipe" not in err, (code, err)
    assert {p.name for p in (folder / "monitor").iterdir()} >= {"summary.json", "evaluations.csv", "events.jsonl"}
    code, err = _piped_into_head([FOURBAR_DIAGNOSE, "."], folder)
    _no_traceback(err)
    assert code == 0 and (folder / "diagnosis" / "diagnosis.json").is_file(), (code, err)
