"""What a view draws a mechanism from: the joints' position outputs and the drawing annotation
of both FMUs of every shipped mechanism (fmu_src/mechanism/drawing.py).

- the annotation (``<VendorAnnotations><Tool name="fourbar-cosim"><Drawing>``) parses, sits
  where the FMI 2.0 schema puts it, names the file's bodies and joints, and every column it
  implies (``J_x J_y``, + ``J_gx J_gy J_gangle`` for a prismatic joint) is an output;
- physics: each joint's output is where the bodies' coordinates put both of its points (read
  from the mechanism file by the tests' independent reader, tests/mechanism_reference.py),
  Table 1's four-bar and the slider-crank written out by hand, a slider on its guide line, a
  length change mid-run seen in the positions;
- the two FMUs agree on them;
- a joint whose position output would take a variable's name is refused, naming the joint.
"""
from __future__ import annotations

import math
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu
from mechanism_reference import read_model
from support import REPO, swept_mechanisms
from test_mechanism_fmus import AGREE, SPAN, TIGHT

from fmu_src.mechanism.check import prepare_mechanism
from fmu_src.mechanism.description import MECHANISM_DIR, MechanismError, load_mechanism

MECHANISMS = swept_mechanisms()   # support.BENCHMARK_MECHANISMS: tested in their own files
KINDS = ("pythonfmu", "native")
#: A joint's output against a point the bodies' coordinates put there (m): the two points of a
#: joint coincide to the constraint residual (<= 1e-12, test_mechanism_fmus.RESIDUAL), and the
#: test's numpy arithmetic differs from the generated code's by a few ulps of coordinates of
#: ~10 m (~1e-14).  Measured <= 1.8e-15 m over every shipped mechanism and both FMUs (5 s, 1e-12).
POSITION = 1e-11
#: Short runs: rtol = atol = 1e-12 over 5 s (the brief's setting), outputs every 0.01 s.
STOP = 5.0
SLIDER = (MECHANISM_DIR / "slider_crank.toml").read_text()
FOURBAR = (MECHANISM_DIR / "fourbar.toml").read_text()


def _fmu(request, mechanism: str, kind: str) -> Path:
    """The FMU of a shipped mechanism: the four-bar's through fourbar_fmu / native_fmu (FOURBAR_FMU,
    FOURBAR_NATIVE_FMU), the others through mechanism_fmus."""
    if mechanism == "fourbar":
        return request.getfixturevalue("fourbar_fmu" if kind == "pythonfmu" else "native_fmu")
    return request.getfixturevalue("mechanism_fmus").get(mechanism, kind)


def _model_description(fmu: Path) -> ET.Element:
    with zipfile.ZipFile(fmu) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def _drawing(root: ET.Element) -> ET.Element:
    tools = [t for t in root.findall("./VendorAnnotations/Tool") if t.get("name") == "fourbar-cosim"]
    assert len(tools) == 1, "one fourbar-cosim tool entry in <VendorAnnotations>"
    drawings = tools[0].findall("Drawing")
    assert len(drawings) == 1
    return drawings[0]


def _columns(joint: ET.Element) -> list[str]:
    name = joint.get("name")
    suffixes = {"revolute": ["x", "y"], "prismatic": ["x", "y", "gx", "gy", "gangle"]}[joint.get("type")]
    return [f"{name}_{s}" for s in suffixes]


@pytest.fixture(scope="module")
def short_runs(request):
    """{(mechanism, kind): simulate_fmu's result} over STOP s at rtol = atol = 1e-12."""
    cache = {}

    def get(mechanism: str, kind: str):
        if (mechanism, kind) not in cache:
            cache[(mechanism, kind)] = simulate_fmu(str(_fmu(request, mechanism, kind)), stop_time=STOP,
                                                    output_interval=0.01,
                                                    start_values={"rtol": 1e-12, "atol": 1e-12})
        return cache[(mechanism, kind)]
    return get


