"""build_fmu.py: both FMUs, one flag for one, and a clear line when there is no C compiler."""
from __future__ import annotations

import zipfile

import pytest

import build_fmu
from fmu_src import build as pythonfmu_build
from fmu_src.native_build import build_native_fmu, find_compiler


def test_without_a_compiler_the_pythonfmu_fmu_is_built_and_the_way_to_the_native_one_said(
        monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    built = []

    def fake_build(dest, validate=True):     # the pythonfmu build itself is tested elsewhere
        built.append(dest)
        return pythonfmu_build.BuildResult(path=tmp_path / "FourBar.fmu", guid="g", problems=())

    monkeypatch.setattr(pythonfmu_build, "build_fmu", fake_build)
    assert build_fmu.main(["--out", str(tmp_path / "FourBar.fmu"), "--native-out", str(tmp_path / "N.fmu")]) == 0
    out = capsys.readouterr().out
    assert built and "native FMU not built: no C compiler found" in out and "--only native" in out
    assert not (tmp_path / "N.fmu").exists()


def test_only_native_without_a_compiler_is_an_error(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    assert build_fmu.main(["--only", "native", "--native-out", str(tmp_path / "N.fmu")]) == 1
    assert "no C compiler found" in capsys.readouterr().err


def test_bad_flag_is_a_usage_error(capsys):
    assert build_fmu.main(["--only", "fortran"]) == 2
    assert "invalid choice" in capsys.readouterr().err


@pytest.mark.skipif(find_compiler() is None, reason="no C compiler")
def test_native_guid_is_a_hash_of_the_sources(tmp_path):
    a = build_native_fmu(tmp_path / "a.fmu", validate=False)
    b = build_native_fmu(tmp_path / "b.fmu", validate=False)
    with zipfile.ZipFile(a.path) as z:
        model_c = z.read("sources/model.c")
    c = build_native_fmu(tmp_path / "c.fmu", validate=False, replace={"model.c": model_c + b"\n/* changed */\n"})
    assert a.guid == b.guid != c.guid
    assert a.platforms[0] in ("linux64", "darwin64", "win64")
