"""fourbar-diagnose on a mechanism the project does not ship: the drag link of
tests/mechanisms/drag_link.toml (a double-crank four-bar whose crank is a flywheel, the
coupler's centre of mass off its pins' line).  Issue 37: on such a drag link a noise-free m2
+10 % step was diagnosed as g with confidence.

Every parameter in turn steps +10 % at t = 8 s of a 12 s run (native FMU).  The diagnosis is
called in-process on a summary that puts the monitor's first alarm at 8.25 s (the monitor's
CUSUM alarmed 0.25 s after such a step on x2; the monitor's own timing is its tests' business,
and running it here would cost 25 s a run): the change is looked for in the 5 s before.

- Noise-free: the right parameter, at 8.00 s, the value exact to round-off or within its
  stated ± (the ± must cover the error: 30x too small on the quick-return before).
- Noisy (5 mm on the six centre columns, the shipped cases' sigma): the right parameter, or
  the verdict ``ambiguous`` naming it, or ``no_change`` only when the step's chi-square gain
  is under the 5-sigma threshold (the data do not show it).
"""
from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from diagnose import diagnose
from support import FOURBAR_RUN, REPO

MECHANISM = REPO / "tests" / "mechanisms" / "drag_link.toml"
PARAMETERS = {name: spec["value"] for name, spec in tomllib.loads(MECHANISM.read_text())["parameters"].items()}
CENTRES = ("x2", "y2", "x3", "y3", "x4", "y4")
FAULT = 8.0          # s
ALARM = FAULT + 0.25  # s


@pytest.fixture(scope="session")
def drag_link_fmu(tmp_path_factory) -> Path:
    from fmu_src.native_build import find_compiler
    if find_compiler() is None:
        pytest.skip("no C compiler: the native FMU cannot be built here")
    dest = tmp_path_factory.mktemp("drag_link") / "DragLinkNative.fmu"
    subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(MECHANISM), "--only", "native",
                    "--fmi", "2", "--native-out", str(dest)], check=True, cwd=REPO, capture_output=True, timeout=600)
    return dest


def _run(where: Path, fmu: Path, parameter: str, value: float, sigma: float = 0.0, columns=("x2",)) -> Path:
    """A 12 s run with ``parameter`` stepping to ``value`` at FAULT, and a summary alarming at ALARM."""
    name = f"{parameter}_{sigma:g}"
    noise = ("\n[noise]\nseed = 5\nstd = { " + ", ".join(f"{c} = {sigma}" for c in CENTRES) + " }\n") if sigma else ""
    case = where / f"{name}.toml"
    case.write_text(f'name = "{name}"\nfmu = {json.dumps(fmu.as_posix())}\n'
                    "[experiment]\nstart = 0.0\nstop = 12.0\nstep = 0.01\ntolerance = 1e-9\n"
                    "[parameters]\nrtol = 1e-9\natol = 1e-6\n"
                    f'[[events]]\ntype = "step"\ntime = {FAULT}\nvariable = "{parameter}"\nvalue = {value!r}\n'
                    f"[outputs]\nvariables = {json.dumps(list(CENTRES))}\n"
                    "[exchange]\nflush_interval = 1.0\nrealtime_factor = 0.0\n" + noise)
    run = where / name
    subprocess.run([FOURBAR_RUN, str(case), "--out", str(run), "--quiet"], check=True, timeout=300)
    run_id = json.loads((run / "run.json").read_text())["run_id"]
    (run / "summary.json").write_text(json.dumps({"run_id": run_id, "first_alarm_time": ALARM,
                                                  "signal": ",".join(columns)}))
    return run


def _check_exact(d, parameter: str, value: float) -> None:
    best = d.best
    print(f"{parameter}: error {best.value - value:.2g}, stated ± {best.stderr:.2g}: {d.message}")   # pytest -s
    assert d.verdict == "explained", d.message
    assert best.parameter == parameter and best.kind == "step", d.message
    assert best.change_time == pytest.approx(FAULT, abs=0.005), d.message      # the grid point itself
    # exact to round-off, or the stated standard error covers the error (at 3 of them)
    assert abs(best.value - value) <= 3 * best.stderr, (best.value - value, best.stderr, d.message)
    assert best.stderr <= 1e-6 * value, d.message      # noise-free: known to 1e-6 at worst (L4's 5e-7 m of 1.32)


def test_a_flywheel_crank_mass_step_is_named_noise_free(tmp_path, drag_link_fmu):
    """Issue 37's case: m2 +10 %, x2 monitored, no noise: m2, not g."""
    run = _run(tmp_path, drag_link_fmu, "m2", PARAMETERS["m2"] * 1.1)
    d = diagnose(run, summary=run / "summary.json")
    _check_exact(d, "m2", PARAMETERS["m2"] * 1.1)
    assert d.ranking[1].chi2 > 1e3 * max(d.best.chi2, d.rows)        # the runner-up is far off


@pytest.mark.slow
@pytest.mark.parametrize("parameter", sorted(set(PARAMETERS) - {"m2"}))
def test_every_drag_link_parameter_is_named_noise_free(tmp_path, drag_link_fmu, parameter):
    value = PARAMETERS[parameter] * 1.1
    run = _run(tmp_path, drag_link_fmu, parameter, value)
    d = diagnose(run, summary=run / "summary.json")
    _check_exact(d, parameter, value)


@pytest.mark.slow
@pytest.mark.parametrize("parameter", sorted(PARAMETERS))
def test_every_drag_link_parameter_under_noise_is_named_or_ambiguous(tmp_path, drag_link_fmu, parameter):
    """5 mm on all six centres: the right parameter within 4 standard errors, or ``ambiguous``
    naming it among the two; ``no_change`` only where the step gains under 25 in chi-square."""
    value = PARAMETERS[parameter] * 1.1
    run = _run(tmp_path, drag_link_fmu, parameter, value, sigma=0.005, columns=CENTRES)
    d = diagnose(run, summary=run / "summary.json")
    print(f"{parameter} under noise: {d.message}")      # pytest -s shows the figures docs/diagnose.md quotes
    if d.verdict == "no_change":
        assert d.healthy_chi2 - d.ranking[0].chi2 < 25.0, d.message
        pytest.xfail(f"{parameter} +10 % does not show through 5 mm of noise in 3 s: {d.message}")
    if d.verdict == "ambiguous":
        assert parameter in (d.best.parameter, d.runner_up.parameter), d.message
        assert d.separating and d.separating[0].column in d.message, d.message
        return
    assert d.verdict == "explained", d.message
    assert d.best.parameter == parameter, d.message
    assert abs(d.best.value - value) <= 4 * d.best.stderr, (d.best.value - value, d.best.stderr, d.message)
