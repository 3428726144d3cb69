"""Two different builds of a pythonfmu FMU in one process each run their own code.

pythonfmu imports the slave script by module name; without orchestrator/pythonfmu_modules.py
the second build would reuse the first one's cached modules.  Build B here is FourBar.fmu
with one line changed in its slave script (x2 is reported as 42 m), so whose code ran is
visible in the exchange file.
"""
from __future__ import annotations

import subprocess
import sys
import zipfile

from support import case_file


def patched_copy(fmu, dest):
    """FourBar.fmu whose slave reports x2 = 42 m (same module names, same GUID)."""
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "resources/fourbar_slave.py":
                text = data.decode()
                line = "        self.energy = dae.energy()\n"
                assert text.count(line) == 1
                data = text.replace(line, line + "        self.x2 = 42.0\n").encode()
            zout.writestr(item, data)
    return dest


def test_each_build_runs_its_own_code(fourbar_fmu, tmp_path, repo_root):
    other = patched_copy(fourbar_fmu, tmp_path / "Patched.fmu")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    case_a = case_file("case1_normal", fourbar_fmu, tmp_path / "a", stop=0.1)
    case_b = case_file("case1_normal", other, tmp_path / "b", stop=0.1)
    code = f"""
import pandas as pd
from orchestrator import run_case
for i, case in enumerate([{str(case_a)!r}, {str(case_b)!r}, {str(case_a)!r}]):
    result = run_case(case, {str(tmp_path)!r} + f"/out{{i}}")
    print(pd.read_csv(result.exchange_path)["x2"].max())
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    first, patched, again = map(float, result.stdout.split())
    assert first < 1.0            # the crank's centre stays within L2/2 = 0.5 m of the origin
    assert patched == 42.0        # build B's own slave ran
    assert again == first         # and build A's again after it


def test_runs_of_the_same_build_keep_its_modules(fourbar_fmu, tmp_path, repo_root):
    # A sweep worker runs the same FMU hundreds of times, each from a fresh extraction:
    # identical Python files are not imported again.
    case = case_file("case1_normal", fourbar_fmu, tmp_path, stop=0.05)
    code = f"""
import sys
from orchestrator import run_case
ids = []
for i in range(3):
    run_case({str(case)!r}, {str(tmp_path)!r} + f"/out{{i}}")
    ids.append(id(sys.modules["fourbar_slave"]))
print(len(set(ids)))
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["1"]
