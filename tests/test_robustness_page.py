"""docs/robustness.md is written in three parts by two commands (benchmarks/robustness.py for the
four-bar and, with --mechanisms, the user-style families; benchmarks/fuzz_inputs.py for the
fuzzing part): each write must replace its own part and keep the others byte for byte.  The
write is benchmarks/robustness_page.py's, run here as a program (tests do not import benchmark
code)."""
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO

#: The headings that open the user-style part and the fuzzing part (docs/robustness.md's).
USER_PART = "# User-style mechanisms\n"
KEPT_FROM = "# Fuzzed input files\n"
FOUR = "# Robustness beyond Table 1\n\nfour-bar table\n"
USER = USER_PART + "\nuser table\n"
FUZZ = KEPT_FROM + "\nfuzz table\n"


def write_part(page: Path, part: str, text: str) -> str:
    """``benchmarks/robustness_page.py part TEXT page`` (TEXT a file holding ``text``); the page after it."""
    given = page.with_name("part.md")
    given.write_text(text, encoding="utf-8")
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "robustness_page.py"), part, str(given),
                           str(page)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return page.read_text(encoding="utf-8")


@pytest.mark.parametrize("page", [FOUR + "\n" + USER + "\n" + FUZZ, FOUR + "\n" + FUZZ, FOUR, ""])
def test_a_user_part_write_keeps_the_four_bar_and_fuzz_parts(tmp_path, page):
    path = tmp_path / "robustness.md"
    path.write_text(page)
    new_user = USER_PART + "\nnew user table\n"
    text = write_part(path, "user", new_user)
    assert new_user in text
    assert "\nuser table" not in text
    if FOUR in page:
        assert text.startswith(FOUR)
    if FUZZ in page:
        assert text.endswith(FUZZ)
        assert text.index(new_user) < text.index(KEPT_FROM)


def test_a_four_bar_write_keeps_the_user_and_fuzz_parts(tmp_path):
    path = tmp_path / "robustness.md"
    path.write_text(FOUR + "\n" + USER + "\n" + FUZZ)
    new_four = "# Robustness beyond Table 1\n\nnew four-bar table\n"
    text = write_part(path, "four-bar", new_four)
    assert text.startswith(new_four) and USER in text and text.endswith(FUZZ)
    assert "\nfour-bar table" not in text


def test_the_headings_are_the_pages():
    """The headings this test writes are the ones docs/robustness.md has (so the test's pages are real ones)."""
    text = (REPO / "docs" / "robustness.md").read_text(encoding="utf-8")
    assert ("\n" + USER_PART) in text and ("\n" + KEPT_FROM) in text
