"""Sweep files, scenario plans and scoring -- no cluster, no FMU run (fast).

Covers: every problem of a malformed sweep file reported at once with its key (library and
CLI, exit 2); the plan of sweeps/smoke.toml (8 scenarios, stable ids, canonical duplicates
removed); reproducible random sampling on the communication grid; the detection figures
of :func:`sweep.score` on hand-made evaluations; the headline rule of the summary; and an
exact round trip of the results CSV, including a torn last line.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from sweep import SweepError, load_sweep, plan_scenarios, score
from sweep.cli import main
from sweep.results import COLUMNS, ResultsStore, table_from_rows
from support import REPO, case_file




def write_sweep(tmp_path: Path, fmu: Path, body: str, name: str = "s.toml") -> Path:
    case = case_file("case1_normal", fmu, tmp_path)
    path = tmp_path / name
    path.write_text(f'case = "{case}"\n' + body)
    return path


def smoke(tmp_path: Path, fmu: Path) -> Path:
    """sweeps/smoke.toml with its base case pointing at the FMU under test."""
    case = case_file("case1_normal", fmu, tmp_path)
    text = (REPO / "sweeps" / "smoke.toml").read_text()
    text = text.replace('case = "../cases/case1_normal.toml"', f'case = "{case}"')
    path = tmp_path / "smoke.toml"
    path.write_text(text)
    return path


MALFORMED = """
stop = 20.005
colour = "red"
[fault]
variable = "L7"
kind = ["step", "jump"]
relative = [0.0, 0.01]
time = [5.0, 10.005]
[noise]
std = -1.0
seed = 1.5
[monitor]
model = "arima"
threshold = [0, "auto"]
window = -1
persistance = 2
"""


def test_malformed_sweep_reports_every_problem_with_its_key(tmp_path, fourbar_fmu):
    path = write_sweep(tmp_path, fourbar_fmu, MALFORMED)
    with pytest.raises(SweepError) as info:
        load_sweep(path)
    text = str(info.value)
    expected = ["colour: unknown key", "stop = 20.005", "fault.variable = \"L7\"", "fault.kind[1] = \"jump\"",
                "fault.relative[0] = 0.0", "fault.time[0] = 5.0", "fault.time[1] = 10.005",
                "noise.std = -1.0", "noise.seed = 1.5", "monitor.model = \"arima\"", "monitor.threshold[0] = 0",
                "monitor.window = -1", "did you mean 'persistence'"]
    for fragment in expected:
        assert fragment in text, f"{fragment!r} not reported:\n{text}"
    assert len(info.value.problems) == len(expected)
    assert all(line.startswith(f"  {path}: ") for line in text.splitlines()[1:])


def test_cli_exit_2_names_the_key_without_traceback(tmp_path, fourbar_fmu, capsys):
    path = write_sweep(tmp_path, fourbar_fmu, '[fault]\nvariable = "L2"\nrelative = 0.01\ntime = 10.0\n'
                                              '[monitor]\nthreshold = "high"\n')
    assert main([str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert 'monitor.threshold = "high"' in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, fragment", [
    (["--workers", "0"], "--workers"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
])
def test_cli_usage_errors_exit_2(tmp_path, fourbar_fmu, capsys, argv, fragment):
    path = smoke(tmp_path, fourbar_fmu)
    assert main([str(path), *argv]) == 2
    assert fragment in capsys.readouterr().err


def test_missing_sweep_file_and_bad_toml(tmp_path, capsys):
    assert main([str(tmp_path / "none.toml")]) == 2
    assert "sweep file not found" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("case = \n")
    with pytest.raises(SweepError, match="not valid TOML"):
        load_sweep(bad)


def test_smoke_plan_has_8_stable_canonical_scenarios(tmp_path, fourbar_fmu):
    path = smoke(tmp_path, fourbar_fmu)
    plan = plan_scenarios(load_sweep(path))
    assert len(plan) == 8
    assert [s.index for s in plan] == list(range(8))
    assert len({s.id for s in plan}) == 8
    assert sum(not s.has_fault for s in plan) == 2
    for s in plan:
        if s.noise_std == 0:
            assert s.noise_seed is None           # noise-free runs do not depend on the seed
        if not s.has_fault:
            assert s.fault_time is None and s.fault_value is None and s.kind == "none"
    again = plan_scenarios(load_sweep(path))
    assert [s.id for s in again] == [s.id for s in plan]
    # the id is a function of the inputs: another noise seed changes only the noisy scenarios
    other = tmp_path / "other.toml"
    other.write_text(path.read_text().replace("seed = 1", "seed = 2"))
    changed = {s.id for s in plan_scenarios(load_sweep(other))} ^ {s.id for s in plan}
    assert len(changed) == 2 * 4                  # 4 noisy scenarios out, 4 in


def test_sampling_is_reproducible_and_on_the_grid(tmp_path, fourbar_fmu):
    body = """stop = 20.0
