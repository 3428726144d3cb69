"""Shared helpers of the orchestrator tests."""
from __future__ import annotations

import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def shipped_case(name: str, fmu: Path, dest: Path, extra: str = "", **exchange) -> Path:
    """cases/<name>.toml copied to ``dest`` with its `fmu` pointing at the test's FMU.

    ``extra`` is appended to the file; ``exchange`` replaces existing ``key = value`` lines
    (e.g. ``flush_interval=0.5``).  The file is otherwise unchanged.
    """
    text = (REPO / "cases" / f"{name}.toml").read_text()
    text, count = re.subn(r"^fmu = .*$", f"fmu = {json.dumps(str(fmu))}", text, flags=re.M)
    assert count == 1
    for key, value in exchange.items():
        text, count = re.subn(rf"^{key} = \S+", f"{key} = {value!r}", text, flags=re.M)
        assert count == 1
    path = dest / f"{name}.toml"
    path.write_text(text + extra)
    return path
