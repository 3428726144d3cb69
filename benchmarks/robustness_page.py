#!/usr/bin/env python3
"""docs/robustness.md in three parts written by two commands: the four-bar part
(``benchmarks/robustness.py --write``), the user-style mechanisms' part (``robustness.py
--mechanisms --write``) and the fuzzing part (``benchmarks/fuzz_inputs.py --write``, its own
marked section).  Each write replaces its own part and keeps the others byte for byte.

Usage: python benchmarks/robustness_page.py {four-bar,user} PART PAGE
  puts the text of the file PART into PAGE as its four-bar or user part (what
  robustness.py --write does with the part it generates); exit 0, 2 usage error.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["KEPT_FROM", "USER_PART", "write_part"]

#: Where this page's part ends: what follows belongs to benchmarks/fuzz_inputs.py (its own
#: marked section), which ``--write`` keeps as it is.
KEPT_FROM = "# Fuzzed input files\n"
#: The part ``--mechanisms`` writes, between the four-bar part and KEPT_FROM.
USER_PART = "# User-style mechanisms\n"


def _read(page: Path) -> str:
    try:
        return page.read_text(encoding="utf-8")
    except OSError:
        return ""


def _split(text: str) -> tuple[str, str, str]:
    """``text`` as (four-bar part, user part, what follows): each "" when absent."""
    fuzz = text.find("\n" + KEPT_FROM)
    fuzz = len(text) if fuzz < 0 else fuzz + 1
    user = text.find("\n" + USER_PART, 0, fuzz)
    user = fuzz if user < 0 else user + 1
    return text[:user], text[user:fuzz], text[fuzz:]


def kept_part(page: Path) -> str:
    """What of ``page`` follows the four-bar part (the user part and KEPT_FROM on; "" when absent)."""
    _four, user, rest = _split(_read(page))
    return "" if not (user or rest) else "\n" + user + rest


def page_with_user_part(page: Path, part: str) -> str:
    """``page`` with its user part replaced by ``part`` (inserted before KEPT_FROM if absent)."""
    four, _user, rest = _split(_read(page))
    four = four.rstrip("\n") + "\n\n" if four.strip() else ""
    return four + part + ("\n" + rest if rest else "")


def write_part(page: Path, part: str, text: str) -> None:
    """Put ``text`` into ``page`` as its ``part`` ("four-bar" or "user"), keeping the other parts."""
    if part == "user":
        new = page_with_user_part(page, text)
    else:
        new = text + kept_part(page)
    page.write_text(new, encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=("four-bar", "user"), help="the part PART's text replaces")
    ap.add_argument("text", type=Path, metavar="PART", help="a file holding the part's new text")
    ap.add_argument("page", type=Path, metavar="PAGE", help="the page (created when absent)")
    args = ap.parse_args(argv)
    try:
        text = args.text.read_text(encoding="utf-8")
    except OSError as exc:
        ap.error(f"{args.text}: {exc.strerror}")
    write_part(args.page, args.part, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
