"""benchmarks/fmi_flavours.py: its comparisons on prebuilt FMUs, its table, its refusals.

The full benchmark builds every mechanism afresh and writes docs/fmi_hosts.md's flavour
table; here one mechanism's prebuilt FMUs go through the same ``run_mechanism`` of
fmu_src/fmi_flavours.py (FMPy's columns; fmusim's where one is found), and the command line's
refusals are checked (the benchmark as a subprocess).
"""
from __future__ import annotations

import subprocess
import sys

import pytest

from fmu_src import fmi_flavours, fmi_hosts
from support import REPO

SCRIPT = [sys.executable, str(REPO / "benchmarks" / "fmi_flavours.py")]


#: s compared here.  The benchmark's 10 s of every flavour against FMI 2.0 co-simulation are
#: asserted for every shipped mechanism, the four-bar included, by tests/test_fmu_model_exchange.py
#: (FMI 2.0 ME, FMPy and fmusim) and tests/test_fmu_fmi3.py (FMI 3.0 CS and ME, FMPy and fmusim),
#: with the same tolerances (fmu_src/fmi_flavours.py, which the benchmark imports too); this test checks the
#: benchmark's own comparison and table, which 2 s (200 rows, every flavour run) go through as
#: 10 s do.  10 s cost ~50 s of the suite's wall (FMPy's Model Exchange loop at rtol 1e-14).
SPAN = 2.0


def test_every_flavour_of_the_four_bar_agrees_and_the_table_says_so(mechanism_fmus, tmp_path):
    fmus = {2: mechanism_fmus.get("fourbar", "native"), 3: mechanism_fmus.get("fourbar", "native3")}
    fmusim = fmi_hosts.find_fmusim()
    assert fmi_flavours.flavour_span("fourbar") == fmi_flavours.DEFAULT_SPAN == 10.0   # what the table says
    span, cells = fmi_flavours.run_mechanism("fourbar", fmus, fmusim, tmp_path, span=SPAN)
    assert span == SPAN and len(cells) == len(fmi_flavours.FLAVOURS)
    for (version, interface, host), cell in zip(fmi_flavours.FLAVOURS, cells):
        if host == "fmusim" and fmusim is None:
            assert cell is None
            continue
        assert cell.agrees, (version, interface, host, cell)
        if (version, interface, host) == (3, "CS", "FMPy"):
            assert cell.difference == 0.0          # the same C model and integrator behind both layers
        if interface == "ME":
            # CVode's own error at 1e-14: measured 1.3e-10 m on the four-bar; 0 would mean the
            # model-exchange run was not compared at all
            assert 0.0 < cell.difference
    row = fmi_flavours.Row("fourbar", span, "", cells)
    lines = fmi_flavours.table([row])
    assert lines[2].startswith("| `fourbar` | 2 | 0 (bit for bit) | ") and "**" not in lines[2]


def test_a_disagreement_is_marked_in_the_table():
    row = fmi_flavours.Row("fourbar", 10.0, "", (fmi_flavours.Cell(2e-9, "over 1e-09"),)
                           + (None,) * (len(fmi_flavours.FLAVOURS) - 1))
    assert not row.ok
    assert "**2.0e-09** (over 1e-09)" in fmi_flavours.table([row])[2]


@pytest.mark.parametrize("args, words", [
    (["--mechanism", "nonesuch"], "unknown mechanism 'nonesuch'"),
    (["--fmusim", "/nonexistent/fmusim"], "/nonexistent/fmusim"),
    (["--mechanism", "fourbar", "--write", "README.md"], "leave out --mechanism"),
])
def test_bad_arguments_exit_2_naming_them(args, words):
    proc = subprocess.run([*SCRIPT, *args], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


def test_write_needs_the_markers(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("no markers here\n", encoding="utf-8")
    fmusim = fmi_hosts.find_fmusim()
    if fmusim is None:
        pytest.skip("--write needs an fmusim first (the refusal for a missing one is checked by the next test)")
    proc = subprocess.run([*SCRIPT, "--fmusim", str(fmusim), "--write", str(page)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and fmi_flavours.BEGIN in proc.stderr, proc.stderr
    assert page.read_text(encoding="utf-8") == "no markers here\n"


def test_write_without_fmusim_is_refused():
    if fmi_hosts.find_fmusim() is not None:
        pytest.skip("an fmusim is found here ($FMUSIM or PATH)")
    proc = subprocess.run([*SCRIPT, "--write", str(REPO / "docs" / "fmi_hosts.md")], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and "no fmusim was found" in proc.stderr, proc.stderr
