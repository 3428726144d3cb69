"""fourbar-view on a system run (issue 40, point 6): the mechanism component's drawing and the
component signals.

One short run of the shipped bench (build/MotorFourBar.ssp, or built once: the ``bench_ssp``
fixture), 1 s at its 1 ms macro step (~1 s of CPU), recording the four-bar's crank speed and
every connected output (read from the .ssp, so the test needs of the bench only a four-bar
component named ``fourbar``), with the crank's length stepped from 1.0 to 1.1 m at 0.5 s.
Checked: run.json names the component whose drawing it keeps, and that drawing is the
component FMU's own with its names in the system's (``fourbar.A_x``); the joints it places
are the crank's length apart before and after the step (the drawing reads the right
columns); the faulted body is the crank; the view's data layer groups the recorded signals per
component; the headless page draws the mechanism and streams each component's signals.
"""
from __future__ import annotations

import io
import json
import signal
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fourbar_common.contract.run_record import RunRecordError, read_run_record
from fourbar_common.drawing import Drawing

MECHANISM = "fourbar"        # the bench's four-bar component
STOP, STEP = 1.0, 0.001
FAULT_TIME, L2_BEFORE, L2_AFTER = 0.5, 1.0, 1.1
AT = 0.8                     # s: where the headless page is opened


def _connected_outputs(ssp: Path) -> list[str]:
    from orchestrator.ssp import read_ssp

    return list(dict.fromkeys(c.source for c in read_ssp(ssp).connections))


@pytest.fixture(scope="module")
def system_run(bench_ssp, tmp_path_factory) -> Path:
    from orchestrator import run_case

    folder = tmp_path_factory.mktemp("view_system")
    outputs = list(dict.fromkeys([f"{MECHANISM}.omega2", *_connected_outputs(bench_ssp)]))
    case = folder / "bench.toml"
    case.write_text(f'name = "bench"\nsystem = {json.dumps(str(bench_ssp))}\n'
                    f"[parameters]\n'{MECHANISM}.L2' = {L2_BEFORE!r}\n"
                    f"[experiment]\nstop = {STOP!r}\nstep = {STEP!r}\n"
                    f"[outputs]\nvariables = {json.dumps(outputs)}\n"
                    f'[[events]]\ntype = "step"\ntime = {FAULT_TIME!r}\nvariable = "{MECHANISM}.L2"\n'
                    f"value = {L2_AFTER!r}\n", encoding="utf-8")
    result = run_case(case, folder / "out")
    assert result.status == "finished", result.error
    return folder / "out"


def test_run_json_names_the_drawn_component_and_keeps_its_drawing(system_run, bench_ssp):
    from orchestrator.ssp import component_bytes, read_ssp

    record = read_run_record(system_run / "run.json")
    assert record.system is not None and record.system.drawing == MECHANISM
    ssp = read_ssp(bench_ssp)
    with zipfile.ZipFile(io.BytesIO(component_bytes(ssp, MECHANISM))) as z:
        own = Drawing.from_model_description(z.read("modelDescription.xml"))
    assert own is not None and record.drawing == own.in_component(MECHANISM)
    assert all(c.startswith(f"{MECHANISM}.") for c in record.drawing.columns)
    header = pd.read_csv(system_run / "exchange.csv", nrows=0).columns
    assert set(record.drawing.columns) <= set(header)
    # the other components declare no drawing: only the four-bar's is recorded
    assert {c.name for c in record.system.components} - {MECHANISM}


def test_the_drawing_places_the_crank_at_its_length_before_and_after_the_fault(system_run):
    from view.geometry import Geometry, faulted_bodies

    record = read_run_record(system_run / "run.json")
    rows = pd.read_csv(system_run / "exchange.csv")
    geometry = Geometry(record.drawing)
    assert geometry.lacking(rows.columns) == []
    crank = next(b for b in record.drawing.bodies if f"{MECHANISM}.L2" in b.parameters)
    p, q = crank.joints
    length = np.hypot(rows[f"{p}_x"] - rows[f"{q}_x"], rows[f"{p}_y"] - rows[f"{q}_y"]).to_numpy()
    before, after = rows["time"] < FAULT_TIME - STEP / 2, rows["time"] > FAULT_TIME + STEP / 2
    # the joint positions are the FMU's outputs, computed from the crank angle and L2:
    # round-off only (1e-12 m on lengths of 1 m)
    np.testing.assert_allclose(length[before.to_numpy()], L2_BEFORE, atol=1e-12)
    np.testing.assert_allclose(length[after.to_numpy()], L2_AFTER, atol=1e-12)
    assert faulted_bodies(record.drawing, [e.variable for e in record.events]) == {crank.name}
    scene = geometry.scene(rows)
    frame = geometry.frame(rows.iloc[-1], scene)
    assert {s.name for s in frame.bodies} == {b.name for b in record.drawing.bodies}


