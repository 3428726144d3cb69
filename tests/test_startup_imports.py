"""Start-up (issue 38, item 6): each command loads only the heavy libraries its path uses.

How long a command takes to start is benchmarks/startup.py's job (docs/benchmarks.md); these
tests do not time anything.  They run a command's ``main`` in a fresh Python process and look at
which top-level packages that process has imported (``sys.modules``): ``--help`` of every
command loads none of the heavy libraries, and a harmonic replay loads neither Prophet nor the
sweep's and the view's libraries (nor matplotlib with ``--no-plots``); ``--version`` looks the
version up only when asked.  A package's
``__init__`` that re-exported everything used to pull pandas into ``fourbar-view --help`` and
scipy into ``fourbar-diagnose --help``.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from support import FOURBAR_RUN, REPO

#: Libraries that take a noticeable share of a second or more to import; none is needed to
#: print a command's help.
HEAVY = ("prophet", "cmdstanpy", "matplotlib", "pandas", "scipy", "sklearn", "dask", "distributed", "bokeh",
         "panel", "fmpy", "sympy", "pyarrow")

#: Libraries only the Prophet model, a sweep or the view use: a harmonic replay loads none.
NOT_IN_HARMONIC_REPLAY = ("prophet", "cmdstanpy", "sklearn", "dask", "distributed", "bokeh", "panel", "fmpy",
                          "sympy")

_PROBE = """
import contextlib, io, json, sys
from {module} import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
    try:
        code = main({argv!r})
    except SystemExit as exc:
        code = exc.code
print(json.dumps({{"code": code, "stderr": err.getvalue()[-2000:],
                  "modules": sorted(sys.modules)}}))
"""

#: A hang guard only (a replay of 12 s of data takes a few seconds of CPU).
_GUARD_S = 300


def _imported(module: str, argv: list[str]) -> tuple[int, set[str], str]:
    """Run ``module.main(argv)`` in a fresh process: its exit status, the modules it imported
    (``a.b`` also as ``a``) and the end of what it wrote to stderr."""
    proc = subprocess.run([sys.executable, "-c", _PROBE.format(module=module, argv=argv)], cwd=REPO,
                          capture_output=True, text=True, timeout=_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-4000:]
    report = json.loads(proc.stdout.splitlines()[-1])
    modules = set(report["modules"])
    return report["code"], modules | {name.split(".")[0] for name in modules}, report["stderr"]


@pytest.mark.parametrize("command, module", [("fourbar-monitor", "monitor.cli"), ("fourbar-run", "orchestrator.cli"),
                                             ("fourbar-diagnose", "diagnose.cli"), ("fourbar-view", "view.cli"),
                                             ("fourbar-sweep", "sweep.cli")])
def test_help_loads_no_heavy_library(command, module):
    code, modules, stderr = _imported(module, ["--help"])
    assert code == 0, stderr
    assert not modules & set(HEAVY), f"{command} --help imported {sorted(modules & set(HEAVY))}"
    # --version's lookup (importlib.metadata, ~50 ms) waits until --version is asked for
    assert "importlib.metadata" not in modules


@pytest.mark.parametrize("module", ["monitor.cli", "orchestrator.cli", "diagnose.cli", "view.cli", "sweep.cli"])
def test_version_still_prints_the_installed_version(module):
    from importlib.metadata import version

    proc = subprocess.run([sys.executable, "-c", f"from {module} import main; main(['--version'])"], cwd=REPO,
                          capture_output=True, text=True, timeout=_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-4000:]
    command = {"orchestrator.cli": "fourbar-run"}.get(module, f"fourbar-{module.split('.')[0]}")
    assert proc.stdout == f"{command} {version('fourbar-cosim')}\n"


def test_packages_load_their_modules_on_first_use():
    """``import monitor`` (``fourbar_common``, ``view``) loads none of its modules but the few lines
    that make the names lazy (``fourbar_common.lazy``); each public name still resolves, from the
    module that defines it."""
    probe = """
import json, sys
import fourbar_common, monitor, view
loaded = sorted(m for m in sys.modules if m.startswith(("monitor.", "fourbar_common.", "view."))
                and m != "fourbar_common.lazy")
