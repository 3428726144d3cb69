"""A mechanism file is data: its expressions are parsed, never run (issue 36, item 1).

Every entry of tests/corpus/mechanism_expressions.toml (injections, bombs, non-finite numbers,
and the expressions the docs use) is put into a rod's length and into a ground point's
coordinate of the shipped four-bar and loaded through ``load_mechanism``, in an empty working
directory: it loads or is refused (MechanismError naming the file, the field and the text) as
the corpus says, and nothing appears in the directory (the injections write ``canary*`` files
when they run).  A few go through ``build_fmu.py --mechanism FILE``: exit 2, the message, no
traceback, no FMU.  Hypothesis then feeds random text (only MechanismError may come out) and
random well-formed arithmetic (the loaded expression's value equals Python's float arithmetic
on the same numbers within the float evaluation's own error bound).

Hang guards only (pytest-timeout, subprocess timeouts): how fast a refusal is, is measured by
benchmarks/untrusted_expressions.py, not asserted here.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import REPO

from fmu_src.mechanism.description import Mechanism, MechanismError, load_mechanism
from fmu_src.mechanism.expressions import MAX_MAGNITUDE
from corpus.mechanism_corpus import BASE, FIELDS, corpus, mechanism_file, shown, toml_string

#: The fourbar's parameters (SI), as its file gives them.
VALUES = {"L1": 3.0, "L2": 1.0, "L3": 4.0, "L4": 2.5, "m2": 1.0, "m3": 1.0, "m4": 1.0, "g": 9.81}


def value_of(expr) -> float:
    """An expression's value at the file's parameters, by sympy at 30 digits (not the parser's floats)."""
    values = {sp.Symbol(k, real=True): sp.Float(v, 30) for k, v in VALUES.items()}
    return complex(sp.sympify(expr, strict=True).xreplace(values).evalf(30))


CASES = corpus()


def test_the_corpus_has_what_issue_36_lists():
    texts = {c.text for c in CASES}
    for listed in ("__import__('os').system('id > canary_system') * 0 + L3", "open('/etc/passwd').read()",
                   "10**10**10", "9**9**9**9", "zoo", "oo", "nan", "I", "1/0", "1e400", "exp(1000)", "lambda: 0"):
        assert listed in texts
    assert {c.expect for c in CASES} == {"load", "refuse"}
    assert sum(c.expect == "load" for c in CASES) >= 5 and len(CASES) >= 100


@pytest.mark.timeout(60)     # a hang guard only: each load or refusal takes milliseconds
@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("case", CASES, ids=[c.label for c in CASES])
def test_corpus_entry_loads_or_is_refused_without_side_effect(case, field, tmp_path, monkeypatch):
    path = mechanism_file(tmp_path, case.text, field)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    try:
        result = load_mechanism(path)
    except MechanismError as exc:
        result = exc
    assert os.getcwd() == str(work)
    assert sorted(os.listdir(work)) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["untrusted.toml", "work"]
    if case.expect == "refuse":
        assert isinstance(result, MechanismError), f"{case.text[:80]!r} was accepted"
        message = str(result)
        assert message.startswith(f"{path}: {FIELDS[field][0]}: {shown(case.text)}"), message
    else:
        assert isinstance(result, Mechanism), f"{case.text[:80]!r} refused: {result}"
        expr = result.body("crank").length if field == "length" else result.ground["O4"][0]
        value = value_of(expr)
        assert value.imag == 0 and math.isfinite(value.real)


@pytest.mark.slow
@pytest.mark.parametrize("text", ["__import__('os').system('id > canary_system') * 0 + L3", "10**10**10",
                                  "exec('import os; os.system(\"touch canary_exec\")')",
                                  "(" * 100000 + "L2" + ")" * 100000, "exp(1000)",
                                  "L2\n__import__('os').system('touch canary_newline')"])
def test_build_fmu_refuses_with_exit_2_naming_file_field_and_text(text, tmp_path):
    path = mechanism_file(tmp_path, text)
    work = tmp_path / "work"
    work.mkdir()
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(path), "--only", "pythonfmu",
                           "--out", str(tmp_path / "X.fmu"), "--no-validate"], cwd=work, capture_output=True,
                          text=True, timeout=120)     # a hang guard: the refusal comes before any build work
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith(f"build_fmu.py: error: {path}: bodies[0] 'crank'.length: {shown(text)}"), proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert os.listdir(work) == [] and not (tmp_path / "X.fmu").exists()