[fault]
variable = "L2"
kind = ["step", "ramp"]
relative = {min = 0.002, max = 0.1, scale = "log"}
time = {min = 10.0, max = 12.0}
ramp_duration = 2.0
no_fault = true
[noise]
std = [0.0, 0.005]
seed = {min = 0, max = 1000}
[monitor]
model = "harmonic"
[sample]
n = 5
seed = 3
"""
    path = write_sweep(tmp_path, fourbar_fmu, body)
    sweep = load_sweep(path)
    plan = plan_scenarios(sweep)
    assert plan == plan_scenarios(load_sweep(path))
    faults = [s for s in plan if s.has_fault]
    assert len(faults) == 2 * 5 * 2               # kinds x draws x noise levels
    for s in faults:
        assert 0.002 <= s.relative_change <= 0.1
        assert 10.0 <= s.fault_time <= 12.0
        assert sweep.case.experiment.index(s.fault_time) is not None
        assert (s.ramp_duration == 2.0) == (s.kind == "ramp")
    reseeded = tmp_path / "reseeded.toml"
    reseeded.write_text(path.read_text().replace("seed = 3", "seed = 4"))
    assert {s.id for s in plan_scenarios(load_sweep(reseeded))}.isdisjoint(s.id for s in faults)


def test_variable_axis_changes_one_parameter_per_scenario_and_shares_the_fault_free_runs(tmp_path, fourbar_fmu):
    body = """stop = 20.0
