"""A case file without ``name`` is named after its file: file names with spaces, accents or no
Latin letter at all, run through ``fourbar-run`` as a new user would (issue 37).

Each run is one simulated second of the native FMU (about 1 s of wall time).
"""
from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from support import FOURBAR_RUN, case_file


def _nameless(native_fmu: Path, path: Path, name_line: str = "") -> Path:
    """cases/case1_normal.toml on the native FMU, saved as ``path`` without its ``name`` line
    (or with ``name_line`` instead)."""
    case_file("case1_normal", native_fmu, path)
    text = re.sub(r"(?m)^name\s*=.*\n", name_line, path.read_text(encoding="utf-8"))
    path.write_text(text, encoding="utf-8")
    return path


def _run(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([FOURBAR_RUN, *args, "--stop", "1", "-q"], cwd=cwd, capture_output=True,
                          text=True, encoding="utf-8", timeout=300)   # hang guard only


@pytest.mark.parametrize("file_name, folder", [("my case.toml", "my_case"), ("casé.toml", "case"),
                                               ("Ünï cødé!.toml", "Uni_c_de")])
def test_a_file_name_with_spaces_or_accents_names_the_run(native_fmu, tmp_path, file_name, folder):
    _nameless(native_fmu, tmp_path / file_name)
    done = _run(tmp_path, file_name)
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "out" / folder / "run.json").read_text(encoding="utf-8"))
    assert record["status"] == "finished" and record["case"] == folder
    assert [p.name for p in (tmp_path / "out").iterdir()] == [folder]


def test_a_file_name_with_spaces_runs_into_out_dir_labelled_with_its_name(native_fmu, tmp_path):
    _nameless(native_fmu, tmp_path / "my case.toml")
    done = _run(tmp_path, "my case.toml", "--out", "here")
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "here" / "run.json").read_text(encoding="utf-8"))["case"] == "my_case"


def test_a_file_name_with_no_latin_letter_is_refused_naming_the_file_and_the_fix(native_fmu, tmp_path):
    _nameless(native_fmu, tmp_path / "案例.toml")
    done = _run(tmp_path, "案例.toml")
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert "the file name '案例.toml' gives no case name" in done.stderr, done.stderr
    assert 'add a line name = "..."' in done.stderr and "rename the file" in done.stderr
    assert "name = " not in done.stderr.split("gives no case name")[0]   # no `name` value the user never wrote
    assert not (tmp_path / "out").exists()


def test_with_out_the_name_only_labels_the_run(native_fmu, tmp_path):
    """With --out the name names no folder: a file name with no Latin letter labels the run as
    it is.  A name written in the file is still checked as a folder name, and its message says so."""
    _nameless(native_fmu, tmp_path / "案例.toml")
    done = _run(tmp_path, "案例.toml", "--out", "a")
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "a" / "run.json").read_text(encoding="utf-8"))["case"] == "案例"

    _nameless(native_fmu, tmp_path / "written.toml", 'name = "my case"\n')
    done = _run(tmp_path, "written.toml", "--out", "b")
    assert done.returncode == 2 and 'name = "my case": expected a non-empty string' in done.stderr, done.stderr
    assert "it names the run and its default folder out/<name>" in done.stderr
    assert not (tmp_path / "b").exists()