# -- property-based: random text, random arithmetic ---------------------------------------------------------------
def load_text(text: str, field: str = "length"):
    """The loaded Mechanism, or the MechanismError; anything else propagates (and fails the test)."""
    with tempfile.TemporaryDirectory() as folder:
        try:
            return load_mechanism(mechanism_file(Path(folder), text, field))
        except MechanismError as exc:
            return exc


_ALPHABET = st.sampled_from(list("L1234 ()+-*/.,e_9") + ["**", "sqrt", "sin", "cos", "pi", "m2", "g", "__", "'",
                                                          "\n", ";", "import", "\\", "x", "1e999", "\u2112"])


@pytest.mark.timeout(300)
@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(st.text(max_size=60), st.lists(_ALPHABET, max_size=30).map("".join)))
def test_random_text_gives_a_mechanism_or_a_mechanism_error(text):
    result = load_text(text)
    assert isinstance(result, (Mechanism, MechanismError))
    if isinstance(result, Mechanism):
        value = value_of(result.body("crank").length)
        assert value.imag == 0 and math.isfinite(value.real)


@dataclass(frozen=True)
class Arithmetic:
    """Random expression text with Python's float value of it and a bound on that value's
    rounding error (first-order propagation, every operation adding one rounding)."""

    text: str
    value: float
    error: float
    well_conditioned: bool        # no division by, or square root of, a value within its error of 0


EPS = 2.0**-52


def _leaf(draw) -> Arithmetic:
    if draw(st.booleans()):
        name = draw(st.sampled_from(sorted(VALUES)))
        return Arithmetic(name, VALUES[name], 0.0, True)
    number = draw(st.sampled_from(["0", "1", "2", "3", "0.5", "0.1", "1.25", "7", "1e-3", "2.5e2", "10"]))
    return Arithmetic(number, float(number), EPS * abs(float(number)), True)


@st.composite
def arithmetic(draw, depth: int = 0) -> Arithmetic:
    if depth >= 4 or draw(st.integers(0, 3)) == 0:
        return _leaf(draw)
    kind = draw(st.sampled_from(["+", "-", "*", "/", "**", "neg", "sqrt", "sin", "cos"]))
    a = draw(arithmetic(depth + 1))
    if kind == "neg":
        return Arithmetic(f"-({a.text})", -a.value, a.error, a.well_conditioned)
    if kind in ("sqrt", "sin", "cos"):
        if kind == "sqrt":
            if a.value < 0:
                raise _Refused(f"{kind}({a.text})")
            r = math.sqrt(a.value)
            ok = a.value > 8 * a.error
            err = (a.error / (2 * r) if r > 0 else math.inf) + EPS * r
        else:
            r = math.sin(a.value) if kind == "sin" else math.cos(a.value)
            ok, err = a.well_conditioned, a.error + EPS
        return Arithmetic(f"{kind}({a.text})", r, err, ok and a.well_conditioned)
    if kind == "**":
        n = draw(st.integers(0, 3))
        r = a.value ** n
        if abs(r) > MAX_MAGNITUDE:
            raise _Refused(f"({a.text})**{n}")
        err = (abs(n) * abs(a.value) ** (n - 1) * a.error if n else 0.0) + n * EPS * abs(r)
        return Arithmetic(f"({a.text})**{n}", r, err, a.well_conditioned)
    b = draw(arithmetic(depth + 1))
    ok = a.well_conditioned and b.well_conditioned
    if kind == "+":
        r, err = a.value + b.value, a.error + b.error
    elif kind == "-":
        r, err = a.value - b.value, a.error + b.error
    elif kind == "*":
        r, err = a.value * b.value, abs(a.value) * b.error + abs(b.value) * a.error + a.error * b.error
    else:
        if b.value == 0:
            raise _Refused(f"({a.text}) {kind} ({b.text})")
        r = a.value / b.value
        ok = ok and abs(b.value) > 8 * b.error
        err = (a.error + abs(r) * b.error) / abs(b.value) if ok else math.inf
    if not math.isfinite(r) or abs(r) > MAX_MAGNITUDE:
        raise _Refused(f"({a.text}) {kind} ({b.text})")
    return Arithmetic(f"({a.text}) {kind} ({b.text})", r, err + EPS * abs(r), ok)