# -- the annotation -------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_the_annotation_names_the_files_bodies_and_joints_and_its_columns_are_outputs(mechanism, kind, request):
    fmu = _fmu(request, mechanism, kind)
    root = _model_description(fmu)
    # FMI 2.0 schema order: ... DefaultExperiment, VendorAnnotations, ModelVariables
    tags = [child.tag for child in root]
    at = tags.index("VendorAnnotations")
    assert tags[at + 1] == "ModelVariables" and "DefaultExperiment" in tags[:at], tags
    drawing = _drawing(root)
    file = load_mechanism(mechanism)
    assert (drawing.get("schema"), drawing.get("mechanism")) == ("1", file.name)

    joints = drawing.findall("Joint")
    assert [(j.get("name"), j.get("type")) for j in joints] == [(j.name, j.type) for j in file.joints]
    on_ground = {j.name: "ground" in (j.first.body, j.second.body) for j in file.joints}
    assert {j.get("name"): j.get("ground") == "true" for j in joints} == on_ground
    assert all(j.get("ground") in (None, "true") for j in joints)

    bodies = drawing.findall("Body")
    assert [(b.get("name"), b.get("label"), b.get("kind")) for b in bodies] == \
        [(b.name, b.label, b.kind) for b in file.bodies]
    parameters = {p.name for p in file.parameters}
    for b in bodies:
        touching = {j.name for j in file.joints if b.get("name") in (j.first.body, j.second.body)}
        drawn = b.get("joints").split()
        assert len(drawn) == len(set(drawn)) and set(drawn) == touching, (b.get("name"), drawn, touching)
        used = b.get("parameters", "").split()
        assert used and set(used) <= parameters, (b.get("name"), used)

    outputs = {v.name: v for v in read_model_description(str(fmu)).modelVariables if v.causality == "output"}
    implied = [c for j in joints for c in _columns(j)]
    missing = [c for c in implied if c not in outputs]
    assert not missing, f"{fmu.name}: the drawing implies {missing}, which are not outputs"
    for c in implied:
        assert outputs[c].unit == ("rad" if c.endswith("_gangle") else "m")
        assert outputs[c].variability == "continuous"
    # appended after every other output, in the drawing's order
    names = list(outputs)
    assert names[-len(implied):] == implied


def test_the_drawing_of_table1_and_of_the_slider_crank(request, mechanism_fmus):
    """What the design names, attribute for attribute: a rod drawn from its tail, the slider's
    joints in file order, the parameters each body uses."""
    fourbar = _drawing(_model_description(request.getfixturevalue("fourbar_fmu")))
    assert [(b.get("name"), b.get("joints"), b.get("parameters")) for b in fourbar.findall("Body")] == \
        [("crank", "O2 A", "L2 m2"), ("coupler", "A B", "L3 m3"), ("rocker", "O4 B", "L4 m4")]
    slider = _drawing(_model_description(mechanism_fmus.get("slider_crank", "native")))
    assert [(b.get("name"), b.get("label"), b.get("kind"), b.get("joints"), b.get("parameters"))
            for b in slider.findall("Body")] == [("crank", "2", "rod", "O2 A", "L2 m2"),
                                                 ("rod", "3", "rod", "A B", "L3 m3"),
                                                 ("slider", "4", "block", "B P", "m4")]
    assert [(j.get("name"), j.get("type"), j.get("ground")) for j in slider.findall("Joint")] == \
        [("O2", "revolute", "true"), ("A", "revolute", None), ("B", "revolute", None), ("P", "prismatic", "true")]
    watt = _drawing(_model_description(mechanism_fmus.get("watt_sixbar", "native")))
    rocker = next(b for b in watt.findall("Body") if b.get("name") == "rocker")
    # the pin C lies between O4 (tail) and B (tip) on the rocker's axis; a4 places it
    assert (rocker.get("joints"), rocker.get("parameters")) == ("O4 C B", "L4 a4 m4")


@pytest.mark.parametrize("kind", KINDS)
def test_fmpy_validate_checks_where_the_annotation_sits(kind, request, tmp_path):
    """The FMU validates; the same FMU with <VendorAnnotations> moved before <CoSimulation> does
    not (so the schema check sees the position, and the test can fail)."""
    fmu = _fmu(request, "fourbar", kind)
    assert validate_fmu(str(fmu)) == []
    root = _model_description(fmu)
    annotation = root.find("VendorAnnotations")
    root.remove(annotation)
    root.insert(0, annotation)
    moved = tmp_path / fmu.name
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(moved, "w") as zout:
        for item in zin.infolist():
            data = ET.tostring(root, encoding="UTF-8", xml_declaration=True) \
                if item.filename == "modelDescription.xml" else zin.read(item)
            zout.writestr(item, data)
    problems = validate_fmu(str(moved))
    assert problems and any("not expected" in p for p in problems), problems


