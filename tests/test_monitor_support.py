"""Exchange files for the monitor tests, produced by the orchestrator (``fourbar-run``).

The four runs (Case 1, Case 2, and both with σ = 5 mm sensor noise on x2) are started
together, once per test session, the first time a monitor test asks for one; the other
``test_monitor_*`` modules import :func:`orchestrated` from here.  The test in this module
checks the parts of the exchange contract the monitor relies on.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import threading
from pathlib import Path

import pytest

from support import FOURBAR_MONITOR, FOURBAR_RUN, REPO, case_file, recorded_columns  # noqa: F401 - re-exported to the monitor tests
from support import file_key, shared_folder_of, shared_result
NOISE_STD = 0.005   # m, σ of the x2 sensor noise in the acceptance criteria

NOISE_SEED = 7

_lock = threading.Lock()
_runs: dict[str, Path] = {}




def noise_case(name: str, fmu: Path, dest: Path, fault: bool) -> Path:
    """Table 1's Case 1 or 2 (the shipped case file) with σ = 5 mm sensor noise on x2."""
    noise = f"\n[noise]\nseed = {NOISE_SEED}\nstd = {{ x2 = {NOISE_STD!r} }}\n"
    return case_file("case2_fault_L2" if fault else "case1_normal", fmu, dest, name=name, extra=noise)


def orchestrated(tmp_path_factory: pytest.TempPathFactory, fmu: Path, name: str) -> Path:
    """Path of the exchange.csv of run ``name`` (case1, case2, noise1, noise2); runs them once per
    test session, also when both xdist workers ask (support.shared_result: ~28 s of CPU on the
    pythonfmu FMU).  The files are shared: a test that changes one works on a copy (copy_run)."""
    with _lock:
        if not _runs:
            def run_all() -> dict[str, Path]:
                base = tmp_path_factory.mktemp("orchestrated")
                cases = {
                    "case1": case_file("case1_normal", fmu, base / "case1.toml"),
                    "case2": case_file("case2_fault_L2", fmu, base / "case2.toml"),
                    "noise1": noise_case("noise1", fmu, base / "noise1.toml", fault=False),
                    "noise2": noise_case("noise2", fmu, base / "noise2.toml", fault=True),
                }
                procs = {}
                for key, case in cases.items():
                    procs[key] = subprocess.Popen([FOURBAR_RUN, str(case), "--out", str(base / key), "--quiet"],
                                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                failures = []
                for key, proc in procs.items():
                    out, err = proc.communicate(timeout=300)
                    if proc.returncode != 0:
                        failures.append(f"{key}: exit {proc.returncode}\n{out}\n{err}")
                if failures:
                    raise RuntimeError("fourbar-run failed:\n" + "\n".join(failures))
                return {key: base / key / "exchange.csv" for key in cases}

            key = file_key(fmu, REPO / "cases" / "case1_normal.toml", REPO / "cases" / "case2_fault_L2.toml") + \
                repr((NOISE_SEED, NOISE_STD)).encode()
            _runs.update(shared_result(shared_folder_of(tmp_path_factory), "orchestrated", key, run_all))
    return _runs[name]


def copy_run(src_exchange: Path, dest_dir: Path, *, run_json: bool = True) -> Path:
    """Copy an orchestrated exchange.csv (and its run.json) into ``dest_dir``."""
    dest_dir.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src_exchange, dest_dir / "exchange.csv")
    if run_json:
        shutil.copyfile(src_exchange.parent / "run.json", dest_dir / "run.json")
    return dest_dir / "exchange.csv"


def test_orchestrated_files_follow_the_exchange_contract(tmp_path_factory, fourbar_fmu):
    for name, fault in (("case1", None), ("case2", 10.0), ("noise1", None), ("noise2", 10.0)):
        path = orchestrated(tmp_path_factory, fourbar_fmu, name)
        data = path.read_bytes()
        lines = data.split(b"\n")
        assert lines[0] == ",".join(["time", *recorded_columns(fourbar_fmu)]).encode()
        assert data.endswith(b"\n") and len(lines) == 10001 + 2        # header + rows + final ''
        assert lines[1001].startswith(b"10.0,")
        run = json.loads((path.parent / "run.json").read_text())
        assert run["status"] == "finished" and run["rows_written"] == 10001
        assert run["fault_time"] == fault
        assert (run["noise"] is not None) == name.startswith("noise")
    assert os.access(FOURBAR_MONITOR, os.X_OK)
