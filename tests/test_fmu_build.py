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

    def fake_build(dest, validate=True, mechanism="fourbar"):     # the pythonfmu build is tested elsewhere
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


def test_the_pythonfmu_fmu_can_be_instantiated_many_times_in_one_process(fourbar_fmu, tmp_path):
    # pythonfmu 0.7.0 releases a reference to the script's globals at every instantiation
    # (fmu_src/build.py, PYTHONFMU_INSTANCES); without the script's own references the second
    # instance failed ("module has no attribute 'FourBar'") and later ones crashed the process.
    # A child process: a failure here must not take the test session down.
    import subprocess
    import sys
    code = f"""
import shutil
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
for k in range(200):
    d = extract({str(fourbar_fmu)!r})
    md = read_model_description(d)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"i{{k}}")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(0.0, 0.01)
    fmu.terminate()
    fmu.freeInstance()
    shutil.rmtree(d)
print("instances: 200")
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert "instances: 200" in proc.stdout, proc.stderr[-2000:]