class _Refused(Exception):
    """The float reference itself fails on this text (0 division, sqrt of a negative, beyond
    MAX_MAGNITUDE): the parser, which refuses what is not finite and real, must refuse it."""

    def __init__(self, text: str):
        super().__init__(text)
        self.text = text


@st.composite
def arithmetic_or_refusal(draw):
    """An Arithmetic, or the text on which Python's float arithmetic fails (a _Refused)."""
    try:
        return draw(arithmetic())
    except _Refused as refused:
        return refused


@pytest.mark.timeout(300)
@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(arithmetic_or_refusal())
def test_well_formed_arithmetic_equals_python_float_arithmetic(reference):
    if isinstance(reference, _Refused):
        result = load_text(reference.text, "point")
        assert isinstance(result, MechanismError), f"{reference.text!r} accepted"
        return
    result = load_text(reference.text, "point")
    if len(reference.text) > 500 or not reference.well_conditioned:
        # beyond the length limit, or within round-off of a pole: either outcome, but only those two
        assert isinstance(result, (Mechanism, MechanismError))
        return
    assert isinstance(result, Mechanism), f"{reference.text!r} refused: {result}"
    value = value_of(result.ground["O4"][0])
    assert value.imag == 0
    # Python's floats round each operation (relative EPS); the bound is their first-order
    # propagation, times 8 for the terms first order leaves out; sympy evaluates at 30 digits.
    assert abs(value.real - reference.value) <= 8 * reference.error + 1e-300, (reference, value)


# -- text of the file copied into generated source code -----------------------------------------------------------
DESCRIPTIONS = ['x"""; import os; os.system("touch canary_docstring") #', "x */ int injected = 1; /*",
                "x *\\\n/ int injected = 1; /*", "x ??/\n*/ int injected = 1; /*"]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("description", DESCRIPTIONS)
def test_the_loader_keeps_a_description_as_text_or_refuses_line_breaks(description, tmp_path):
    base = BASE.read_text(encoding="utf-8")
    line = 'description = "Planar four-bar linkage (Table 1 of Park\'s integrated engineering education model)"'
    assert line in base
    path = tmp_path / "m.toml"
    path.write_text(base.replace(line, f"description = {toml_string(description)}"), encoding="utf-8")
    if "\n" in description:
        with pytest.raises(MechanismError, match=r"\[mechanism\]: 'description' contains the control or separator "
                                                 r"character U\+000A"):
            load_mechanism(path)
    else:
        assert load_mechanism(path).description == description


@pytest.mark.timeout(300)
@pytest.mark.parametrize("description", DESCRIPTIONS)
def test_a_description_cannot_end_a_comment_of_the_generated_code(description, tmp_path, monkeypatch):
    """The generators quote what they are given, whatever the loader lets through (a Mechanism
    can be made in code, and the file name is not the loader's to check)."""
    import dataclasses

    from fmu_src.build import _script
    from fmu_src.c_codegen import generate_c_sources
    from fmu_src.mechanism.check import prepare_mechanism
    from fmu_src.mechanism.python_code import generate_module, load_module

    folder = tmp_path / 'a"""b*?'
    folder.mkdir()
    path = folder / 'c"""d.toml'
    path.write_text(BASE.read_text(encoding="utf-8"), encoding="utf-8")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    checked = prepare_mechanism(dataclasses.replace(load_mechanism(path), description=description))
    module = load_module(generate_module(checked.equations), "untrusted")      # runs the generated module
    assert module.DESCRIPTION == description                                  # kept as data, exactly
    compile(_script(checked), "<script>", "exec")
    header = generate_c_sources(checked.equations)["equations.h"]
    spliced = header.replace("\\\n", "").replace("??/\n", "")
    assert "injected" not in spliced.split("*/", 2)[1].split("/*")[0]
    assert spliced.count("/*") == spliced.count("*/")
    assert os.listdir(work) == []