def test_the_four_bars_outputs_end_with_its_joints():
    """Every value reference of the FMUs before the drawing keeps its number: the 22 outputs of
    the file's [outputs] first (value references 13-34), then the joints' positions."""
    table = [o.name for o in prepare_mechanism("fourbar").equations.outputs]
    assert table == ["x2", "y2", "x3", "y3", "x4", "y4", "theta2", "theta3", "theta4", "omega2", "omega3", "omega4",
                     "energy", "constraint_residual", "O2_Fx", "O2_Fy", "A_Fx", "A_Fy", "B_Fx", "B_Fy",
                     "O4_Fx", "O4_Fy", "O2_x", "O2_y", "A_x", "A_y", "B_x", "B_y", "O4_x", "O4_y"]


# -- physics --------------------------------------------------------------------------------
def _rotation(theta: np.ndarray) -> np.ndarray:
    """Rotation matrices, shape (rows, 2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _point(run, model, attachment) -> np.ndarray | None:
    """Where the bodies' coordinates put an attachment (rows x 2), or None when the FMU does not
    output all of its body's coordinates (the slider-crank's slider has no y4 output)."""
    if attachment.body is None:
        return np.tile(attachment.local, (len(run), 1))
    body = model.bodies[attachment.body]
    names = [f"x{body.label}", f"y{body.label}"] + ([f"theta{body.label}"] if body.rotates else [])
    if not all(n in run.dtype.names for n in names):
        return None
    centre = np.column_stack([run[names[0]], run[names[1]]])
    theta = run[names[2]] if body.rotates else np.zeros(len(run))
    return centre + _rotation(theta) @ attachment.local


def _angle(run, model, attachment) -> np.ndarray | None:
    if attachment.body is None:
        return np.zeros(len(run))
    body = model.bodies[attachment.body]
    if not body.rotates:
        return np.zeros(len(run))
    name = f"theta{body.label}"
    return run[name] if name in run.dtype.names else None


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_each_joint_is_where_the_bodies_put_its_points(mechanism, kind, short_runs):
    run = short_runs(mechanism, kind)
    model = read_model(mechanism)
    checked = 0
    for joint in model.joints:
        at = np.column_stack([run[f"{joint.name}_x"], run[f"{joint.name}_y"]])
        points = [_point(run, model, a) for a in (joint.first, joint.second)]
        if joint.type == "revolute":
            expected = [p for p in points if p is not None]
        else:   # the sliding point is the joint's position, the first point is the guide's
            expected = [points[1]] if points[1] is not None else []
            guide = np.column_stack([run[f"{joint.name}_gx"], run[f"{joint.name}_gy"]])
            assert points[0] is not None, f"{joint.name}: the guide's body has no coordinate outputs"
            err = np.max(np.abs(guide - points[0]))
            assert err <= POSITION, f"{mechanism} {kind}: guide point of {joint.name} off by {err:.3g} m"
            first_angle = _angle(run, model, joint.first)
            assert first_angle is not None
            angle_err = np.max(np.abs(run[f"{joint.name}_gangle"] - (joint.angle + first_angle)))
            # an angle plus a constant: round-off only
            assert angle_err <= 1e-13, f"{mechanism} {kind}: {joint.name}_gangle off by {angle_err:.3g} rad"
        assert expected or joint.type == "prismatic", f"{joint.name}: no point of it can be checked"
        for p in expected:
            err = float(np.max(np.abs(at - p)))
            assert err <= POSITION, f"{mechanism} {kind}: joint {joint.name} off by {err:.3g} m"
            checked += 1
    assert checked >= len(model.joints)
    # it moves: a joint that is not on the ground travels, so a constant output would fail
    travel = max(float(np.ptp(run[f"{j.name}_x"])) for j in model.joints)
    assert travel > 0.1


@pytest.mark.parametrize("kind", KINDS)
def test_table1_four_bar_by_hand(kind, short_runs):
    """O2 = (0, 0), A = L2 (cos theta2, sin theta2), O4 = (L1, 0), |B - A| = L3, |B - O4| = L4."""
    run = short_runs("fourbar", kind)
    L1, L2, L3, L4 = 3.0, 1.0, 4.0, 2.5
    O2, A, B, O4 = (np.column_stack([run[f"{j}_x"], run[f"{j}_y"]]) for j in ("O2", "A", "B", "O4"))
    theta2 = run["theta2"]
    assert np.max(np.abs(O2)) <= POSITION
    assert np.max(np.abs(A - L2 * np.column_stack([np.cos(theta2), np.sin(theta2)]))) <= POSITION
    assert np.max(np.abs(O4 - [L1, 0.0])) <= POSITION
    assert np.max(np.abs(np.hypot(*(B - A).T) - L3)) <= POSITION
    assert np.max(np.abs(np.hypot(*(B - O4).T) - L4)) <= POSITION
    assert np.ptp(theta2) > 1.0        # the crank swings


def _distance_to_guide(run, joint: str) -> np.ndarray:
    """Distance (m) of the joint's point from the line through (J_gx, J_gy) at J_gangle."""
    u = np.column_stack([np.cos(run[f"{joint}_gangle"]), np.sin(run[f"{joint}_gangle"])])
    d = np.column_stack([run[f"{joint}_x"] - run[f"{joint}_gx"], run[f"{joint}_y"] - run[f"{joint}_gy"]])
    return np.abs(u[:, 0] * d[:, 1] - u[:, 1] * d[:, 0])


