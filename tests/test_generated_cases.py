"""Generated configurations, end to end: property-based tests (hypothesis) over what a user
can write in a case file -- geometries (Grashof or not), start angles and rates (swings and
full rotations), which parameters the file names, the fault's parameter, size and time, on
and off the output grid -- and over invalid case files and damaged exchange files.

The rules that make a configuration live in ``fmu_src/fourbar_configurations.py`` (one home:
``benchmarks/robustness.py`` draws its seeded sample with the same rules); here hypothesis
supplies the numbers (:class:`Drawn`).  Every example runs the real CLIs on the native FMU
as subprocesses, and each property asserts what a user sees: exit codes, messages, files.

A generated case either works or exits with a clear message:

- works: no false alarm before the fault, an alarm within ``DETECTION_BOUND`` after it, and
  ``fourbar-diagnose`` names the changed parameter (noise-free; with noise on x2 alone it gives
  a verdict, and benchmarks/robustness.py measures how often it is right);
- a motion that reaches a fold fails part-way: exit 1, the FMU's reason, rows kept;
- an off-grid fault time, a wrong type, a missing or unknown key, a negative length, a loop
  that cannot close, bad TOML: exit 2 naming the file and the field, nothing written;
- never a Python traceback.

Reproducible: ``derandomize=True`` (the examples are the same on every run; hypothesis
derives them from the test's source, so editing a test draws other examples), no example
database, no shrinking (a failing end-to-end example would be re-run dozens of times; the
example is reported as drawn, with its case file, through ``note``).  About a minute of CPU
for the whole file (2 cores, native FMU); the larger sample is benchmarks/robustness.py.
"""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, Phase, given, note, reject, settings
from hypothesis import strategies as st
from support import BIN, REPO

from fmu_src import fourbar_configurations as C

FOURBAR_RUN = str(BIN / "fourbar-run")
FOURBAR_MONITOR = str(BIN / "fourbar-monitor")
FOURBAR_DIAGNOSE = str(BIN / "fourbar-diagnose")
STEP = 0.01                      # s, the generated cases' communication step

#: The documented bound of "an alarm after the fault": within 5 s.  The faults generated here
#: (lengths 2-5 %, masses 20-40 %, g 5-10 %, noise <= 5 mm on x2) are 2-4x the sizes that
#: docs/detection.md measured within 2.7 s on Table 1; 5 s leaves room for other geometries.
DETECTION_BOUND = 5.0
TEST_SIZES = {"length": (0.02, 0.05), "mass": (0.2, 0.4), "g": (0.05, 0.1)}
#: Fault times: after the 0-9 s training and the phase tracker's 3 s guard.
FAULT_TIMES = (15.0, 30.0)
AFTER_FAULT = 12.0               # s of run after the fault: the bound plus the diagnosis' 3 s horizon and slack
NOISE = (0.003, 0.005)           # m, σ on x2 when a case is noisy


def examples(n: int):
    """Settings of every property here: n examples, the same ones on every run."""
    return settings(max_examples=n, deadline=None, derandomize=True, database=None,
                    phases=(Phase.explicit, Phase.generate),
                    suppress_health_check=(HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much, HealthCheck.function_scoped_fixture))


@pytest.fixture(autouse=True)
def _same_examples_in_every_process(monkeypatch):
    """The examples must not depend on what else ran in the process.

    Hypothesis (6.13x on) sometimes draws a number it found as a literal in the project's
    modules loaded so far, so under xdist the "same" derandomized examples changed with the
    tests that had run before on the worker: a clean clone's `make test` drew m4 = 1.37 kg
    where this file alone draws 2 kg, and that other case broke the 5 s bound.  No such
    constants here (a private hook of Hypothesis: left alone when a version lacks it)."""
    try:
        from hypothesis.internal.conjecture import providers
    except ImportError:                             # pragma: no cover - another Hypothesis layout
        return
    if not (hasattr(providers, "_get_local_constants") and hasattr(providers, "Constants")):
        return                                      # pragma: no cover
    cache = getattr(getattr(providers, "CONSTANTS_CACHE", None), "cache", None)
    if cache is not None:
        cache.clear()                               # allowed constants already cached with local ones
    monkeypatch.setattr(providers, "_get_local_constants", lambda: providers.Constants())
    yield
    if cache is not None:
        cache.clear()


