#!/usr/bin/env python3
"""The README's animation and screenshot of the live page, from a finished Case 2 run folder.

Writes docs/img/case2.gif (``fourbar-view RUN_DIR --animate``: the linkage beside its signal,
5 s before to 10 s after the fault) and docs/img/view.png (the page of ``fourbar-view RUN_DIR
--at 10.5`` in headless Chromium, 1400 x 900).  ``benchmarks/doc_figures.py --write`` calls it
on make demo's run, so both are renewed with the other README figures.

Usage: python scripts/readme_media.py RUN_DIR [--at 10.5] [--gif docs/img/case2.gif] [--png docs/img/view.png]
"""
from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def screenshot(run_dir: Path, png: Path, at: float) -> None:
    from playwright.sync_api import sync_playwright

    from view.headless import launch

    server = subprocess.Popen([str(BIN / "fourbar-view"), str(run_dir), "--quiet", "--at", f"{at:g}"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = server.stdout.readline().strip()
        if not url:
            raise SystemExit(f"readme_media: fourbar-view did not start: {server.stderr.read()}")
        with sync_playwright() as p:
            browser = launch(p)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(url)
            page.wait_for_selector("#verdict", timeout=60_000)      # everything read, diagnosis included
            time.sleep(1.5)                                        # one more tick: plots drawn
            page.screenshot(path=str(png))
            browser.close()
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(timeout=30)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--at", type=float, default=10.5, help="run time of the screenshot (default 10.5 s)")
    parser.add_argument("--gif", type=Path, default=REPO / "docs" / "img" / "case2.gif")
    parser.add_argument("--png", type=Path, default=REPO / "docs" / "img" / "view.png")
    args = parser.parse_args(argv)
    from view.animate import animate

    result = animate(args.run_dir, args.gif)
    print(f"wrote {args.gif} ({result.frames} frames, {result.bytes / 1e6:.2f} MB)")
    screenshot(args.run_dir, args.png, args.at)
    print(f"wrote {args.png} ({args.png.stat().st_size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