@pytest.mark.parametrize("kind", KINDS)
def test_the_slider_stays_on_its_guide_line(kind, short_runs):
    """The slider-crank: the pin P on the horizontal line through (0, e), the rod from A to B of
    length L3, A on the crank's circle."""
    run = short_runs("slider_crank", kind)
    e, L2, L3 = 0.0, 1.0, 4.0
    assert np.max(_distance_to_guide(run, "P")) <= POSITION
    assert np.all(run["P_gx"] == 0.0) and np.all(run["P_gy"] == e) and np.all(run["P_gangle"] == 0.0)
    A, B, P = (np.column_stack([run[f"{j}_x"], run[f"{j}_y"]]) for j in ("A", "B", "P"))
    assert np.max(np.abs(B - P)) <= POSITION
    assert np.max(np.abs(np.hypot(*A.T) - L2)) <= POSITION
    assert np.max(np.abs(np.hypot(*(B - A).T) - L3)) <= POSITION
    assert np.ptp(run["P_x"]) > 1.0     # it slides


@pytest.mark.parametrize("kind", KINDS)
def test_a_length_change_moves_the_joint(kind, request):
    """Table 1's fault at 1 s (L2 1.0 -> 1.1 m): |A - O2| is 1.0 m before and 1.1 m after it (the
    row at 1 s still shows the old state)."""
    fmu = _fmu(request, "fourbar", kind)
    signal = np.array([(0.0, 1.0), (1.0, 1.0), (1.0, 1.1)], dtype=[("time", float), ("L2", float)])
    run = simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.01, start_values={"rtol": 1e-12, "atol": 1e-12},
                       input=signal, output=["O2_x", "O2_y", "A_x", "A_y", "x2", "y2", "theta2"])
    crank = np.hypot(run["A_x"] - run["O2_x"], run["A_y"] - run["O2_y"])
    t = run["time"]
    before, after = t <= 1.0 + 1e-9, t >= 1.01 - 1e-9
    assert np.max(np.abs(crank[before] - 1.0)) <= POSITION
    assert np.max(np.abs(crank[after] - 1.1)) <= POSITION
    # the crank's centre moved out with it: A is the tip of the new crank
    tip = np.column_stack([run["x2"] + 0.55 * np.cos(run["theta2"]), run["y2"] + 0.55 * np.sin(run["theta2"])])
    assert np.max(np.abs(tip[after] - np.column_stack([run["A_x"], run["A_y"]])[after])) <= POSITION