homes = {}
for package in (fourbar_common, monitor, view):
    for name in package.__all__:
        value = getattr(package, name)
        homes[package.__name__ + "." + name] = getattr(value, "__module__", None)
    assert set(package.__all__) <= set(dir(package)), package.__name__
print(json.dumps({"loaded": loaded, "homes": homes}))
"""
    proc = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, timeout=_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-4000:]
    report = json.loads(proc.stdout)
    assert report["loaded"] == [], report["loaded"]
    homes = report["homes"]
    assert homes["monitor.replay"] == "monitor.session"
    assert homes["monitor.MonitorOptions"] == "monitor.options"
    assert homes["fourbar_common.StepEvent"] == "fourbar_common.events"
    assert homes["view.RunFolder"] == "view.sources"
    with pytest.raises(AttributeError, match="no attribute 'nothing_by_this_name'"):
        import monitor
        monitor.nothing_by_this_name  # noqa: B018


@pytest.fixture(scope="module")
def short_case2(native_fmu, tmp_path_factory) -> Path:
    """Case 2 up to 12 s (the training window and the fault at 10 s) on the native FMU."""
    out = tmp_path_factory.mktemp("startup") / "case2"
    subprocess.run([FOURBAR_RUN, str(REPO / "cases" / "case2_fault_L2.toml"), "--fmu", str(native_fmu),
                    "--stop", "12", "--out", str(out), "--quiet"], check=True, timeout=_GUARD_S)
    return out / "exchange.csv"


@pytest.mark.parametrize("plots", [True, False], ids=["plots", "no-plots"])
def test_harmonic_replay_loads_no_prophet(short_case2, tmp_path, plots):
    argv = [str(short_case2), "--model", "harmonic", "--quiet", "--out", str(tmp_path / "monitor")]
    code, modules, stderr = _imported("monitor.cli", argv + ([] if plots else ["--no-plots"]))
    assert code == 1, f"expected Case 2's alarm (exit 1), got {code}: {stderr}"
    # the probe sees what the replay loads on its way: pandas (its frames), scipy (the period)
    assert {"pandas", "scipy"} <= modules
    assert ("matplotlib" in modules) == plots
    assert (tmp_path / "monitor" / "history.png").exists() == plots
    assert not modules & set(NOT_IN_HARMONIC_REPLAY), \
        f"a harmonic replay imported {sorted(modules & set(NOT_IN_HARMONIC_REPLAY))}"


def test_replay_runs_blas_on_one_thread(short_case2, tmp_path):
    """``fourbar-monitor`` monitors with one BLAS thread: its linear algebra is small, and more
    threads only wait, busily, for work (a harmonic replay of Case 2 spent 0.7 s more CPU on 2
    cores, with the same results; docs/benchmarks.md).  The library's own setting is restored
    after the session.  (On a 1-core machine BLAS has one thread anyway.)"""
    probe = """
import json, sys
import monitor.session
from threadpoolctl import threadpool_info
from monitor.cli import main

def blas_threads():
    return sorted(set(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"))

before = blas_threads()
seen, replay = [], monitor.session.replay
def spy(*args, **kwargs):
    seen.append(blas_threads())
    return replay(*args, **kwargs)
monitor.session.replay = spy
code = main({argv!r})
print(json.dumps({{"code": code, "before": before, "during": seen, "after": blas_threads()}}))
"""
    import os

    argv = [str(short_case2), "--model", "harmonic", "--quiet", "--no-plots", "--out", str(tmp_path / "monitor")]
    proc = subprocess.run([sys.executable, "-c", probe.format(argv=argv)], cwd=REPO, capture_output=True, text=True,
                          timeout=_GUARD_S, env={k: v for k, v in os.environ.items() if "_NUM_THREADS" not in k})
    assert proc.returncode == 0, proc.stderr[-4000:]
    report = json.loads(proc.stdout.splitlines()[-1])
    assert report["code"] == 1, report
    assert report["during"] == [[1]], report
    assert report["after"] == report["before"], report         # the library's setting, restored