class Drawn:
    """A ``fourbar_configurations.Source`` drawing from hypothesis (``draw`` of a composite strategy)."""

    def __init__(self, draw):
        self.draw = draw

    def uniform(self, low: float, high: float) -> float:
        return self.draw(st.floats(low, high, allow_nan=False, allow_infinity=False))

    def choice(self, options):
        return self.draw(st.sampled_from(list(options)))

    def integer(self, low: int, high: int) -> int:
        return self.draw(st.integers(low, high))


@dataclass(frozen=True)
class Generated:
    """A generated case: the configuration, the fault (or none) and the noise on x2."""

    config: C.Configuration
    fault: C.Fault | None = None
    noise: float = 0.0               # m, σ on x2
    seed: int = 1

    def __repr__(self) -> str:       # what hypothesis prints for a falsifying example
        fault = "no fault" if self.fault is None else (
            f"{self.fault.variable} {self.fault.before:.6g} -> {self.fault.value:.6g} ({self.fault.relative:+.2%}) "
            f"at {self.fault.time:g} s")
        return f"<{self.config.describe()}; {fault}; noise {self.noise * 1000:g} mm (seed {self.seed})>"

    def text(self, fmu: Path, stop: float, **kw) -> str:
        return C.case_text(self.config, fmu, stop=stop, fault=self.fault, noise_std=self.noise,
                           noise_seed=self.seed, **kw)


@st.composite
def configurations(draw, families=C.FAMILIES) -> C.Configuration:
    """A steady configuration of one of ``families``; an example whose numbers meet no rule
    within 60 tries (hypothesis' simplest examples: every number at a bound) is rejected."""
    src = Drawn(draw)
    try:
        return C.draw_configuration(src, src.choice(families), attempts=60)
    except RuntimeError:
        reject()


@st.composite
def generated_cases(draw, *, fault: bool, families=C.FAMILIES) -> Generated:
    """A configuration, a safe fault (``fault``) in TEST_SIZES at a grid time in FAULT_TIMES,
    noise-free or σ in NOISE on x2."""
    config = draw(configurations(families))
    src = Drawn(draw)
    step = None
    if fault:
        step = C.draw_fault(src, config, sizes=TEST_SIZES, time_range=FAULT_TIMES, step=STEP)
        if step is None:
            reject()
    noise = src.choice((0.0, round(src.uniform(*NOISE), 6)))
    return Generated(config, step, noise, src.integer(0, 10**6))


@st.composite
def locking_configurations(draw) -> C.Configuration:
    try:
        return C.draw_locking(Drawn(draw), attempts=60)
    except RuntimeError:
        reject()


@dataclass(frozen=True)
class Cli:
    """One CLI call: its exit code and its output."""

    argv: tuple[str, ...]
    code: int
    stdout: str
    stderr: str

    def __str__(self) -> str:
        return f"{' '.join(self.argv)} -> exit {self.code}\nstdout: {self.stdout[-1500:]}\nstderr: {self.stderr[-3000:]}"


