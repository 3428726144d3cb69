"""Every shipped mechanism's native FMU gives FMPy's numbers in libcosim and in fmusim (issue 24).

Issue 24: "The native FMU of every shipped mechanism runs in FMPy, libcosim and fmusim with no
environment variables."  Each host runs as a process started with an empty environment
(``env={}``), through the runners of benchmarks/fmi_hosts.py (the benchmark that writes the
table of docs/fmi_hosts.md, "Every shipped mechanism in three hosts"), here over 5 s instead
of its 20 s.  Every output is compared at every communication point, each host within its
bound of ``fmi_hosts.AGREEMENT``:

- libcosim: the same binary on the same communication grid; its integer-nanosecond times
  differ from FMPy's start + n * step by an ulp at some steps, and the FMU snaps both to whole
  nanoseconds (docs/contracts.md, "Time resolution 1 ns"), so the numbers must agree to
  round-off: 1e-12 x max(1, |value|) (measured 0.0);
- fmusim: the same, seen through its CSV's 16 significant digits: 1e-15 x max(1, |value|)
  (a printed value is within 5e-16 of the double, relative, and reading it back adds at most
  1.1e-16; measured 5.3e-16).

fmusim is not packaged: the fmusim tests run when ``$FMUSIM`` names an fmusim executable or
``fmusim`` is on PATH (``scripts/build_fmusim.sh`` builds one from the Reference-FMUs'
sources), and are skipped otherwise.  A ``$FMUSIM`` that names no executable fails them.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from support import fmucheck_or_skip, fmusim_or_skip, swept_mechanisms

from fmu_src import fmi_hosts
from fmu_src.mechanism.table import DEFAULT_TOLERANCE

pytest.importorskip("libcosimpy", reason="libcosimpy is not installed (pip install libcosimpy); "
                                         "the libcosim comparison needs it")

MECHANISMS = swept_mechanisms()   # support.BENCHMARK_MECHANISMS: tested in their own files
#: 5 s of the benchmark's experiment (20 s): 501 communication points, past the first second in
#: which every shipped mechanism moves through most of its motion (a fast crank turns ~5 times).
EXPERIMENT = fmi_hosts.Experiment(stop=5.0)

@pytest.fixture(scope="module")
def runs_of(mechanism_fmus, tmp_path_factory):
    """``runs_of(mechanism)``: (the FMU, its outputs, FMPy's run), one FMPy run per mechanism."""
    cache = {}

    def get(mechanism: str):
        if mechanism not in cache:
            fmu = mechanism_fmus.get(mechanism, "native")
            outputs = fmi_hosts.output_names(fmu)
            reference = fmi_hosts.run_fmpy(fmu, outputs, EXPERIMENT, tmp_path_factory.mktemp(f"fmpy_{mechanism}"))
            assert reference.ok, f"{mechanism}: FMPy (empty environment) failed: exit {reference.exit_code}: " \
                                 f"{reference.message}"
            cache[mechanism] = fmu, outputs, reference
        return cache[mechanism]

    return get


@pytest.fixture(scope="module")
def fmusim():
    return fmusim_or_skip()


def _assert_agrees(agreement: fmi_hosts.Agreement, mechanism: str) -> None:
    assert agreement.agrees, f"{mechanism} in {agreement.host}: {agreement.problem}"
    assert agreement.rows == EXPERIMENT.steps + 1


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_fmpy_runs_with_no_environment(mechanism, runs_of):
    _fmu, outputs, reference = runs_of(mechanism)
    agreement = fmi_hosts.compare(reference, reference, EXPERIMENT)
    _assert_agrees(agreement, mechanism)
    assert np.isfinite(reference.values).all() and len(outputs) == reference.values.shape[1]


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_libcosim_gives_fmpys_numbers(mechanism, runs_of, tmp_path):
    fmu, outputs, reference = runs_of(mechanism)
    run = fmi_hosts.run_libcosim(fmu, outputs, EXPERIMENT, tmp_path)
    _assert_agrees(fmi_hosts.compare(run, reference, EXPERIMENT), mechanism)


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_fmusim_gives_fmpys_numbers(mechanism, runs_of, fmusim, tmp_path):
    fmu, outputs, reference = runs_of(mechanism)
    run = fmi_hosts.run_fmusim(fmusim, fmu, outputs, EXPERIMENT, tmp_path)
    _assert_agrees(fmi_hosts.compare(run, reference, EXPERIMENT), mechanism)


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_the_compliance_checker_gives_fmpys_numbers_in_co_simulation(mechanism, runs_of, tmp_path):
    """fmuCheck -k cs (issue 26's hosts: the FMU Compliance Checker on FMI 2.0 co-simulation):
    no warning or error, and FMPy's numbers (fmi_hosts.AGREEMENT['fmuCheck']); skipped where the
    checker is not built ($FMUCHECK, or fmuCheck.linux64 on PATH; scripts/build_fmucheck.sh)."""
    fmucheck = fmucheck_or_skip()
    fmu, outputs, _ = runs_of(mechanism)
    # the checker sets no parameter: FMPy at the FMU's own tolerance is its reference
    experiment = dataclasses.replace(EXPERIMENT, rtol=DEFAULT_TOLERANCE, atol=DEFAULT_TOLERANCE)
    reference = fmi_hosts.run_fmpy(fmu, outputs, experiment, tmp_path)
    checked = fmi_hosts.run_fmucheck(fmucheck, fmu, outputs, stop=experiment.stop, step=experiment.step,
                                     points=experiment.steps + 1, workdir=tmp_path, interface="cs")
    assert checked.checker_errors == 0 and checked.checker_warnings == 0, checked.log[-3000:]
    _assert_agrees(fmi_hosts.compare(checked.run, reference, experiment), mechanism)


def test_the_comparison_sees_a_difference_and_a_failure(runs_of):
    """The checks above can fail: a change of 1e-11 in one output at one point, a missing row
    and a host that exited 1 are each reported, naming the output, the count or the status."""
    _fmu, outputs, reference = runs_of("fourbar")
    values = reference.values.copy()
    values[250, 3] += 1e-11 * max(1.0, abs(values[250, 3]))
    moved = dataclasses.replace(reference, host="libcosim", values=values)
    found = fmi_hosts.compare(moved, reference, EXPERIMENT)
    assert not found.agrees and outputs[3] in found.problem and "t = 2.50 s" in found.problem
    assert found.max_difference == pytest.approx(1e-11 * max(1.0, abs(reference.values[250, 3])), rel=1e-3)

    short = dataclasses.replace(reference, host="fmusim", time=reference.time[:-1], values=reference.values[:-1])
    assert "500 rows, expected 501" in fmi_hosts.compare(short, reference, EXPERIMENT).problem

    failed = fmi_hosts.HostRun("fmusim", outputs, None, None, 1, 0.1, "Failed to instantiate FMU.")
    assert fmi_hosts.compare(failed, reference, EXPERIMENT).problem == "exit 1: Failed to instantiate FMU."


def test_a_wrong_fmusim_path_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("FMUSIM", str(tmp_path / "no_fmusim"))
    with pytest.raises(fmi_hosts.HostError, match=r"\$FMUSIM = .*no_fmusim: not an executable file"):
        fmi_hosts.find_fmusim()
