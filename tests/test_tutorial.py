"""examples/tutorial.ipynb: executed end to end with nbclient, judged by its outputs.

The kernel is this interpreter (the venv's ``sys.executable``), through a kernelspec written
into the test's temporary folder (nothing is installed into the user's Jupyter). The notebook
reads two environment variables, set in that kernelspec: ``TUTORIAL_OUT`` (its output folder,
here the temporary folder, never out/) and ``FOURBAR_NATIVE_FMU`` (the FMU, from the
``native_fmu`` fixture: never a build into build/). The working directory is the repository.
"""
from __future__ import annotations

import json
import re
import sys
import time
from pathlib import Path

import pytest

from support import REPO

pytestmark = pytest.mark.slow

NOTEBOOK = REPO / "examples" / "tutorial.ipynb"
KERNEL = "fourbar-tutorial-venv"
#: The brief's budget is ~60 s on 2 cores; the machine is shared with other test runs, so the
#: test fails only at three times that (the measured time is printed with -s).
BUDGET_S = 180.0
#: One cell may take this long before nbclient gives up (the slowest, the diagnosis, takes ~4 s).
CELL_TIMEOUT_S = 240


def _state(path: Path):
    """What the notebook must not change: whether ``path`` exists, and its modification time."""
    return (path.exists(), path.stat().st_mtime_ns if path.exists() else None)


@pytest.fixture(scope="module")
def executed(tmp_path_factory, native_fmu):
    import nbformat
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import KernelManager
    from nbclient import NotebookClient

    tmp = tmp_path_factory.mktemp("tutorial")
    out = tmp / "out"
    spec_dir = tmp / "kernels" / KERNEL
    spec_dir.mkdir(parents=True)
    spec_dir.joinpath("kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "fourbar-cosim venv (test)",
        "language": "python",
        "env": {"TUTORIAL_OUT": str(out), "FOURBAR_NATIVE_FMU": str(Path(native_fmu).resolve()),
                # figures inline even when the test's environment selects another backend
                "MPLBACKEND": "module://matplotlib_inline.backend_inline"},
    }))
    km = KernelManager(kernel_name=KERNEL, kernel_spec_manager=KernelSpecManager(kernel_dirs=[str(tmp / "kernels")]))
    assert km.kernel_spec.argv[0] == sys.executable

    default_out = REPO / "out" / "tutorial"
    before = _state(default_out)
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = NotebookClient(nb, km=km, timeout=CELL_TIMEOUT_S, allow_errors=True,
                            resources={"metadata": {"path": str(REPO)}})
    started = time.monotonic()
    client.execute()
    seconds = time.monotonic() - started
    print(f"\ntutorial.ipynb executed in {seconds:.1f} s")
    return {"nb": nb, "seconds": seconds, "out": out, "fmu": Path(native_fmu).resolve(),
            "default_out_before": before, "default_out_after": _state(default_out)}


def _outputs(nb):
    return [o for cell in nb.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]


def _stdout(nb) -> str:
    return "".join(o.get("text", "") for o in _outputs(nb) if o.output_type == "stream" and o.name == "stdout")


def test_committed_notebook_has_no_outputs():
    import nbformat

    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    dirty = [i for i, c in enumerate(nb.cells)
             if c.cell_type == "code" and (c.get("outputs") or c.get("execution_count") is not None)]
    assert not dirty, f"{NOTEBOOK.name}: code cells {dirty} carry outputs; clear them before committing"


def test_runs_without_errors_within_budget(executed):
    errors = [f"{o.ename}: {o.evalue}" for o in _outputs(executed["nb"]) if o.output_type == "error"]
    assert not errors, "the notebook raised:\n" + "\n".join(errors)
    assert executed["seconds"] < BUDGET_S, f"the notebook took {executed['seconds']:.0f} s"


def test_alarm_after_the_fault(executed):
    found = re.findall(r"first alarm at t = (\d+(?:\.\d+)?) s", _stdout(executed["nb"]))
    assert len(found) == 1, f"expected one 'first alarm at t = ... s' line, got {found}"
    # the fault is at 10 s; the monitor's measured alarm is 10.01 s, the paper's 14 s
    assert 10.0 < float(found[0]) < 12.0


def test_diagnosis_names_L2_at_1_1(executed):
    text = _stdout(executed["nb"])
    found = re.findall(r"diagnosed: (\w+) = (\d+\.\d+)", text)
    assert len(found) == 1, f"expected one 'diagnosed: NAME = VALUE' line, got {found}"
    name, value = found[0]
    assert name == "L2"
    # Case 2 sets L2 = 1.1 m; the fit's standard error is ~1e-12 m, the line prints 4 decimals
    assert float(value) == pytest.approx(1.1, abs=1e-4)
    assert re.search(r"diagnosis: L2 changed 1\.0+ → 1\.10* m", text)


def test_figures_and_live_view_rendered(executed):
    outputs = _outputs(executed["nb"])
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    # Figs. 6/12, 8, 3, the spectrum, 9, 10/11 and 13: one PNG each
    assert len(images) >= 7, f"{len(images)} figures rendered"
    panel = [o for o in outputs if any("holoviews" in mime for mime in o.get("data", {}))]
    assert panel, "the live view's Panel layout was not displayed"
    # the page replayed to the end of the 40 s run and shows the alarm of section 5
    text = _stdout(executed["nb"])
    alarm = re.findall(r"first alarm at t = (\d+\.\d+) s", text)
    assert alarm and f"page clock at t = 40.00 s of 40.00 s; banner: ALARM since t = {alarm[0]} s" in text


#: The figures the notebook saves into <output folder>/figures/, one per paper figure it draws.
SAVED_FIGURES = ("fig06_12_x2", "fig08_file_reads", "fig03_linkage", "fig09_spectrum", "fig09_forecast",
                 "fig10_11_forecast_zoom", "fig13_statistic")


def test_figures_are_saved_for_a_headless_run(executed):
    """`jupyter execute` keeps no output: every figure must also land in the output folder."""
    folder = executed["out"] / "figures"
    saved = sorted(p.stem for p in folder.glob("*.png")) if folder.is_dir() else []
    assert saved == sorted(SAVED_FIGURES)
    for name in SAVED_FIGURES:
        head = (folder / f"{name}.png").read_bytes()[:24]
        assert head[:8] == b"\x89PNG\r\n\x1a\n", name
        width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
        assert width > 300 and height > 150, (name, width, height)   # a drawn figure, not an empty canvas
        assert f"figure saved: {folder.resolve() / (name + '.png')}" in _stdout(executed["nb"])


def test_writes_only_into_its_folder(executed):
    text = _stdout(executed["nb"])
    assert f"output folder : {executed['out'].resolve()}" in text
    assert f"FMU: {executed['fmu']} " in text
    run = executed["out"] / "case2_fault_L2"
    for name in ("exchange.csv", "run.json", "monitor/summary.json", "diagnosis/diagnosis.json"):
        assert (run / name).is_file(), name
    assert executed["default_out_after"] == executed["default_out_before"], "the notebook changed out/tutorial"