def test_the_data_layer_groups_the_recorded_signals_by_component(system_run):
    from view.sources import RunFolder
    from view.timeline import Timeline

    timeline = Timeline()
    timeline.feed(RunFolder(system_run).poll())
    record = timeline.record
    groups = timeline.components
    assert [g.component for g in groups] == [c.name for c in record.system.components
                                             if any(o.startswith(f"{c.name}.") for o in record.outputs)]
    signals = [o for o in record.outputs if o not in set(record.drawing.columns)]
    assert len(signals) >= 2                # the crank's speed and the connected outputs at least
    assert sorted(s for g in groups for s in g.signals) == sorted(signals)
    assert all(s.partition(".")[0] == g.component for g in groups for s in g.signals)


def test_the_page_draws_the_mechanism_and_plots_each_component(system_run):
    from view.page import PageSettings, RunPage, SharedRun

    page = RunPage(SharedRun(system_run, poll_s=0.0), PageSettings(at=AT, window_s=0.5))
    page.tick()
    rows = pd.read_csv(system_run / "exchange.csv")
    assert len(page.src["bodies"].data["xs"]) == len(read_run_record(system_run / "run.json").drawing.bodies)
    assert page.mechanism.title.text.endswith(f"t = {AT:.2f} s")
    groups = page.timeline.components
    assert groups and len(page.component_plots.objects) == len(groups)
    window = rows[(rows["time"] > AT - 0.5 + 1e-9) & (rows["time"] <= AT + 1e-9)]
    for group in groups:
        data = page.src[f"component_{group.component}"].data
        np.testing.assert_array_equal(np.asarray(data["time"]), window["time"].to_numpy())
        for signal in group.signals:
            np.testing.assert_array_equal(np.asarray(data[signal]), window[signal].to_numpy())
    record = page.timeline.record
    assert f"system {record.system.name} (" in page.facts.object


def test_an_animation_of_the_system_run_draws_the_mechanism(system_run, tmp_path):
    from view.animate import animate

    result = animate(system_run, tmp_path / "bench.gif", fps=4, start=0.5, stop=1.0, width_px=320)
    record = read_run_record(system_run / "run.json")
    assert result.not_drawn is None and result.frames == 3
    # the signal beside it is a recorded output, not a joint coordinate
    assert result.signal in record.outputs and result.signal not in record.drawing.columns


def test_a_drawing_of_an_unknown_component_is_named(system_run, tmp_path):
    data = json.loads((system_run / "run.json").read_text())
    data["system"]["drawing"] = "nobody"
    (tmp_path / "run.json").write_text(json.dumps(data))
    with pytest.raises(RunRecordError, match=r"system\.drawing.*'nobody'.*expected null or the name of a component"):
        read_run_record(tmp_path / "run.json")


@pytest.mark.slow
def test_the_served_page_shows_the_system_in_a_browser(system_run):
    """The real fourbar-view, read by headless Chromium (tests/test_view_browser.py's pattern):
    the mechanism from the component's joint columns, a plot per component, no console error."""
    import subprocess
    import sys

    from view.headless import chromium_path, launch

    if chromium_path() is None:
        pytest.skip("no Chromium: `make browser` installs Debian's chromium (make test does it)")
    from playwright.sync_api import sync_playwright

    record = read_run_record(system_run / "run.json")
    rows = pd.read_csv(system_run / "exchange.csv")
    view = subprocess.Popen([str(Path(sys.executable).parent / "fourbar-view"), str(system_run), "--quiet",
                             "--at", str(AT)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = view.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), url
        with sync_playwright() as p:
            browser = launch(p)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 1400})
                errors: list[str] = []
                page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
                page.on("pageerror", lambda e: errors.append(str(e)))
                page.goto(url)
                page.wait_for_selector("#state", timeout=30_000)
                data = ("(name) => { const s = Bokeh.documents[0].get_model_by_name(name);"
                        " return s ? Object.fromEntries(Object.entries(s.data).map(([k, v]) => [k, Array.from(v)]))"
                        " : null; }")
                page.wait_for_function("() => { const s = Bokeh.documents[0].get_model_by_name('joints');"
                                       " return s && s.data.x.length > 0; }", timeout=30_000)
                joints = page.evaluate(data, "joints")
                row = rows[rows["time"] == joints["time"][0]].iloc[0]
                for name, x, y in zip(joints["name"], joints["x"], joints["y"]):
                    assert (x, y) == (row[f"{name}_x"], row[f"{name}_y"]), name   # the CSV's 17 digits
                assert sorted(joints["name"]) == sorted(j.name for j in record.drawing.joints)
                from view.components import component_signals

                for group in component_signals(record, rows.columns):
                    held = page.evaluate(data, f"component_{group.component}")
                    assert held is not None and set(group.signals) <= set(held) and len(held["time"]) > 0, group
                assert errors == [], errors
                page.screenshot(path=str(system_run.parent / "view_system.png"))
            finally:
                browser.close()
    finally:
        view.send_signal(signal.SIGTERM)
        try:
            _, err = view.communicate(timeout=30)
        except subprocess.TimeoutExpired:          # a hang guard: the test fails below
            view.kill()
            _, err = view.communicate()
    assert view.returncode == 143 and "Traceback" not in err, err
