"""The monitor is independent of the simulation: it imports nothing from orchestrator/,
fmu_src/ (or the FMU run-time mechanism_model) or sweep/, and it is cheap to import.
"""
from __future__ import annotations

import ast
import json
import subprocess
import sys

import pytest

from test_monitor_support import REPO, orchestrated

FORBIDDEN = ("orchestrator", "fmu_src", "mechanism_model", "sweep", "fmpy", "pythonfmu")


def test_no_forbidden_import_in_the_source():
    """Static scan of every import statement of monitor/*.py."""
    problems = []
    files = sorted((REPO / "monitor").glob("*.py"))
    assert {p.name for p in files} >= {"__init__.py", "reader.py", "spectrum.py", "forecasters.py",
                                         "detector.py", "options.py", "stream.py", "summary.py",
                                         "session.py", "outputs.py", "cli.py"}
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:                    # relative: must stay inside monitor/
                    if node.level > 1:
                        problems.append(f"{path.name}:{node.lineno}: relative import leaves the package")
                    continue
                names = [node.module or ""]
            elif isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) in (
                    "__import__", "import_module"):
                problems.append(f"{path.name}:{node.lineno}: dynamic import")
                continue
            else:
                continue
            for name in names:
                if name.split(".")[0] in FORBIDDEN:
                    problems.append(f"{path.name}:{node.lineno}: imports {name}")
        assert "__all__" in path.read_text(encoding="utf-8") or path.name == "__init__.py", path
    assert not problems, problems


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_no_forbidden_module_loaded_at_run_time(tmp_path_factory, fourbar_fmu, tmp_path):
    """Import the package and the CLI, replay a file with both models and write every output,
    then list sys.modules.  The library prints nothing (Prophet's and cmdstanpy's logging included)."""
    exchange = orchestrated(tmp_path_factory, fourbar_fmu, "case2")
    code = f"""
import json, sys
import monitor, monitor.cli
light = sorted(m for m in ("prophet", "matplotlib", "sklearn", "pandas", "scipy") if m in sys.modules)
from monitor import replay
for model in ("harmonic", "prophet"):
    r = replay({str(exchange)!r}, model=model, out_dir={str(tmp_path / "out")!r})
bad = sorted(m for m in sys.modules if m.split(".")[0] in {FORBIDDEN!r})
print(json.dumps({{"light": light, "bad": bad, "alarm": r.first_alarm_time}}))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "" and len(proc.stdout.splitlines()) == 1, (proc.stdout, proc.stderr)
    report = json.loads(proc.stdout)
    assert report["bad"] == []
    assert report["light"] == []          # heavy libraries are imported only when used
    assert report["alarm"] == 10.01           # the CUSUM at the first changed row
    assert (tmp_path / "out" / "statistic.png").exists()
