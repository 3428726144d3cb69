"""The figures quoted in README.md and docs/ match a fresh run (benchmarks/doc_figures.py, run
as a program: tests do not import benchmark code).

The slow test measures (12 fourbar-run runs and their replays, one simulate_fmu, make demo at
10x real time, the libcosim example; about 90 s on 2 cores) and compares every quote, the
copied timings and counts included; the fast one shows that the comparison notices a changed or a lost
quote, so the slow one can fail."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest
from support import REPO

DOC_FIGURES = [sys.executable, str(REPO / "benchmarks" / "doc_figures.py")]


def doc_figures(*args, timeout: float = 120.0) -> subprocess.CompletedProcess:
    """benchmarks/doc_figures.py with ``args``, from the repository's folder (a hang guard, not a timing)."""
    return subprocess.run([*DOC_FIGURES, *map(str, args)], cwd=REPO, capture_output=True, text=True, timeout=timeout)


def keys_marked(proc: subprocess.CompletedProcess, what: str = "STALE") -> set[str]:
    """The keys of the check's lines that are not "ok" (``STALE file key ...``), or of the quotes it
    did not find (``what = "(not found)"``)."""
    lines = [line.split() for line in proc.stdout.splitlines() if line.startswith("STALE")]
    return {words[2] for words in lines if what == "STALE" or what in " ".join(words)}


def quoted_figures(root) -> dict[str, str]:
    """The figures as the files quote them now (every quote found)."""
    proc = doc_figures("--quoted", "--root", root)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_the_comparison_notices_a_changed_or_lost_quote(tmp_path):
    for doc in [REPO / "README.md", *(REPO / "docs").glob("*.md")]:       # every file a quote is in
        (tmp_path / doc.relative_to(REPO)).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(doc, tmp_path / doc.relative_to(REPO))
    figures = quoted_figures(tmp_path)
    given = tmp_path / "figures.json"
    given.write_text(json.dumps(figures), encoding="utf-8")
    proc = doc_figures("--check", "--figures", given, "--root", tmp_path)
    assert proc.returncode == 0 and not keys_marked(proc), proc.stdout + proc.stderr
    # a fresh value differing from the quote is stale; writing it makes the files current
    moved = dict(figures, ratio_clean="0.99", **{"fmpy_row.10.0": figures["fmpy_row.10.0"].replace("0.2835", "0.2836", 1)})
    given.write_text(json.dumps(moved), encoding="utf-8")
    proc = doc_figures("--check", "--figures", given, "--root", tmp_path)
    assert proc.returncode == 1 and keys_marked(proc) == {"ratio_clean", "fmpy_row.10.0"}, proc.stdout + proc.stderr
    proc = doc_figures("--write", "--figures", given, "--root", tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.splitlines()[-1] == "rewrote README.md, docs/fmi_hosts.md", proc.stdout
    proc = doc_figures("--check", "--figures", given, "--root", tmp_path)
    assert proc.returncode == 0 and not keys_marked(proc), proc.stdout + proc.stderr
    # a quote edited out of its sentence is reported, not skipped
    readme = tmp_path / "README.md"
    readme.write_text(readme.read_text().replace("largest MAE/threshold in Case 1", "largest ratio"))
    proc = doc_figures("--check", "--figures", given, "--root", tmp_path)
    assert proc.returncode == 1
    assert keys_marked(proc, "(not found)") == {"false_alarms", "ratio_clean", "ratio_noisy",    # one quote: both detectors
                                                "cusum_false_alarms", "cusum_ratio_clean", "cusum_ratio_noisy"}


@pytest.mark.slow
def test_quoted_figures_match_a_fresh_run(fourbar_fmu):
    proc = doc_figures("--check", timeout=1800)
    stale = [line for line in proc.stdout.splitlines() if line.startswith("STALE")]
    assert proc.returncode == 0 and not stale, ("figures in the docs differ from a fresh run; rewrite them with "
                                                "`python benchmarks/doc_figures.py --write`:\n" + "\n".join(stale)
                                                + proc.stderr[-3000:])
