"""build_fmu.py under what a user writes or does (issue 23, "inputs and signals").

Real runs of ``python build_fmu.py``: a directory or a foreign file as --out, a CC that does
not exist, Ctrl-C and SIGTERM during a build, and the pythonfmu FMU's GUID, which is a hash
of its content (two builds of the same sources agree, a changed source changes it).
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from support import FOURBAR_RUN, REPO, case_file, unwritable_folder

PYTHON = sys.executable


def build(*args, cwd=REPO, env=None, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([PYTHON, "build_fmu.py", *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=timeout)


def guid_of(fmu: Path) -> str:
    with zipfile.ZipFile(fmu) as z:
        return re.search(rb' guid="([^"]+)"', z.read("modelDescription.xml")).group(1).decode()


def test_out_on_a_directory_is_refused_and_leaves_nothing(tmp_path):
    target = tmp_path / "folder"
    target.mkdir()
    for option in ("--out", "--native-out"):
        only = "pythonfmu" if option == "--out" else "native"
        proc = build("--only", only, option, target)
        assert proc.returncode == 2, proc.stderr
        assert f"{option} {target}: is a directory" in proc.stderr and "Traceback" not in proc.stderr
        # Nothing in it or beside it (the old build left folder.fmu.tmp, 700 kB, beside it).
        assert list(target.iterdir()) == [] and list(tmp_path.iterdir()) == [target]


def test_out_on_a_file_that_is_not_an_fmu_needs_force(tmp_path):
    mine = tmp_path / "notes.txt"
    mine.write_text("not an FMU\n")
    proc = build("--only", "pythonfmu", "--out", mine)
    assert proc.returncode == 2, proc.stderr
    assert "exists and is not an FMU" in proc.stderr and "--force" in proc.stderr
    assert mine.read_text() == "not an FMU\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    assert "--force" in build("--help").stdout


def test_out_in_a_folder_that_cannot_be_written_is_refused_before_building(tmp_path):
    """--out / --native-out in (or under) a read-only folder: exit 2 at once, naming the folder
    and the OS's reason; the build (seconds) is not started.  It used to build, then fail to
    write the FMU: exit 1 with a bare "[Errno 13] Permission denied: '....fmu.tmp'"."""
    locked = unwritable_folder(tmp_path)
    for option, only, target in (("--out", "pythonfmu", locked / "F.fmu"),
                                 ("--native-out", "native", locked / "sub" / "N.fmu")):
        started = time.monotonic()
        proc = build("--only", only, option, target, timeout=60)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert f"build_fmu.py: error: {option} {target}: cannot write in {locked}: " in proc.stderr
        assert "choose a writable folder" in proc.stderr and "Traceback" not in proc.stderr
        assert proc.stdout == ""                                  # nothing was built
        assert time.monotonic() - started < 30, "refused only after building"   # a build takes >= 3 s here
    if locked.is_relative_to(tmp_path):
        assert list(locked.iterdir()) == []


@pytest.mark.slow
def test_a_native_build_that_cannot_write_its_fmu_leaves_nothing_and_the_old_fmu_intact(tmp_path, native_fmu):
    """Failures after the checks, in the library itself (build_fmu.py used to clean up after
    it): the destination became a directory while the FMU was built (the rename fails after
    the whole temporary file is written), and a compile error with an FMU already at the
    destination.  No temporary file is left (the old build left N.fmu.tmp, 60 kB) and the
    existing FMU is byte for byte the old one."""
    from fmu_src.native_build import build_native_fmu

    raced = tmp_path / "raced"
    (raced / "N.fmu" / "inside").mkdir(parents=True)
    with pytest.raises(IsADirectoryError):
        build_native_fmu(raced / "N.fmu", validate=False)
    assert [p.name for p in raced.iterdir()] == ["N.fmu"]
    assert [p.name for p in (raced / "N.fmu").iterdir()] == ["inside"]

    kept = tmp_path / "kept"
    kept.mkdir()
    old = kept / "N.fmu"
    shutil.copy2(native_fmu, old)
    before = old.read_bytes()
    with pytest.raises(RuntimeError, match="compiling the native FMU failed"):
        build_native_fmu(old, validate=False, replace={"model.c": b"#error a broken model.c\n"})
    assert old.read_bytes() == before
    assert [p.name for p in kept.iterdir()] == ["N.fmu"]


def test_a_cc_that_does_not_exist_is_named(tmp_path):
    env = {**os.environ, "CC": "/nonexistent/cc"}
    proc = build("--only", "native", "--native-out", tmp_path / "N.fmu", env=env)
    assert proc.returncode == 1, proc.stderr
    assert "CC=/nonexistent/cc names no executable file or command on PATH" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize("sig, code, said", [(signal.SIGINT, 130, "interrupted by Ctrl-C"),
                                             (signal.SIGTERM, 143, "terminated by SIGTERM")])
def test_a_signal_during_a_build_leaves_no_partial_fmu(sig, code, said, tmp_path):
    """The signal lands after 1 s: during the build (pythonfmu's takes about 3 s) or, on a loaded
    machine, still during the imports (that gave a traceback, and SIGTERM killed it silently,
    before build_fmu.py caught both from its first line).  SIGINT is restored to Python's
    default in the child: a job started in the background inherits it ignored (see conftest.py)."""
    proc = subprocess.Popen([PYTHON, "build_fmu.py", "--out", str(tmp_path / "F.fmu"),
                             "--native-out", str(tmp_path / "N.fmu")], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        time.sleep(1.0)                            # into the imports or the build: either must end cleanly
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code, (stdout, stderr)
    assert f"build_fmu.py: {said}; no partial FMU was left" in stderr and "Traceback" not in stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_pythonfmu_guid_is_a_hash_of_the_sources(tmp_path):
    """Three builds of the pythonfmu FMU (about 4 s each), from a copy of the build's sources:
    the same sources give the same GUID; a changed comment in the run-time's slave gives another.  The rewritten GUID passes `fmpy validate` and the FMU still runs
    (pythonfmu's binary does not compare it at fmi2Instantiate)."""
    copy = tmp_path / "src"
    copy.mkdir()
    shutil.copy2(REPO / "build_fmu.py", copy / "build_fmu.py")
    shutil.copytree(REPO / "fmu_src", copy / "fmu_src", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))

    first = tmp_path / "a" / "FourBar.fmu"
    proc = build("--only", "pythonfmu", "--out", first, cwd=copy)
    assert proc.returncode == 0, proc.stderr
    assert "pythonfmu FMU: fmpy validate: no problems" in proc.stdout
    second = tmp_path / "b" / "FourBar.fmu"
    assert build("--only", "pythonfmu", "--out", second, "--no-validate", cwd=copy).returncode == 0
    assert guid_of(first) == guid_of(second)
    assert re.fullmatch(r"[0-9a-f]{8}-[0-9a-f]{4}-5[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}", guid_of(first))

    slave = copy / "fmu_src" / "mechanism_model" / "slave.py"
    slave.write_text(slave.read_text() + "\n# a changed source\n")
    changed = tmp_path / "c" / "FourBar.fmu"
    changed.parent.mkdir()
    shutil.copy2(second, changed)                  # an existing FMU is replaced without --force
    proc = build("--only", "pythonfmu", "--out", changed, "--no-validate", cwd=copy)
    assert proc.returncode == 0, proc.stderr
    assert guid_of(changed) != guid_of(first)
    assert not list(changed.parent.glob("*.tmp")) and not list(changed.parent.glob(".*.tmp"))

    out = tmp_path / "run"
    proc = subprocess.run([FOURBAR_RUN, str(case_file("case1_normal", first, tmp_path)), "--out", str(out),
                           "--stop", "0.1", "-q"], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    assert (out / "exchange.csv").read_text().count("\n") == 1 + 11
