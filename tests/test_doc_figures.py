"""The figures quoted in README.md and docs/ match a fresh run (benchmarks/doc_figures.py).

The slow test measures (12 fourbar-run runs and their replays, one simulate_fmu, make demo at
10x real time, the libcosim example; about 90 s on 2 cores) and compares every quote, the
copied timings and counts included; the fast one shows that the comparison notices a changed or a lost
quote, so the slow one can fail."""
from __future__ import annotations

import shutil
import sys

import pytest
from support import REPO

sys.path.insert(0, str(REPO / "benchmarks"))
import doc_figures  # noqa: E402


def quoted_figures(root) -> dict[str, str]:
    """The figures as the files quote them now (every quote found)."""
    findings = doc_figures.compare({key: "" for q in doc_figures.QUOTES for key in q.keys}, root)
    assert all(f.quoted is not None for f in findings), [f for f in findings if f.quoted is None]
    return {f.key: f.quoted for f in findings}


def test_the_comparison_notices_a_changed_or_lost_quote(tmp_path):
    for quote in doc_figures.QUOTES:
        (tmp_path / quote.file).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / quote.file, tmp_path / quote.file)
    figures = quoted_figures(tmp_path)
    assert all(f.ok for f in doc_figures.compare(figures, tmp_path))
    # a fresh value differing from the quote is stale; writing it makes the files current
    moved = dict(figures, ratio_clean="0.99", **{"fmpy_row.10.0": figures["fmpy_row.10.0"].replace("0.2835", "0.2836", 1)})
    stale = {f.key for f in doc_figures.compare(moved, tmp_path) if not f.ok}
    assert stale == {"ratio_clean", "fmpy_row.10.0"}
    assert set(doc_figures.rewrite(moved, tmp_path)) == {"README.md", "docs/fmi_hosts.md"}
    assert all(f.ok for f in doc_figures.compare(moved, tmp_path))
    # a quote edited out of its sentence is reported, not skipped
    readme = tmp_path / "README.md"
    readme.write_text(readme.read_text().replace("largest MAE/threshold in Case 1", "largest ratio"))
    lost = [f for f in doc_figures.compare(moved, tmp_path) if f.quoted is None]
    assert {f.key for f in lost} == {"false_alarms", "ratio_clean", "ratio_noisy",    # one quote: both detectors
                                     "cusum_false_alarms", "cusum_ratio_clean", "cusum_ratio_noisy"}


@pytest.mark.slow
def test_quoted_figures_match_a_fresh_run(tmp_path, fourbar_fmu):
    figures = doc_figures.all_figures(tmp_path)
    stale = [f for f in doc_figures.compare(figures) if not f.ok]
    assert not stale, ("figures in the docs differ from a fresh run; rewrite them with "
                       "`python benchmarks/doc_figures.py --write`:\n"
                       + "\n".join(f"{f.file}: {f.key}: quoted {f.quoted}, fresh {f.fresh}" for f in stale))
