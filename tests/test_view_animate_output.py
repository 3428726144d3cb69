"""`fourbar-view --animate OUT` checks OUT before drawing a frame (issue 37: into a read-only
folder it drew every frame, 34 s, and then failed with exit 1).

A small run folder written here (a signal, no drawing: the animation needs nothing more);
the library call must raise before its first frame (``progress`` never called), and the
command must exit 2 with a message naming the path, leaving nothing in the folder.
"""
from __future__ import annotations

import json
import os
import socket

import numpy as np
import pytest

from support import unwritable_folder
from view.animate import AnimationError, animate
from view.cli import main


@pytest.fixture
def run_folder(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    record = {"schema": 2, "status": "finished", "run_id": "d" * 32, "case": "small", "case_file": None,
              "description": "", "fmu": {"path": "F.fmu", "guid": "g", "model_name": "M"},
              "experiment": {"start": 0.0, "stop": 5.0, "step": 0.01, "tolerance": None},
              "parameters": {}, "events": [], "fault_time": None, "outputs": ["x2"], "units": {}, "noise": None,
              "exchange": {"flush_interval": 1.0, "realtime_factor": 0.0, "max_rows": 1000},
              "rows_written": 501, "last_time": 5.0, "started_at": "2026-11-27T00:00:00Z", "updated_at": None,
              "finished_at": "2026-11-27T00:00:01Z", "wall_time_s": 1.0, "error": None,
              "writer": {"pid": os.getpid(), "host": socket.gethostname(), "heartbeat_s": 2.0}}
    (folder / "run.json").write_text(json.dumps(record))
    t = np.arange(501) * 0.01
    (folder / "exchange.csv").write_text("time,x2\n" + "".join(f"{float(v)!r},{float(np.sin(v))!r}\n" for v in t))
    return folder


def _bad_outputs(tmp_path):
    """(name, path) of outputs that cannot be written."""
    read_only = unwritable_folder(tmp_path)
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    a_folder = tmp_path / "anim.gif"
    a_folder.mkdir()
    return [("read-only folder", read_only / "anim.gif", "cannot write in"),
            ("a folder named like the output", a_folder, "is a folder"),
            ("a file as the folder", a_file / "anim.gif", "is not a folder")]


def test_an_unwritable_output_is_refused_before_the_first_frame(run_folder, tmp_path):
    for what, out, says in _bad_outputs(tmp_path):
        drawn = []
        with pytest.raises(AnimationError, match=says) as raised:
            animate(run_folder, out, progress=lambda done, total: drawn.append(done))
        assert drawn == [], what                       # refused before any frame was drawn
        assert str(out) in str(raised.value), (what, str(raised.value))


def test_the_command_exits_2_naming_the_output(run_folder, tmp_path, capsys):
    read_only = unwritable_folder(tmp_path)
    out = read_only / "anim.gif"
    assert main([str(run_folder), "--animate", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"fourbar-view: error: {out}: cannot write in {read_only}" in err, err
    assert not [p.name for p in read_only.iterdir() if "anim" in p.name]       # nothing left behind


def test_a_writable_output_still_gets_its_animation(run_folder, tmp_path):
    """The check leaves no probe behind and does not stop a good output."""
    out = tmp_path / "ok.gif"
    result = animate(run_folder, out, fps=2.0)
    assert result.path == out and out.stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.gif", "run"]
