"""Headless Chromium for the view's tests, benchmark and README screenshot: one home for how
it is found and started.

Debian's ``chromium`` (``make browser`` installs it) driven by Playwright's Python package
with ``executable_path`` (Playwright's own browser download is not used).  On a machine with no
network, Chromium must not try its background connections, and as root it needs
``--no-sandbox``.  Playwright is imported by the callers, not here.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

__all__ = ["CHROMIUM_ARGS", "chromium_path", "launch"]

#: Flags for a headless Chromium on a closed network (and as root).
CHROMIUM_ARGS = ("--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-quic")


def chromium_path() -> Path | None:
    """The Chromium to drive: $CHROMIUM, else chromium on PATH, else /usr/bin/chromium; None
    when there is none."""
    found = os.environ.get("CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
    return Path(found) if Path(found).exists() else None


def launch(playwright):
    """A headless Chromium browser from a started ``sync_playwright()``; RuntimeError naming
    the fix when there is no Chromium."""
    path = chromium_path()
    if path is None:
        raise RuntimeError("no Chromium: `make browser` installs Debian's chromium (or set CHROMIUM=/path)")
    return playwright.chromium.launch(executable_path=str(path), args=list(CHROMIUM_ARGS))