[fault]
variable = ["L1", "m3", "g"]
relative = [0.01, 0.1]
time = 10.0
no_fault = true
[noise]
std = [0.0, 0.005]
[monitor]
model = "harmonic"
"""
    path = write_sweep(tmp_path, fourbar_fmu, body)
    plan = plan_scenarios(load_sweep(path))
    faults = [s for s in plan if s.has_fault]
    assert len(faults) == 3 * 2 * 2                # variables x sizes x noise levels
    assert len(plan) - len(faults) == 2            # one fault-free run per noise level, not per variable
    base = {"L1": 3.0, "m3": 1.0, "g": 9.81}       # Table 1 (cases/case1_normal.toml)
    for s in faults:
        assert s.base_value == pytest.approx(base[s.variable], rel=1e-12)
        assert s.fault_value == pytest.approx(base[s.variable] * (1 + s.relative_change), rel=1e-12)
    assert all(s.variable is None and s.base_value is None for s in plan if not s.has_fault)
    # several variables with absolute values, and a name given twice, are reported
    bad = write_sweep(tmp_path, fourbar_fmu, '[fault]\nvariable = ["L2", "L3", "L2"]\nvalue = 1.1\ntime = 10.0\n',
                      name="bad.toml")
    with pytest.raises(SweepError) as info:
        load_sweep(bad)
    text = str(info.value)
    assert 'fault.variable[2] = "L2": named twice' in text
    assert "fault.value = 1.1: expected fault.relative" not in text   # reported once the names are valid
    bad.write_text(bad.read_text().replace('["L2", "L3", "L2"]', '["L2", "L3"]'))
    with pytest.raises(SweepError, match="expected fault.relative when fault.variable names several"):
        load_sweep(bad)


def test_range_without_sample_table_is_reported(tmp_path, fourbar_fmu):
    path = write_sweep(tmp_path, fourbar_fmu, '[fault]\nvariable = "L2"\nrelative = {min = 0.01, max = 0.1}\n'
                                              'time = 10.0\n')
    with pytest.raises(SweepError, match=r"sample: missing.*fault.relative is a range"):
        load_sweep(path)


def test_score_definitions():
    # evaluations every 0.1 s; threshold 1; fault at 10.0 s; persistence 2
    t = [9.8, 9.9, 10.0, 10.1, 10.2, 10.3, 10.4]
    mae = [0.5, 3.0, 0.5, 0.5, 2.0, 4.0, 5.0]
    thr = [1.0] * len(t)
    s = score(t, mae, thr, alarm_times=[9.6, 10.3], fault_time=10.0, persistence=2)
    assert s["false_alarms"] == 1 and s["alarms"] == 2
    assert s["detected"] and s["detection_time"] == 10.3
    assert s["latency"] == pytest.approx(0.3, abs=1e-12)
    assert s["statistic_max_pre"] == 3.0 and s["statistic_mean_pre"] == pytest.approx(4.0 / 3)
    assert s["statistic_max_post"] == 5.0
    assert s["score_pre"] == 0.5                  # no two consecutive pre-fault windows above 0.5
    assert s["score_post"] == 4.0                 # min(4, 5) over the last pair
    clean = score(t, mae, thr, alarm_times=[10.3], fault_time=None, persistence=1)
    assert clean["false_alarms"] == 1 and clean["detected"] is False and clean["latency"] is None
    assert clean["score_pre"] == 5.0 and clean["score_post"] is None


def _row(i, rel, std, latency, false_alarms=0, has_fault=True, variable="L2"):
    detected = latency is not None
    return {"scenario_id": f"s{i}", "index": i, "variable": variable if has_fault else None, "kind": "step" if has_fault else "none",
            "relative_change": rel, "noise_std": std, "model": "harmonic", "threshold": "auto",
            "has_fault": has_fault, "status": "ok", "detected": detected if has_fault else False,
            "latency": latency, "false_alarms": false_alarms, "alarms": false_alarms + detected,
            "score_pre": 0.1, "score_post": 3.0 if detected else 0.5, "fault_time": 10.0 if has_fault else None}


def test_headline_is_the_smallest_size_from_which_every_run_is_good():
    from sweep.report import summarize

    rows = [_row(0, 0.002, 0.0, None), _row(1, 0.005, 0.0, 1.5), _row(2, 0.01, 0.0, 2.5),
            _row(3, 0.02, 0.0, 0.6), _row(4, 0.05, 0.0, 0.3), _row(5, 0.0, 0.0, None, has_fault=False),
            _row(6, 0.05, 0.005, 0.4, false_alarms=1), _row(7, 0.1, 0.005, 0.3)]
    summary = summarize(table_from_rows(rows), 2.0, unit="m")
    series = {g["noise_std"]: g for g in summary["series"]}
    # 0.5 % is good but 1 % takes 2.5 s: reliable only from 2 % up
    assert series[0.0]["smallest_reliable_change"] == 0.02
    assert series[0.0]["no_fault"] == {"n": 1, "runs_with_alarms": 0, "alarms": 0}
    assert series[0.005]["smallest_reliable_change"] == 0.1     # 5 % had a false alarm
    assert series[0.005]["series"].startswith("noise σ = 5 mm")


def test_headline_per_variable_judges_each_with_the_shared_fault_free_runs():
    from sweep.report import summarize

    rows = [_row(0, 0.01, 0.0, 0.5, variable="L1"), _row(1, 0.02, 0.0, 0.4, variable="L1"),
            _row(2, 0.01, 0.0, 3.0, variable="m2"), _row(3, 0.02, 0.0, 1.0, variable="m2"),
            _row(4, 0.0, 0.0, None, has_fault=False, false_alarms=1)]
    summary = summarize(table_from_rows(rows), 2.0, unit="m")
    assert summary["variable"] is None and summary["variables"] == ["L1", "m2"]
    series = {g["variable"]: g for g in summary["series"]}
    assert series["L1"]["smallest_reliable_change"] == 0.01
    assert series["m2"]["smallest_reliable_change"] == 0.02      # +1 % of m2 took 3 s
    assert series["L1"]["series"].startswith("L1, no noise")
    for g in series.values():                                     # the one fault-free run counts for both
        assert g["no_fault"] == {"n": 1, "runs_with_alarms": 1, "alarms": 1}


def test_results_csv_round_trip_is_exact(tmp_path):
    rows = [{"scenario_id": "a", "index": 0, "relative_change": 0.1 + 0.2, "latency": 1 / 3, "detected": True,
             "false_alarms": 0, "error": None, "noise_seed": None, "status": "ok"},
            {"scenario_id": "b", "index": 1, "relative_change": 9.0, "latency": None, "detected": None,
             "false_alarms": None, "error": 'run failed: "quoted", with commas\nand a newline', "noise_seed": 7,
             "status": "failed"}]
    store = ResultsStore(tmp_path)
    store.rewrite(rows[:1])
    store.append(rows[1])
    store.close()
    with open(store.csv_path, "a") as fh:         # a row torn by a kill: no newline at the end
        fh.write("c,2,L2,step,0.1")
    back = store.load()
    assert len(back) == 2
    assert back[0]["relative_change"] == 0.1 + 0.2 and back[0]["latency"] == 1 / 3
    assert back[1]["error"] == rows[1]["error"] and back[1]["detected"] is None and back[1]["noise_seed"] == 7
    import pandas.testing as pdt

    pdt.assert_frame_equal(table_from_rows(back), table_from_rows(rows))
    assert list(table_from_rows(back).columns) == list(COLUMNS)
    assert math.isnan(table_from_rows(back)["latency"][1])


def test_dry_run_counts_without_running(tmp_path, fourbar_fmu, capsys):
    path = smoke(tmp_path, fourbar_fmu)
    assert main([str(path), "--dry-run", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "8 scenarios (6 step, 2 none); 0 already in" in out and "8 to run" in out
    assert not (tmp_path / "out").exists()


def test_a_directory_in_use_by_a_live_sweep_is_refused(tmp_path, fourbar_fmu):
    from sweep import ResultsError, run_sweep

    from fourbar_common.folder_lock import FolderLock

    out = tmp_path / "out"
    out.mkdir()
    held = FolderLock(out, "fourbar-sweep").acquire()      # a flock on its own open file: a second writer
    with pytest.raises(ResultsError, match=r"another fourbar-sweep \(pid"):
        run_sweep(smoke(tmp_path, fourbar_fmu), out)
    held.release()
    (out / ".lock").write_text("999999999")                 # a pid, no flock (a dead process's lock): taken over
    result = run_sweep(smoke(tmp_path, fourbar_fmu), out, limit=0)
    assert result.ran == 0 and (out / ".lock").read_text() == ""   # released


def test_a_sweep_file_can_name_the_native_fmu(tmp_path, fourbar_fmu, native_fmu):
    path = smoke(tmp_path, fourbar_fmu)
    path.write_text(f'fmu = "{native_fmu}"\n' + path.read_text())
    sweep = load_sweep(path)
    assert sweep.case.fmu == native_fmu.resolve()
    from fmpy import read_model_description
    assert sweep.fmu_guid == read_model_description(str(native_fmu)).guid
    bad = smoke(tmp_path, fourbar_fmu)
    bad.write_text('fmu = "missing.fmu"\n' + bad.read_text())
    with pytest.raises(SweepError, match="missing.fmu.*file not found"):
        load_sweep(bad)


# -- bounded work (issue 36): what benchmarks/fuzz_inputs.py found in `fourbar-sweep --dry-run` ------------

#: A guard against a hang of the CLI on a FIFO or a device, not a speed target (a refusal takes ~2 s).
HANG_GUARD = 60.0
FAULT = '[fault]\nvariable = "L2"\nrelative = 0.01\ntime = 10.0\n'


def test_a_sweep_of_too_many_scenarios_is_refused_before_planning(tmp_path, fourbar_fmu):
    """A grid of 1000 x 1000 x 1000 or 10**9 draws is refused at load, naming the count, instead of
    being planned for hours (the old dry run was still planning the grid after 30 s)."""
    from sweep.config import MAX_SCENARIOS

    arrays = ('[fault]\nvariable = "L2"\ntime = 10.0\nno_fault = true\nrelative = [' +
              ", ".join(f"{0.001 * (i + 1):.3f}" for i in range(999)) + "]\n[noise]\nstd = [" +
              ", ".join(f"{1e-5 * i:.5f}" for i in range(1000)) + "]\nseed = [" +
              ", ".join(str(i) for i in range(1000)) + "]\n")
    with pytest.raises(SweepError, match=r"plans 1,000,000,000 scenarios \(999,000,000 grid points with a fault "
                                         r"and 1,000,000 without"):
        load_sweep(write_sweep(tmp_path, fourbar_fmu, arrays, "grid.toml"))
    draws = FAULT + "[noise]\nstd = { min = 0.0, max = 0.01 }\n[sample]\nn = 1000000000\nseed = 1\n"
    with pytest.raises(SweepError, match=r"plans 1,000,000,000 scenarios .* 1,000,000,000 draw\(s\) of \[sample\]"):
        load_sweep(write_sweep(tmp_path, fourbar_fmu, draws, "draws.toml"))
    # the bound itself is allowed: 1000 sizes x 1000 draws
    at_bound = ('[fault]\nvariable = "L2"\ntime = 10.0\nrelative = [' +
                ", ".join(f"{0.001 * (i + 1):.3f}" for i in range(1000)) + "]\n[noise]\nstd = { min = 0.0, max = 0.01 }"
                f"\n[sample]\nn = {MAX_SCENARIOS // 1000}\nseed = 1\n")
    assert load_sweep(write_sweep(tmp_path, fourbar_fmu, at_bound, "bound.toml")).sample.n == 1000


def test_seeds_beyond_64_bits_are_refused_and_the_largest_is_drawn_exactly(tmp_path, fourbar_fmu):
    for body, key in ((FAULT + "[noise]\nstd = 0.001\nseed = 18446744073709551616\n", "noise.seed"),
                      (FAULT + "[noise]\nstd = { min = 0.0, max = 0.01 }\n[sample]\nn = 2\n"
                               "seed = 99999999999999999999999\n", "sample.seed")):
        with pytest.raises(SweepError, match=rf"{key} = \d+: expected an integer <= 2\*\*63 - 1"):
            load_sweep(write_sweep(tmp_path, fourbar_fmu, body))
    # a seed axis sampled up to 2**63 - 1: the bound is kept as an integer (its float is 2**63, which
    # numpy refuses as the top of an int64 draw)
    top = FAULT + "[noise]\nstd = 0.001\nseed = { min = 9223372036854775800, max = 9223372036854775807 }\n" \
                  "[sample]\nn = 50\nseed = 3\n"
    seeds = {s.noise_seed for s in plan_scenarios(load_sweep(write_sweep(tmp_path, fourbar_fmu, top)))}
    assert seeds and all(9223372036854775800 <= s <= 2 ** 63 - 1 for s in seeds)


def test_a_stop_longer_than_the_case_may_run_is_refused(tmp_path, fourbar_fmu):
    """The sweep's stop gets the case's own check (exchange.max_rows: 10,000,000 rows by default)."""
    with pytest.raises(SweepError, match=r"stop = 10000000.0: experiment: .* would write 1,000,000,001 rows"):
        load_sweep(write_sweep(tmp_path, fourbar_fmu, "stop = 1e7\n" + FAULT))
    # the base case's events are dropped, so a stop before them is still fine (case 2's fault is at 10 s)
    case = case_file("case2_fault_L2", fourbar_fmu, tmp_path)
    path = tmp_path / "short.toml"
    path.write_text(f'case = "{case}"\nstop = 9.5\n[fault]\nvariable = "L2"\nrelative = 0.01\ntime = 9.2\n')
    assert load_sweep(path).stop == 9.5


def _dry_run(argv: list[str], cwd: Path):
    import subprocess
    import sys

    return subprocess.run([str(Path(sys.executable).parent / "fourbar-sweep"), *argv, "--dry-run", "--out",
                           str(cwd / "out")], cwd=cwd, capture_output=True, text=True, timeout=HANG_GUARD)


def test_a_fifo_or_a_device_is_refused_not_read(tmp_path, fourbar_fmu):
    """A sweep file or base case that is a FIFO (no writer) or /dev/zero was read forever; now exit 2
    naming it, nothing written."""
    text = smoke(tmp_path, fourbar_fmu).read_text()
    device = tmp_path / "device.toml"
    device.write_text(text.replace(f'case = "{tmp_path / "case1_normal.toml"}"', 'case = "/dev/zero"'))
    assert 'case = "/dev/zero"' in device.read_text()
    proc = _dry_run([str(device)], tmp_path)
    assert proc.returncode == 2 and 'case = "/dev/zero": not a regular file' in proc.stderr, proc.stderr
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    proc = _dry_run([str(fifo)], tmp_path)
    assert proc.returncode == 2 and f'{fifo}: sweep = "{fifo}": not a regular file' in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()


def test_a_path_that_cannot_be_looked_up_is_refused(tmp_path, fourbar_fmu):
    """A base case or FMU path with a NUL character or a 4000-character name (fuzzed sweep files)
    raised ValueError / OSError tracebacks; now each is one problem naming the key."""
    text = smoke(tmp_path, fourbar_fmu).read_text()
    case_line = f'case = "{tmp_path / "case1_normal.toml"}"'
    for name, line, fragment in (
            ("nul_case", 'case = "cases/\\u0000.toml"', 'case = "cases/\\u0000.toml": cannot be looked up (embedded null'),
            ("long_case", f'case = "{"A" * 4000}"', "cannot be looked up (File name too long)"),
            ("long_fmu", f'{case_line}\nfmu = "{"A" * 4000}"', "fmu = \"AAAA"),
            ("nul_fmu", f'{case_line}\nfmu = "x\\u0000.fmu"', 'fmu = "x\\u0000.fmu": cannot be looked up')):
        path = tmp_path / f"{name}.toml"
        path.write_text(text.replace(case_line, line))
        with pytest.raises(SweepError) as info:
            load_sweep(path)
        assert fragment in str(info.value), str(info.value)


def test_a_deeply_nested_sweep_file_is_refused(tmp_path, fourbar_fmu):
    """tomllib recurses per nesting level: 5000 nested arrays raised RecursionError (a traceback)."""
    path = write_sweep(tmp_path, fourbar_fmu, FAULT + "[report]\nx = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(SweepError, match="nested too deeply to be a sweep file"):
        load_sweep(path)


GOOD = """
[fault]
variable = "L2"
kind = ["step"]
relative = [0.01]
time = [10.0]
"""


@pytest.mark.parametrize("file_name, name", [("my sweep.toml", "my_sweep"), ("swéep.toml", "sweep")])
def test_a_sweep_without_name_is_named_after_its_file_made_a_folder_name(tmp_path, fourbar_fmu, file_name, name):
    # A file name with a space or an accent used to be refused with a message about a `name` key
    # the user never wrote (issue 37); the orchestrator names cases the same way.
    assert load_sweep(write_sweep(tmp_path, fourbar_fmu, GOOD, name=file_name)).name == name


def test_a_sweep_file_name_with_no_latin_letter_is_refused_naming_the_file(tmp_path, fourbar_fmu, capsys):
    path = write_sweep(tmp_path, fourbar_fmu, GOOD, name="案例.toml")
    assert main([str(path), "--dry-run", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "案例.toml" in err and 'name = "..."' in err and "rename the file" in err