@pytest.mark.timeout(120)
def test_a_refused_expression_is_refused_before_sympy_is_imported(tmp_path):
    """The checks need no sympy (its import is most of a refusal's time through build_fmu.py)."""
    path = mechanism_file(tmp_path, "10**10**10")
    code = ("import sys\nfrom fmu_src.mechanism.description import MechanismError, load_mechanism\n"
            f"try:\n    load_mechanism({str(path)!r})\nexcept MechanismError as exc:\n    print(exc)\n"
            "print('sympy' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.stdout.splitlines() == [f"{path}: bodies[0] 'crank'.length: '10**10**10' has the exponent '10**10' "
                                        f"(= 1e+10); an exponent is at most 16 in magnitude", "False"], proc.stderr


#: The crank's length with every function and constant the grammar allows, as a small change of
#: L2 (about +1.3 cm): the generated Python and C must define each (the Python module imported
#: only cos and sin, and the C printed pi as the POSIX macro M_PI, which C99 does not have).
EVERY_FUNCTION = ("L2 + 1e-3*(sqrt(L1) + sin(L1) + cos(L1) + tan(L1/8) + asin(L1/8) + acos(L1/8) + atan(L1)"
                  " + atan2(L1, L4) + exp(-L1) + log(L1) + pi)")


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_every_allowed_function_builds_into_both_fmus_and_means_the_same(tmp_path):
    """Both FMUs of a four-bar whose crank length uses every function: the crank's length in
    the run (|A - O2|, from the drawing outputs) equals Python's math on the same text, and the
    two FMUs agree."""
    import numpy as np
    from fmpy import extract, simulate_fmu

    from orchestrator.pythonfmu_workarounds import forget_other_fmu_modules

    path = mechanism_file(tmp_path, EVERY_FUNCTION)
    build = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(path), "--no-validate",
                            "--out", str(tmp_path / "M.fmu"), "--native-out", str(tmp_path / "MN.fmu")],
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr[-3000:]
    m = math
    crank = 1.0 + 1e-3 * (m.sqrt(3.0) + m.sin(3.0) + m.cos(3.0) + m.tan(3.0 / 8) + m.asin(3.0 / 8)
                          + m.acos(3.0 / 8) + m.atan(3.0) + m.atan2(3.0, 2.5) + m.exp(-3.0) + m.log(3.0) + m.pi)
    runs = []
    for name in ("M.fmu", "MN.fmu"):
        unzipped = extract(str(tmp_path / name))
        # a pythonfmu FMU's slave module is cached by name in this interpreter: another
        # test's FourBar would answer for this one (PythonFMU #228; the project's workaround)
        forget_other_fmu_modules(unzipped)
        runs.append(simulate_fmu(unzipped, stop_time=1.0, output_interval=0.01,
                                 output=["A_x", "A_y", "O2_x", "O2_y", "x3", "y3"]))
    for r in runs:
        length = np.hypot(r["A_x"] - r["O2_x"], r["A_y"] - r["O2_y"])
        # the constraints hold to round-off at every communication point (projection), so the
        # crank keeps its length to ~1e-12 m; 1e-9 m leaves margin and fails on a wrong constant
        np.testing.assert_allclose(length, crank, rtol=0, atol=1e-9)
    # the two FMUs integrate the same equations (DOP853, rtol 1e-9 by default) with different
    # round-off: over 1 s they agree to ~1e-10 m; 1e-7 m fails on any term printed differently
    np.testing.assert_allclose(runs[0]["x3"], runs[1]["x3"], rtol=0, atol=1e-7)
    np.testing.assert_allclose(runs[0]["y3"], runs[1]["y3"], rtol=0, atol=1e-7)