def test_a_guide_that_turns_with_its_body(tmp_path):
    """A bead sliding on a line through the middle of a swinging arm, 15 deg off the arm's axis:
    J_gangle = theta_arm + 15 deg, the guide point is the arm's centre and the bead stays on
    the line, at the start and after 1 s of motion (in-process, the generated Python)."""
    from fmu_src.mechanism.check import start_state
    from fmu_src.mechanism_model.dae import MechanismDAE

    path = tmp_path / "bead.toml"
    path.write_text("""
[mechanism]
name = "Bead"
gravity = "g"
[parameters]
L2 = { value = 2.0, unit = "m", positive = true }
m2 = { value = 1.0, unit = "kg", positive = true }
m3 = { value = 0.5, unit = "kg", positive = true }
J3 = { value = 0.01, unit = "kg.m2", positive = true }
g = { value = 9.81, unit = "m/s2" }
[ground.points]
O = [0, 0]
[[bodies]]
name = "arm"
label = "2"
kind = "rod"
length = "L2"
mass = "m2"
angle = 30
[[bodies]]
name = "bead"
label = "3"
kind = "block"
mass = "m3"
inertia = "J3"
angle = 30
x = 1.5
y = 1.2
points = { pin = [0, 0] }
[[joints]]
name = "O"
type = "revolute"
connects = ["ground.O", "arm.tail"]
[[joints]]
name = "S"
type = "prismatic"
connects = ["arm.centre", "bead.pin"]
angle = 15
[start]
theta2 = { value = 30, unit = "deg" }
x3 = { value = 1.5, unit = "m" }
""")
    checked = prepare_mechanism(str(path))
    names = [o.name for o in checked.equations.outputs]
    assert names[-7:] == ["O_x", "O_y", "S_x", "S_y", "S_gx", "S_gy", "S_gangle"]
    module = checked.module
    guess, rates, p = start_state(module)
    dae = MechanismDAE(module, p, rtol=1e-12, atol=1e-12)
    dae.assemble(0.0, guess, rates)
    dae.start()
    for t in (0.0, 0.5, 1.0):
        if t:
            dae.advance(t)
        out = dict(zip(names, dae.outputs(forces=False)))
        # one constant added to an angle: round-off only
        assert out["S_gangle"] == pytest.approx(out["theta2"] + math.radians(15), abs=1e-14)
        assert (out["S_gx"], out["S_gy"]) == pytest.approx((out["x2"], out["y2"]), abs=POSITION)
        u = (math.cos(out["S_gangle"]), math.sin(out["S_gangle"]))
        d = (out["S_x"] - out["S_gx"], out["S_y"] - out["S_gy"])
        assert abs(u[0] * d[1] - u[1] * d[0]) <= POSITION
        assert (out["S_x"], out["S_y"]) == pytest.approx((out["x3"], out["y3"]), abs=POSITION)
    assert abs(out["theta2"] - math.radians(30)) > 0.01      # the arm has swung


# -- the two FMUs -----------------------------------------------------------------------------
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_the_two_fmus_agree_on_the_joints(mechanism, request):
    """The tolerance and spans of test_mechanism_fmus's agreement test (rtol = atol = TIGHT);
    measured 3.6e-15 (driven four-bar) to 4.7e-12 m (five-bar, over its 5 s)."""
    python_fmu, native_fmu = _fmu(request, mechanism, "pythonfmu"), _fmu(request, mechanism, "native")
    columns = [c for j in _drawing(_model_description(native_fmu)).findall("Joint") for c in _columns(j)]
    stop = SPAN.get(mechanism, 20.0)
    runs = [simulate_fmu(str(f), stop_time=stop, output_interval=0.01, start_values={"rtol": TIGHT, "atol": TIGHT},
                         output=columns) for f in (python_fmu, native_fmu)]
    worst = max(float(np.max(np.abs(runs[0][c] - runs[1][c]))) for c in columns)
    assert worst <= AGREE, (mechanism, worst)


# -- a name clash ----------------------------------------------------------------------------
CLASHES = [
    ("a parameter named like a joint's x", FOURBAR,
     ('g = { value = 9.81,', 'A_x = { value = 0.0, unit = "m" }\ng = { value = 9.81,'), ["joints[1] 'A'", "'A_x'"]),
    ("a parameter named like a guide's angle", SLIDER,
     ('g = { value = 9.81,', 'P_gangle = { value = 0.0 }\ng = { value = 9.81,'), ["joints[3] 'P'", "'P_gangle'"]),
]


@pytest.mark.parametrize("case", CLASHES, ids=[c[0] for c in CLASHES])
def test_a_joint_whose_position_takes_a_variables_name_is_refused(case, tmp_path):
    _, base, (old, new), words = case
    assert old in base
    path = tmp_path / "mine.toml"
    path.write_text(base.replace(old, new, 1))
    with pytest.raises(MechanismError) as info:
        prepare_mechanism(str(path))
    message = str(info.value)
    assert all(w in message for w in [str(path), *words]), message
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "build_fmu.py", "--mechanism", str(path), "--out", str(out / "a.fmu"),
                           "--native-out", str(out / "b.fmu")], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc
    assert all(w in proc.stderr for w in words), proc.stderr
    assert not out.exists() or not any(out.iterdir())


def test_outputs_may_not_list_a_joints_position(tmp_path):
    """They always come after the listed outputs; listing one would move it."""
    path = tmp_path / "mine.toml"
    path.write_text(SLIDER.replace('"P_Fy"]', '"P_Fy", "A_x"]'))
    with pytest.raises(MechanismError, match=r"\[outputs\]: 'A_x': the joints' positions are always outputs"):
        prepare_mechanism(str(path))
