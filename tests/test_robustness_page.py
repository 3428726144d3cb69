"""docs/robustness.md is written in three parts by two commands (benchmarks/robustness.py for the
four-bar and, with --mechanisms, the user-style families; benchmarks/fuzz_inputs.py for the
fuzzing part): each write must replace its own part and keep the others byte for byte."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import robustness as R  # noqa: E402

FOUR = "# Robustness beyond Table 1\n\nfour-bar table\n"
USER = R.USER_PART + "\nuser table\n"
FUZZ = R.KEPT_FROM + "\nfuzz table\n"


@pytest.mark.parametrize("page", [FOUR + "\n" + USER + "\n" + FUZZ, FOUR + "\n" + FUZZ, FOUR, ""])
def test_a_user_part_write_keeps_the_four_bar_and_fuzz_parts(tmp_path, page):
    path = tmp_path / "robustness.md"
    path.write_text(page)
    new_user = R.USER_PART + "\nnew user table\n"
    text = R._page_with_user_part(path, new_user)
    assert new_user in text
    assert "\nuser table" not in text
    if FOUR in page:
        assert text.startswith(FOUR)
    if FUZZ in page:
        assert text.endswith(FUZZ)
        assert text.index(new_user) < text.index(R.KEPT_FROM)


def test_a_four_bar_write_keeps_the_user_and_fuzz_parts(tmp_path):
    path = tmp_path / "robustness.md"
    path.write_text(FOUR + "\n" + USER + "\n" + FUZZ)
    new_four = "# Robustness beyond Table 1\n\nnew four-bar table\n"
    text = new_four + R._kept_part(path)
    assert text.startswith(new_four) and USER in text and text.endswith(FUZZ)
    assert "\nfour-bar table" not in text