def cli(*argv) -> Cli:
    proc = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=300)
    result = Cli(tuple(str(a) for a in argv), proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr, f"a traceback: {result}"
    # a message shows numbers as a user writes them, not as Python objects
    assert not re.search(r"np\.\w+\(", proc.stderr + proc.stdout), f"a Python repr in a message: {result}"
    return result


def write_case(folder: Path, text: str, name: str = "case") -> Path:
    path = folder / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    note(f"case file {path}:\n{text}")
    return path


# ------------------------------------------------------------------ the generator is the FMU's

def _crossing_times(t: np.ndarray, x: np.ndarray, level: float) -> np.ndarray:
    """Times where x rises through level (linear interpolation between samples)."""
    i = np.flatnonzero((x[:-1] < level) & (x[1:] >= level))
    return t[i] + (level - x[i]) / (x[i + 1] - x[i]) * (t[i + 1] - t[i])


@examples(6)
@given(config=configurations())
def test_the_generated_motion_is_the_fmus(config, tmp_path_factory, native_fmu):
    """The family (swing or rotation), period and swing range predicted by fourbar_configurations.analyse
    are the FMU's: the labels the other properties rely on are right."""
    from orchestrator import load_case, run_case

    stop = C.on_grid(4 * config.motion.period + 1.0, STEP)
    folder = tmp_path_factory.mktemp("motion")
    case = write_case(folder, C.case_text(config, native_fmu, stop=stop, outputs=("x2", "theta2")))
    result = run_case(load_case(case), folder / "run")
    assert result.ok, result.error
    rows = np.loadtxt(result.exchange_path, delimiter=",", skiprows=1)
    t, theta = rows[:, 0], np.unwrap(rows[:, 2])
    if config.kind == "rotating":
        turns = (theta - theta[0]) * math.copysign(1.0, config.values["omega2_start"]) / (2 * math.pi)
        assert turns[-1] > 3.0, f"predicted a rotation, the crank turned {turns[-1]:.2f} times"
        ticks = _crossing_times(t, turns, 1.0), _crossing_times(t, turns, 2.0), _crossing_times(t, turns, 3.0)
        measured = float(np.mean(np.diff([tick[0] for tick in ticks])))
    else:
        low, high = config.motion.theta_low, config.motion.theta_high
        # the turning points to 0.01 rad: the samples every 0.01 s miss the exact extremum by
        # at most omega*dt ~ 0 there (the crank is at rest), plus the bisection's 1e-12 rad
        assert abs(theta.max() - high) < 0.01 and abs(theta.min() - low) < 0.01, (theta.min(), theta.max(), low, high)
        measured = float(np.mean(np.diff(_crossing_times(t, theta, 0.5 * (low + high)))))
    # 1 %: the prediction is a 64-point quadrature (swing) or a 0.25-degree sum (rotation) of
    # the same equations, and the crossings are interpolated between 0.01 s samples; the two
    # agreed to 1 ms on 1-4 s periods when this was written
    assert measured == pytest.approx(config.motion.period, rel=0.01)


# ---------------------------------------------------------------------------- working cases

@dataclass(frozen=True)
class EndToEnd:
    run: Cli
    monitor: Cli
    summary: dict
    diagnose: Cli | None
    diagnosis: dict | None


def end_to_end(folder: Path, case: Path, *, diagnose: bool) -> EndToEnd:
    """fourbar-run, fourbar-monitor (harmonic model: the model is not the point here) and,
    after an alarm, fourbar-diagnose -- as a user types them."""
    out = folder / "run"
    run = cli(FOURBAR_RUN, case, "--out", out, "--quiet")
    assert run.code == 0, f"the run failed: {run}"
    monitor = cli(FOURBAR_MONITOR, out / "exchange.csv", "--model", "harmonic", "--no-plots", "--quiet")
    assert monitor.code in (0, 1), f"the monitor failed: {monitor}"
    summary = json.loads((out / "monitor" / "summary.json").read_text())
    if not diagnose or monitor.code != 1:
        return EndToEnd(run, monitor, summary, None, None)
    diag = cli(FOURBAR_DIAGNOSE, out, "--no-plot", "--quiet")
    path = out / "diagnosis" / "diagnosis.json"
    return EndToEnd(run, monitor, summary, diag, json.loads(path.read_text()) if path.exists() else None)


def names_the_fault(diagnosis: dict, variable: str) -> bool:
    """The diagnosis names ``variable``; or it says the data cannot tell two parameters
    apart and ``variable`` is the other one (with x2 alone and noise, two masses can explain
    the same change equally well: docs/diagnose.md, identifiability)."""
    best = diagnosis["best"]["parameter"]
    if best == variable:
        return True
    runner_up = next((f["parameter"] for f in diagnosis["ranking"] if f["parameter"] != best), None)
    return runner_up == variable and "cannot tell these two apart" in diagnosis["message"]


@pytest.mark.slow
@examples(4)
@given(case=generated_cases(fault=True))
def test_a_generated_fault_is_detected_in_time_and_named(case, tmp_path_factory, native_fmu):
    fault = case.fault
    folder = tmp_path_factory.mktemp("fault")
    path = write_case(folder, case.text(native_fmu, C.on_grid(fault.time + AFTER_FAULT, STEP)))
    e = end_to_end(folder, path, diagnose=True)
    s = e.summary
    assert s["fault_time"] == pytest.approx(fault.time, abs=1e-9), "the monitor did not read the fault time"
    assert s["false_alarms_before_fault"] == 0, f"false alarm at {s['alarm_times']}: {e.monitor}"
    assert e.monitor.code == 1 and s["detection_latency_s"] is not None, f"no alarm after the fault: {e.monitor}"
    assert s["detection_latency_s"] <= DETECTION_BOUND, f"alarm {s['detection_latency_s']} s after the fault"
    assert e.diagnose.code in (0, 1) and e.diagnosis is not None, f"no diagnosis: {e.diagnose}"
    if case.noise == 0:
        # Noise-free, one parameter explains the data exactly: the diagnosis must name it.  With
        # noise on x2 alone it misses a share of the benchmark's noisy runs ("right parameter"
        # in docs/robustness.md), so a noisy example asks only for a verdict with its message.
        assert e.diagnose.code == 0 and names_the_fault(e.diagnosis, fault.variable), e.diagnosis["message"]


@pytest.mark.slow
@examples(4)
@given(case=generated_cases(fault=False))
def test_a_generated_healthy_case_never_alarms(case, tmp_path_factory, native_fmu):
    """Any steady motion, 240 s, noise-free or 3-5 mm on x2: no alarm at the default setting."""
    folder = tmp_path_factory.mktemp("healthy")
    e = end_to_end(folder, write_case(folder, case.text(native_fmu, 240.0)), diagnose=False)
    assert e.monitor.code == 0 and not e.summary["alarm_times"], (
        f"false alarm(s) at {e.summary['alarm_times']} s on a healthy run: {e.monitor}")


# --------------------------------------------------------------------------- failing cases

@pytest.mark.slow
@examples(3)
@given(config=locking_configurations())
def test_a_generated_case_that_reaches_a_fold_swings_through_it(config, tmp_path_factory, native_fmu):
    """A motion that reaches a fold of the crank angle (coupler and rocker in line: theta2
    cannot go on) passes it: coordinate partitioning changes its independent coordinate there
    and the crank swings back.  (Until mechanisms became data the FMUs integrated theta2 with a
    closed-form loop closure, which cannot pass a fold, and such a run failed there.)  On the
    physical path: constraint residual at round-off (1e-10: coordinates of a few metres), energy
    conserved to 1e-5 J (the FMU's rtol = atol = 1e-10 over 30 s on energies of ~200 J: 1.9e-6 J
    measured; an integrator that stalls at the fold loses tens of joules: 35 J seen), and theta2
    turning back without a full turn."""
    note(config.motion.reason)
    folder = tmp_path_factory.mktemp("fold")
    outputs = ["x2", "y2", "theta2", "energy", "constraint_residual"]
    case = write_case(folder, C.case_text(config, native_fmu, stop=30.0, outputs=outputs))
    run = cli(FOURBAR_RUN, case, "--out", folder / "run", "--quiet")
    assert run.code == 0, run
    record = json.loads((folder / "run" / "run.json").read_text())
    data = pd.read_csv(folder / "run" / "exchange.csv")
    assert record["status"] == "finished" and len(data) == 3001, (record, len(data))
    assert data["constraint_residual"].max() <= 1e-10
    assert (data["energy"] - data["energy"].iloc[0]).abs().max() <= 1e-5
    theta = data["theta2"].to_numpy()
    assert np.ptp(theta) < 2 * np.pi and np.any(np.diff(np.sign(np.diff(theta))) != 0)


# ------------------------------------------------------------------------ invalid case files

def _edit(text: str, table: str, key: str, value: str | None) -> str:
    """``key = ...`` inside ``[table]`` (``""``: the top level, ``"events"``: the first
    ``[[events]]``) replaced by ``key = value``, removed (None), or added when absent."""
    lines = text.splitlines()
    current, start, end = "", 0 if table == "" else None, None
    for i, line in enumerate(lines):
        header = re.fullmatch(r"\[\[?([\w.]+)\]\]?", line.strip())
        if header:
            if current == table and start is not None and end is None:
                end = i
            current = header.group(1)
            if current == table and start is None:
                start = i + 1
    if start is None:
        lines += ["", f"[[{table}]]" if table == "events" else f"[{table}]"]
        start = len(lines)
    end = len(lines) if end is None else end
    for i in range(start, end):
        if re.match(rf"{re.escape(key)}\s*=", lines[i]):
            if value is None:
                del lines[i]
            else:
                lines[i] = f"{key} = {value}"
            return "\n".join(lines) + "\n"
    assert value is not None, f"{table}.{key} is not in the case"
    lines.insert(start, f"{key} = {value}")
    return "\n".join(lines) + "\n"


#: Stands for the FMU's path in a generated invalid case (the FMU is a fixture).
FMU_PLACEHOLDER = "@FMU@"


@dataclass(frozen=True)
class Invalid:
    """An invalid case file: what is wrong (``kind``), what the message must name (``field``)
    and say (``why``)."""

    kind: str
    field: str
    why: str
    text: str

    def __repr__(self) -> str:
        return f"<{self.kind}: {self.field}>"

    def case_text(self, fmu: Path) -> str:
        return self.text.replace(json.dumps(FMU_PLACEHOLDER), json.dumps(str(fmu)))


def _label(table: str, key: str) -> str:
    return key if table == "" else f"events[0].{key}" if table == "events" else f"{table}.{key}"


@st.composite
def invalid_cases(draw) -> Invalid:
    """A valid generated case (four lengths named, a step fault), then one thing made wrong."""
    src = Drawn(draw)
    case = draw(generated_cases(fault=True))
    config = C.with_names(case.config, ("L1", "L2", "L3", "L4"))
    text = C.case_text(config, FMU_PLACEHOLDER, stop=40.0, fault=case.fault)
    kind = src.choice(("bad_toml", "wrong_type", "missing", "unknown", "negative_length", "unassemblable",
                       "off_grid"))
    if kind == "bad_toml":
        return Invalid(kind, "not valid TOML", "line", text.replace("[experiment]", "[experiment", 1))
    if kind == "wrong_type":
        table, key = src.choice((("experiment", "stop"), ("experiment", "step"), ("parameters", "L2"),
                                 ("events", "time"), ("events", "value")))
        bad = src.choice(('"abc"', "true", "[1.0]"))
        return Invalid(kind, _label(table, key), "expected", _edit(text, table, key, bad))
    if kind == "missing":
        table, key = src.choice((("", "fmu"), ("experiment", "stop"), ("experiment", "step"),
                                 ("events", "variable"), ("events", "time"), ("events", "type")))
        return Invalid(kind, _label(table, key), "missing", _edit(text, table, key, None))
    if kind == "unknown":
        table, key = src.choice((("", "fmu_path"), ("experiment", "stpo"), ("events", "tiem"),
                                 ("parameters", "L5"), ("noise", "sigma")))
        base = _edit(text, "noise", "seed", "1") if table == "noise" else text
        return Invalid(kind, _label(table, key), "", _edit(base, table, key, "1.0"))
    if kind == "negative_length":
        name = src.choice(C.LENGTHS)
        value = repr(-src.uniform(0.0, 5.0))
        return Invalid(kind, f"parameters.{name}", "> 0", _edit(text, "parameters", name, value))
    if kind == "unassemblable":
        try:
            bad = C.draw_unassemblable(src, attempts=60)
        except RuntimeError:
            reject()
        return Invalid(kind, "parameters", "the loop cannot be closed",
                       C.case_text(bad, FMU_PLACEHOLDER, stop=40.0))
    t = C.off_grid_time(src, *FAULT_TIMES, STEP)
    return Invalid(kind, "events[0].time", "not on the communication grid",
                   C.case_text(config, FMU_PLACEHOLDER, stop=40.0, fault=case.fault, fault_time=t))


@pytest.mark.slow
@examples(10)
@given(bad=invalid_cases())
def test_a_generated_invalid_case_exits_2_naming_what_to_fix(bad, tmp_path_factory, native_fmu):
    folder = tmp_path_factory.mktemp("invalid")
    case = write_case(folder, bad.case_text(native_fmu))
    run = cli(FOURBAR_RUN, case, "--out", folder / "run", "--quiet")
    assert run.code == 2, run
    assert f"{case.name}: {bad.field}" in run.stderr or (bad.field in run.stderr and case.name in run.stderr), run
    assert bad.why in run.stderr, run
    assert "nothing was run or written" in run.stderr and not (folder / "run").exists(), run


# --------------------------------------------------------------------- damaged exchange files

@pytest.fixture(scope="module")
def healthy_exchange(tmp_path_factory, native_fmu) -> Path:
    """A 20 s noise-free exchange file of a generated swing (not Table 1)."""
    config = C.draw_configuration(C.RandomSource(1), "other_swing")
    folder = tmp_path_factory.mktemp("exchange")
    case = folder / "case.toml"
    case.write_text(C.case_text(config, native_fmu, stop=20.0))
    assert cli(FOURBAR_RUN, case, "--out", folder / "run", "--quiet").code == 0
    return folder / "run" / "exchange.csv"


#: The damages and what docs/monitor.md ("Robustness") says a replay does with each:
#: "error" = exit 2 naming the file; "skip" = the row is skipped with a warning naming the
#: file and line (exit 2 only if too little is left to learn from, with a message).
DAMAGES = {"empty": "error", "header_only": "error", "no_time_column": "error", "training_gone": "error",
           "truncated_row": "skip", "non_numeric": "skip", "decreasing_time": "skip", "blank_line": "skip"}


@dataclass(frozen=True)
class Damage:
    """What is done to an exchange file: ``kind`` (DAMAGES) at the data row ``where`` (a
    fraction of the file), with a kind's detail (a cut fraction, a text, a time shift)."""

    kind: str
    where: float
    detail: object = None

    def apply(self, lines: list[str]) -> tuple[list[str], int]:
        """The damaged lines and the 1-based line number of the damaged row."""
        lines = list(lines)
        k = 1 + int(self.where * (len(lines) - 2))          # a data row (lines[0] is the header)
        if self.kind == "empty":
            lines = []
        elif self.kind == "header_only":
            lines = lines[:1]
        elif self.kind == "no_time_column":
            lines[0] = lines[0].replace("time", str(self.detail), 1)
        elif self.kind == "training_gone":
            lines = lines[:1] + [row for row in lines[1:] if float(row.split(",")[0]) > 9.5]
        elif self.kind == "truncated_row":                  # cut short: fewer fields than the header
            fields = lines[k].rstrip("\n").split(",")
            kept = ",".join(fields)[: max(1, int(self.detail * (len(",".join(fields)) - 1)))]
            if kept.count(",") >= len(fields) - 1:
                kept = kept.rsplit(",", 1)[0]
            lines[k] = kept + "\n"
        elif self.kind == "non_numeric":                    # in the time or the monitored column
            column, text = self.detail
            fields = lines[k].rstrip("\n").split(",")
            fields[column] = text
            lines[k] = ",".join(fields) + "\n"
        elif self.kind == "decreasing_time":
            fields = lines[k].split(",")
            fields[0] = repr(float(fields[0]) - float(self.detail))
            lines[k] = ",".join(fields)
        elif self.kind == "blank_line":
            lines.insert(k, "\n")
        return lines, k + 1


@st.composite
def damages(draw) -> Damage:
    kind = draw(st.sampled_from(sorted(DAMAGES)))
    detail = {"no_time_column": st.sampled_from(("t", "Time", "seconds")),
              "truncated_row": st.floats(0.05, 0.95),
              "non_numeric": st.tuples(st.sampled_from((0, 1)), st.sampled_from(("abc", "1.2.3", "--", ""))),
              "decreasing_time": st.sampled_from((0.05, 0.5, 5.0))}.get(kind, st.none())
    return Damage(kind, draw(st.floats(0.05, 0.95)), draw(detail))


@pytest.mark.slow
@examples(8)
@given(damage=damages())
def test_a_damaged_exchange_file_gives_a_message_never_a_traceback(damage, healthy_exchange, tmp_path_factory):
    lines, line_no = damage.apply(healthy_exchange.read_text().splitlines(keepends=True))
    folder = tmp_path_factory.mktemp("damaged")
    path = folder / "exchange.csv"
    path.write_text("".join(lines), encoding="utf-8")
    note(f"damaged line {line_no}: {lines[line_no - 1] if 0 < line_no <= len(lines) else ''!r}")
    monitor = cli(FOURBAR_MONITOR, path, "--model", "harmonic", "--no-plots", "--quiet")
    if DAMAGES[damage.kind] == "error" or monitor.code == 2:
        assert monitor.code == 2 and "error:" in monitor.stderr and "exchange.csv" in monitor.stderr, monitor
        if DAMAGES[damage.kind] == "skip":   # too little left to learn from: the message says what
            assert "training window" in monitor.stderr or "samples" in monitor.stderr, monitor
        return
    # A healthy run: the skipped row raises no alarm.  Where the skipped row leaves a hole in the
    # time grid inside the windows the monitor judges, it says so and exits 5 (indeterminate),
    # never "0, no alarm" (issue 36); otherwise 0.
    assert monitor.code in (0, 5), monitor
    if monitor.code == 5:
        assert "INDETERMINATE" in monitor.stdout + monitor.stderr, monitor
    assert re.search(rf"exchange\.csv line {line_no}\b", monitor.stderr), monitor


# ------------------------------------------------------------------ the robustness benchmark

@pytest.mark.slow
def test_the_robustness_benchmark_runs_on_its_quick_setting(tmp_path):
    """One Dask worker (``--workers 1``; by default one per core): the suite's own workers keep
    the cores busy, and a second worker process cost its start-up and imports again for the
    quick setting's few scenarios (36.4 s of CPU with two, 28.6 s with one, the same rows)."""
    page = tmp_path / "robustness.md"
    run = cli(sys.executable, REPO / "benchmarks" / "robustness.py", "--quick", "--workers", "1", "--out",
              tmp_path / "cache", "--write", page)
    assert run.code == 0, run
    text = page.read_text()
    for family in C.FAMILIES:
        assert re.search(rf"^\| {family} \| none \| 1 \|", text, re.M), text
    # a second call finds every row in the cache and runs nothing
    again = cli(sys.executable, REPO / "benchmarks" / "robustness.py", "--quick", "--workers", "1", "--out",
                tmp_path / "cache", "--write", page)
    assert again.code == 0 and "0 to run now" in again.stderr, again
