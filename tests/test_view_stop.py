"""fourbar-view stopped by Ctrl-C: one "stopped" line and exit 130, as docs/view.md and
`--help` say (issue 37: it ended 0 and said nothing, Panel's own SIGINT handler having
replaced the command's).  A real process on a real run folder; the waits are hang guards only.
"""
from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from support import FOURBAR_RUN, case_file

FOURBAR_VIEW = str(Path(sys.executable).parent / "fourbar-view")
HANG_GUARD_S = 120        # Panel's import and the first page on a loaded 2-core machine; not a timing


@pytest.fixture(scope="module")
def run_folder(native_fmu, tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("viewstop")
    out = tmp / "run"
    done = subprocess.run([FOURBAR_RUN, str(case_file("case1_normal", native_fmu, tmp)), "--stop", "2", "--out",
                           str(out), "--quiet"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_stop_signal_ends_the_server_with_its_status_and_a_line(run_folder, signum, code):
    # the SIGINT disposition is the terminal's (tests/conftest.py restores it when pytest runs
    # as a background job), so the child gets Ctrl-C as from a terminal
    proc = subprocess.Popen([FOURBAR_VIEW, str(run_folder), "--quiet"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()         # printed once the server listens
        assert url.startswith("http://127.0.0.1:"), (url, proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, err
    assert "fourbar-view: stopped" in err and "Traceback" not in err, err
