"""fourbar-run on the native FMI 3.0 FMUs (issue 26: "The mechanisms issue's cases run on FMI 3.0
CS through fourbar-run"): the shipped cases give the FMI 2.0 FMU's exchange file, and FMI 3.0
Model Exchange through CVode follows co-simulation."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from support import FOURBAR_RUN, case_file

#: The shipped cases and the mechanism each runs.
CASES = {"case2_fault_L2": "fourbar", "slider_crank_fault_L3": "slider_crank",
         "fourbar_driven_fault_m3": "fourbar_driven"}
#: s: past each case's fault (10 s; the driven four-bar's at 10 s too).
STOP = 14.0


def _run(tmp_path: Path, case: str, fmu: Path, name: str, fmi_type: str | None = None, **settings) -> pd.DataFrame:
    path = case_file(case, fmu, tmp_path / f"{name}.toml", name=name, **settings)
    if fmi_type is not None:
        text = path.read_text(encoding="utf-8")
        path.write_text(text.replace("\n[experiment]", f'\nfmi_type = "{fmi_type}"\n\n[experiment]', 1), encoding="utf-8")
    proc = subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp_path / name), "--stop", repr(STOP), "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return pd.read_csv(tmp_path / name / "exchange.csv")


@pytest.mark.parametrize("case", list(CASES))
def test_each_shipped_case_runs_on_fmi3_co_simulation_as_on_fmi2(case, mechanism_fmus, tmp_path):
    """The same C model and integrator behind both layers: the same numbers, to the last bit."""
    mechanism = CASES[case]
    fmi3 = _run(tmp_path, case, mechanism_fmus.get(mechanism, "native3"), "fmi3")
    fmi2 = _run(tmp_path, case, mechanism_fmus.get(mechanism, "native"), "fmi2")
    assert list(fmi3.columns) == list(fmi2.columns) and len(fmi3) == len(fmi2) == round(STOP / 0.01) + 1
    assert np.array_equal(fmi3.to_numpy(), fmi2.to_numpy())
    record = json.loads((tmp_path / "fmi3" / "run.json").read_text())
    assert record["status"] == "finished" and record["fmu"]["fmi_type"] == "CoSimulation"
    assert record["fmu"]["path"].endswith("Native3.fmu")


def test_fmi3_model_exchange_follows_co_simulation(mechanism_fmus, tmp_path):
    """Case 2 through FMI 3.0 Model Exchange (CVode at 1e-14; its error over 14 s ~1e-10 m) against
    FMI 2.0 co-simulation at rtol = atol = 1e-12: within the issue's 1e-9 m, fault included."""
    me = _run(tmp_path, "case2_fault_L2", mechanism_fmus.get("fourbar", "native3"), "me", "ModelExchange",
              tolerance=1e-14)
    cs = _run(tmp_path, "case2_fault_L2", mechanism_fmus.get("fourbar", "native"), "cs", rtol=1e-12, atol=1e-12)
    centres = ["x2", "y2", "x3", "y3", "x4", "y4"]
    assert np.array_equal(me["time"], cs["time"])
    worst = float(np.max(np.abs(me[centres].to_numpy() - cs[centres].to_numpy())))
    assert worst <= 1e-9, worst
