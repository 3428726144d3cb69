"""The drawing's one home (fourbar_common.drawing) and how it travels: from the FMU's vendor
annotation through the case validation into run.json, and back (issue 25's data path).

The FMUs with a drawing are checked where they are built (tests/test_fmu_drawing.py); here a
drawing is injected into a copy of an FMU, so the orchestrator's handling is tested on
annotations the build would never write (malformed ones, ones naming missing columns).
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pytest

from fourbar_common import Drawing, DrawingError, DrawnBody, DrawnJoint
from fourbar_common.contract.run_record import (RecordedExchange, RecordedExperiment, RecordedFmu, RecordedWriter,
                                               RunRecord, RunRecordError, read_run_record)

FOURBAR = Drawing(
    mechanism="FourBar",
    bodies=(DrawnBody("crank", "2", "rod", ("O2", "A"), ("L2", "m2")),
            DrawnBody("coupler", "3", "rod", ("A", "B"), ("L3", "m3")),
            DrawnBody("rocker", "4", "rod", ("B", "O4"), ("L4", "m4"))),
    joints=(DrawnJoint("O2", "revolute", True), DrawnJoint("A", "revolute"), DrawnJoint("B", "revolute"),
            DrawnJoint("O4", "revolute", True)))

ANNOTATION = """<VendorAnnotations><Tool name="fourbar-cosim"><Drawing schema="1" mechanism="FourBar">
  <Body name="crank" label="2" kind="rod" joints="O2 A" parameters="L2 m2"/>
  <Body name="coupler" label="3" kind="rod" joints="A B" parameters="L3 m3"/>
  <Body name="rocker" label="4" kind="rod" joints="B O4" parameters="L4 m4"/>
  <Joint name="O2" type="revolute" ground="true"/><Joint name="A" type="revolute"/>
  <Joint name="B" type="revolute"/><Joint name="O4" type="revolute" ground="true"/>
</Drawing></Tool></VendorAnnotations>"""


def _model_description(annotation: str) -> str:
    return f'<?xml version="1.0"?>\n<fmiModelDescription fmiVersion="2.0" modelName="M" guid="x">{annotation}' \
           f'<ModelVariables/></fmiModelDescription>'


# -- the schema ---------------------------------------------------------------------------------------------

def test_the_annotation_reads_as_the_drawing_and_survives_json():
    drawing = Drawing.from_model_description(_model_description(ANNOTATION))
    assert drawing == FOURBAR
    assert Drawing.from_json(json.loads(json.dumps(drawing.to_json()))) == drawing
    assert drawing.columns == ("O2_x", "O2_y", "A_x", "A_y", "B_x", "B_y", "O4_x", "O4_y")
    assert [b.name for b in drawing.bodies_changed_by("L3")] == ["coupler"]
    # a prismatic joint also has its guide line
    assert DrawnJoint("P", "prismatic", True).columns == ("P_x", "P_y", "P_gx", "P_gy", "P_gangle")


def test_a_model_description_without_the_annotation_has_no_drawing():
    assert Drawing.from_model_description(_model_description("")) is None
    other_tool = '<VendorAnnotations><Tool name="someone-else"><Drawing schema="1"/></Tool></VendorAnnotations>'
    assert Drawing.from_model_description(_model_description(other_tool)) is None


@pytest.mark.parametrize("edit, named", [
    (('schema="1"', 'schema="2"'), "schema"),
    (('kind="rod" joints="O2 A"', 'kind="wheel" joints="O2 A"'), "bodies[0].kind"),
    (('type="revolute" ground="true"/><Joint name="A"', 'type="ball" ground="true"/><Joint name="A"'), "joints[0].type"),
    (('joints="A B"', 'joints="A Q"'), "names joint(s) Q"),
    (('<Joint name="A" type="revolute"/>', '<Joint name="A" type="revolute"/><Joint name="A" type="revolute"/>'),
     "declared twice"),
    (('ground="true"/><Joint name="A"', 'ground="yes"/><Joint name="A"'), "ground = 'yes'"),
    (('joints="O2 A" parameters', 'joints="" parameters'), "bodies[0].joints"),
])
def test_a_malformed_annotation_is_refused_naming_what_is_wrong(edit, named):
    old, new = edit
    assert old in ANNOTATION
    with pytest.raises(DrawingError, match="M.xml: the fourbar-cosim drawing") as info:
        Drawing.from_model_description(_model_description(ANNOTATION.replace(old, new, 1)), "M.xml")
    assert named in str(info.value)


def test_run_json_keeps_the_drawing_and_names_a_broken_one():
    record = RunRecord(status="finished", run_id="0" * 32, case="c", fmu=RecordedFmu("F.fmu", "g", "FourBar"),
                       experiment=RecordedExperiment(0.0, 1.0, 0.01), exchange=RecordedExchange(1.0, 0.0, 100),
                       writer=RecordedWriter(1, "h", 2.0), started_at="2026-11-24T00:00:00Z", drawing=FOURBAR)
    data = record.to_json()
    assert RunRecord.from_json(json.loads(json.dumps(data))).drawing == FOURBAR
    # written before drawings: no key at all
    del data["drawing"]
    assert RunRecord.from_json(data).drawing is None
    data["drawing"] = {**FOURBAR.to_json(), "joints": [{"name": "O2", "type": "hinge"}]}
    with pytest.raises(RunRecordError, match=r"run.json: field 'drawing': field 'joints\[0\].type' = 'hinge'"):
        RunRecord.from_json(data)


# -- the orchestrator ---------------------------------------------------------------------------------------

def _with_annotation(fmu: Path, dest: Path, annotation: str) -> Path:
    """A copy of ``fmu`` whose model description carries ``annotation`` before ModelVariables."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as out:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode("utf-8")
                assert "<VendorAnnotations>" not in text, "this FMU has its own drawing: inject into one without"
                data = text.replace("<ModelVariables>", annotation + "\n<ModelVariables>", 1).encode("utf-8")
            out.writestr(item, data)
    return dest


