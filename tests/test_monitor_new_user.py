"""What a new user hit with the monitor (issue 37): a stopped replay's line about the files it
keeps, the docs on ``--follow`` of a folder whose run has ended, and the exit-code lists.

The data are the synthetic swing of ``test_monitor_common_period`` (an exchange file and a
run.json written as fourbar-run writes them): no FMU is run.
"""
from __future__ import annotations

import json
import re
import signal
from pathlib import Path

import pytest

from fourbar_common.signals import Stopped
from monitor.cli import main
from monitor.cusum_detector import CusumDetector
from monitor.session import _Session
from support import REPO
from test_docs import doc_exit_list, epilog_codes
from test_monitor_common_period import swing, times, write_run

ARGS = ["--signal", "x2", "--model", "harmonic", "--quiet"]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    t = times(20.0)
    return write_run(tmp_path_factory.mktemp("swing") / "run", swing(t, fault=None), t, None)


def stopped_by(signum: int):
    def stop(*args, **kwargs):
        raise Stopped(signum)          # what fourbar_common.signals.StopSignals raises on the signal
    return stop


def one_line(capsys) -> str:
    printed = capsys.readouterr()
    lines = printed.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in printed.err + printed.out, printed.err
    return lines[0]


def test_a_replay_stopped_before_it_writes_does_not_claim_an_earlier_sessions_files(run, tmp_path, capsys,
                                                                                       monkeypatch):
    out = tmp_path / "monitor"
    assert main([str(run), *ARGS, "--out", str(out)]) == 0          # an earlier session: every file
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert {"summary.json", "history.png", "events.jsonl"} <= set(before)
    # SIGTERM while the model is fitted: nothing of this session is written yet
    monkeypatch.setattr(CusumDetector, "train", stopped_by(signal.SIGTERM))
    assert main([str(run), *ARGS, "--out", str(out)]) == 143
    line = one_line(capsys)
    assert line.startswith("fourbar-monitor: terminated by SIGTERM; nothing was written this time; "), line
    assert "kept" not in line                                       # before issue 37: "kept ... summary.json, ..."
    for name in before:                                             # each named as the earlier session's, with its time
        assert re.search(rf"\b{re.escape(name)} \d{{4}}-\d\d-\d\d \d\d:\d\d:\d\d UTC\b", line), (name, line)
    assert line.endswith(f"in {out} are from an earlier session, not this one")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before          # untouched


def test_a_replay_stopped_after_it_wrote_says_what_it_kept(run, tmp_path, capsys, monkeypatch):
    out = tmp_path / "monitor"
    assert main([str(run), *ARGS, "--no-plots", "--out", str(out)]) == 0
    capsys.readouterr()
    # Ctrl-C after every row was judged, before the summary: this session's streamed files only
    monkeypatch.setattr(_Session, "end_of_data", stopped_by(signal.SIGINT))
    assert main([str(run), *ARGS, "--no-plots", "--out", str(out)]) == 130
    line = one_line(capsys)
    assert f"; kept events.jsonl, evaluations.csv, forecast.csv in {out} (up to then; no summary.json" in line, line
    assert "earlier session" not in line and not (out / "summary.json").exists()


# -- --follow on a folder whose run has ended: the docs say what the program does -------------------------

DOC = (REPO / "docs" / "monitor.md").read_text(encoding="utf-8")


def doc_section(title: str) -> str:
    start = DOC.index(f"### {title}\n")
    return re.sub(r"\s+", " ", DOC[start:DOC.index("\n#", start + 4)])


def test_follow_of_a_folder_whose_run_has_ended_does_what_the_docs_say(run, tmp_path, capsys):
    section = doc_section("Following a folder whose run has ended")
    # a fourbar-run run.json (run_id, started_at) that says the run finished
    folder = tmp_path / "ended"
    folder.mkdir()
    (folder / "exchange.csv").write_bytes(run.read_bytes())
    record = json.loads((run.parent / "run.json").read_text())
    record.update(run_id="3f2a9c", case="swing", started_at="2026-11-27T22:00:00.000+00:00")
    (folder / "run.json").write_text(json.dumps(record))
    out = tmp_path / "out"
    code = main([str(folder), "--follow", "--timeout", "0.5", "--poll", "0.05", *ARGS[:-1], "--out", str(out)])
    printed = capsys.readouterr()
    assert code == 2 and not out.exists(), printed
    said = f"{folder} holds run 3f2a9c of swing, started 2026-11-27T22:00:00.000+00:00, which has ended (finished); " \
           "waiting for the next run (replay the ended one without --follow)"
    assert said in printed.out
    assert "no new run started within 0.5 s (--timeout); it holds run 3f2a9c" in printed.err
    # ... and the docs promise exactly that (before issue 37 they said the ended run "is read as that run")
    assert "which has ended (finished); waiting for the next run (replay the ended one without --follow)" in section
    assert "ends with exit 2 and `no new run started within <timeout> s (--timeout); it holds ..., which has " \
           "ended: replay it without --follow`" in section
    assert "is read as that run" not in DOC


def test_follow_of_a_run_json_without_identity_reads_it_as_the_docs_say(run, tmp_path, capsys):
    section = doc_section("Following a folder whose run has ended")
    assert "A run.json without `run_id` and `started_at` (not written by fourbar-run) cannot be told from the " \
           "next run: its rows are read and the session ends with the file" in section
    out = tmp_path / "out"
    code = main([str(run), "--follow", "--timeout", "5", "--poll", "0.05", *ARGS, "--out", str(out)])
    printed = capsys.readouterr()
    assert code == 0, printed
    assert json.loads((out / "summary.json").read_text())["last_time"] == pytest.approx(20.0)


# -- exit codes: every list of the monitor's is the --help epilog's ----------------------------------------

def test_every_list_of_the_monitors_exit_codes_is_complete():
    codes = epilog_codes("fourbar-monitor")
    assert {0, 1, 2, 3, 4, 5, 130, 143} <= codes
    assert doc_exit_list("docs/monitor.md", "Exit status:") == codes
    # the README's monitor section (before issue 37: 0, 1, 2, 3, 130 only)
    assert doc_exit_list("README.md", "Without `--follow` it replays a finished file. Exit status:") == codes
    docstring = (REPO / "monitor" / "cli.py").read_text(encoding="utf-8").split('"""')[1]
    assert {int(c) for c in re.findall(r"\b(\d+) (?=[a-z(])", docstring.split("Exit codes:")[1])} == codes