def _fmu_without_drawing(fmu: Path, tmp: Path) -> Path:
    """``fmu`` without its drawing annotation, if it has one (the build adds it)."""
    with zipfile.ZipFile(fmu) as z:
        text = z.read("modelDescription.xml").decode("utf-8")
    start = text.find("<VendorAnnotations>")
    if start < 0:
        return fmu
    end = text.index("</VendorAnnotations>") + len("</VendorAnnotations>")
    dest = tmp / "plain.fmu"
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as out:
        for item in src.infolist():
            data = src.read(item)
            out.writestr(item, (text[:start] + text[end:]).encode("utf-8") if item.filename == "modelDescription.xml"
                         else data)
    return dest


def _case(path: Path, fmu: Path, outputs: str = "") -> Path:
    path.write_text(f'fmu = {json.dumps(fmu.as_posix())}\n[experiment]\nstop = 0.2\nstep = 0.01\n{outputs}',
                    encoding="utf-8")
    return path


def test_an_fmu_without_a_drawing_runs_as_before(native_fmu, tmp_path):
    from orchestrator import load_case, run_case

    plain = _fmu_without_drawing(native_fmu, tmp_path)
    case = load_case(_case(tmp_path / "c.toml", plain))
    assert case.drawing is None and case.recorded == ("x2", "y2", "x3", "y3", "x4", "y4")
    result = run_case(case, tmp_path / "out")
    assert result.ok, result.error
    assert read_run_record(result.run_json_path).drawing is None
    assert json.loads(result.run_json_path.read_text())["drawing"] is None


@pytest.mark.parametrize("annotation, message", [
    (ANNOTATION.replace('kind="rod" joints="O2 A"', 'kind="wheel" joints="O2 A"'),
     "the fourbar-cosim drawing: field 'bodies[0].kind' = 'wheel'"),
    (ANNOTATION.replace('joints="B O4"', 'joints="B Z"').replace('<Joint name="B" type="revolute"/>',
                                                                '<Joint name="B" type="revolute"/><Joint name="Z" type="revolute"/>'),
     "its drawing places joints by Z_x, Z_y, which"),
])
def test_an_fmu_whose_drawing_cannot_be_used_is_refused_with_the_fix(native_fmu, tmp_path, annotation, message):
    """A malformed annotation, or one naming a joint the FMU does not place: refused naming the
    FMU and the way out ([outputs] drawing = false), and that way out works."""
    from orchestrator import ConfigError, load_case

    fmu = _with_annotation(_fmu_without_drawing(native_fmu, tmp_path), tmp_path / "annotated.fmu", annotation)
    with pytest.raises(ConfigError) as info:
        load_case(_case(tmp_path / "c.toml", fmu))
    text = str(info.value)
    assert message in text and "[outputs] drawing = false" in text, text
    case = load_case(_case(tmp_path / "off.toml", fmu, '[outputs]\nvariables = ["x2"]\ndrawing = false\n'))
    assert case.drawing is None and case.recorded == ("x2",) and case.as_dict()["outputs"]["drawing"] is False


def test_a_drawing_flag_that_is_not_a_boolean_is_refused(native_fmu, tmp_path):
    from orchestrator import ConfigError, load_case

    with pytest.raises(ConfigError, match=r'outputs.drawing = "yes": expected true'):
        load_case(_case(tmp_path / "c.toml", native_fmu, '[outputs]\nvariables = ["x2"]\ndrawing = "yes"\n'))


def test_the_drawings_columns_are_recorded_after_the_named_outputs(native_fmu, tmp_path):
    """On an FMU that declares a drawing: its columns follow the outputs the case names (none
    twice), run.json keeps the drawing, and the columns hold where the joints are."""
    import numpy as np
    import pandas as pd
    from orchestrator import load_case, run_case

    probe = load_case(_case(tmp_path / "probe.toml", native_fmu))
    if probe.drawing is None:
        pytest.skip("this FMU declares no drawing (built before drawings)")
    case = load_case(_case(tmp_path / "c.toml", native_fmu, '[outputs]\nvariables = ["x2", "A_x", "theta2"]\n'))
    columns = case.drawing.columns
    assert case.outputs == ("x2", "A_x", "theta2")       # A_x is one of the drawing's: not twice
    assert case.recorded == ("x2", "A_x", "theta2", *[c for c in columns if c != "A_x"])
    assert load_case(_case(tmp_path / "again.toml", native_fmu)).recorded[6:] == columns
    result = run_case(case, tmp_path / "out")
    assert result.ok, result.error
    record = read_run_record(result.run_json_path)
    assert record.drawing == case.drawing and record.outputs == case.recorded
    rows = pd.read_csv(result.exchange_path)
    assert list(rows.columns) == ["time", *case.recorded]
    # The crank's tip is L2 (Table 1: 1 m) from its pivot at the origin: the joint columns are
    # positions, not some other output (1e-9 m: the constraint holds to ~1e-12 m).
    tip = np.hypot(rows["A_x"] - rows["O2_x"], rows["A_y"] - rows["O2_y"])
    assert np.max(np.abs(tip - 1.0)) < 1e-9
