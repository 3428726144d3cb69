#!/usr/bin/env python3
"""fourbar-view following an hour-long run at 100 Hz: server memory and CPU, browser memory,
and the update latency from a row written to the row drawn.

An hour of Case 1 is simulated once on the native FMU (fourbar-run, 360,001 rows of the
four-bar's 14 columns) and replayed by the monitor (harmonic model, CUSUM: its forecast.csv
and evaluations.csv), cached in ``--out``.  A writer thread then appends those files to a live
folder block by block (one second of run per block, as fourbar-run's flush interval), at
``--pace`` times real time, with run.json saying ``running`` and naming this process as its
writer.  ``fourbar-view`` follows the folder; a headless Chromium page (Debian's chromium,
Playwright) stays open on it.  Sampled every second: the server's resident memory and CPU
(psutil, the server process and its children), the page's JavaScript heap (Chrome DevTools
Protocol ``Performance.getMetrics``) and the rows the page's data sources hold.  Latency: the
page records, every 10 ms, the newest time its recent-signal source holds; a block's latency is
from the wall time its last line was written to the first record at or after that time.

With ``--concurrent N`` it measures instead N page loads at once on a finished run (the same
hour, cached): N threads each GET the page (what a browser's first request does: Bokeh builds
the session's document for it) at the same moment; reported are the median and largest time to
the page's last byte, and the server's resident memory before the loads, its largest during
them, after the sessions closed (a session no browser connects to is dropped after 5 s), and
after a second round of N loads (memory bounded: it does not grow by a round's worth).

Usage: python benchmarks/view_load.py [--hours 1] [--pace 30] [--out DIR] [--quick]
       python benchmarks/view_load.py --concurrent 50 [--hours 1] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def native_fmu(out: Path) -> Path:
    built = REPO / "build" / "FourBarNative.fmu"
    if built.exists():
        return built
    dest = out / "FourBarNative.fmu"
    if not dest.exists():
        subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--only", "native", "--native-out", str(dest)],
                       check=True, cwd=REPO, capture_output=True)
    return dest


def source_run(out: Path, seconds: float) -> Path:
    """The cached run: Case 1 for ``seconds`` on the native FMU, replayed by the monitor."""
    folder = out / f"source_{seconds:g}s"
    if (folder / "monitor" / "summary.json").exists():
        return folder
    fmu = native_fmu(out)
    t0 = time.perf_counter()
    subprocess.run([str(BIN / "fourbar-run"), str(REPO / "cases" / "case1_normal.toml"), "--fmu", str(fmu),
                    "--stop", f"{seconds:g}", "--out", str(folder), "--quiet", "--max-rows", "100000000"],
                   check=True)
    subprocess.run([str(BIN / "fourbar-monitor"), str(folder / "exchange.csv"), "--model", "harmonic", "--quiet",
                    "--no-plots"], check=False, stdout=subprocess.DEVNULL)
    print(f"  source run of {seconds:g} s made in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return folder


def _lines(path: Path) -> tuple[bytes, list[bytes], np.ndarray]:
    """(header, data lines, their times) of a CSV whose first column is time."""
    data = path.read_bytes().splitlines(keepends=True)
    times = np.array([float(line.split(b",", 1)[0]) for line in data[1:]])
    return data[0], data[1:], times


class Writer(threading.Thread):
    """Appends the source folder's files to ``live`` one run-second at a time, at ``pace``."""

    def __init__(self, source: Path, live: Path, pace: float):
        super().__init__(daemon=True)
        self.source, self.live, self.pace = source, live, pace
        self.written: list[tuple[float, float]] = []          # (wall time, run time of the block's last row)
        self.done = threading.Event()
        self.stop_now = threading.Event()
        self.files = {}
        for rel in ("exchange.csv", "monitor/evaluations.csv", "monitor/forecast.csv"):
            self.files[rel] = _lines(source / rel)
        events = [json.loads(x) for x in (source / "monitor" / "events.jsonl").read_text().splitlines() if x.strip()]
        self.events = events
        self.record = json.loads((source / "run.json").read_text())

    def _run_json(self, status: str, rows: int, last: float | None) -> None:
        rec = dict(self.record, status=status, rows_written=rows, last_time=last,
                   writer={"pid": os.getpid(), "host": __import__("socket").gethostname(), "heartbeat_s": 2.0},
                   finished_at=None if status == "running" else self.record.get("finished_at"))
        tmp = self.live / "run.json.tmp"
        tmp.write_text(json.dumps(rec))
        os.replace(tmp, self.live / "run.json")

    def run(self) -> None:
        (self.live / "monitor").mkdir(parents=True, exist_ok=True)
        handles = {}
        for rel, (header, _, _) in self.files.items():
            handles[rel] = open(self.live / rel, "wb")
            handles[rel].write(header)
            handles[rel].flush()
        events = open(self.live / "monitor" / "events.jsonl", "w")
        self._run_json("running", 0, None)
        _, lines, times = self.files["exchange.csv"]
        end = float(times[-1])
        cursor = {rel: 0 for rel in self.files}
        ev = 0
        wall0 = time.monotonic()
        t = 0.0
        while t < end and not self.stop_now.is_set():
            t = min(end, t + 1.0)
            target = wall0 + t / self.pace
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            for rel, (_, rows, ts) in self.files.items():
                k = int(np.searchsorted(ts, t + 1e-9, side="right"))
                if k > cursor[rel]:
                    handles[rel].write(b"".join(rows[cursor[rel]:k]))
                    handles[rel].flush()
                    cursor[rel] = k
            while ev < len(self.events) and self.events[ev]["time"] <= t:
                events.write(json.dumps(self.events[ev]) + "\n")
                ev += 1
            events.flush()
            self.written.append((time.time(), float(times[cursor["exchange.csv"] - 1])))
            if int(t) % 2 == 0:
                self._run_json("running", cursor["exchange.csv"], float(times[cursor["exchange.csv"] - 1]))
        for h in handles.values():
            h.close()
        events.close()
        self._run_json("finished", cursor["exchange.csv"], end)
        self.done.set()


RECORDER = """() => {
  window.__drawn = [];
  let last = null;
  setInterval(() => {
    const doc = Bokeh.documents[0];
    const s = doc && doc.get_model_by_name('signal_recent');
    if (!s) return;
    const t = s.data.time;
    const v = t.length ? t[t.length - 1] : null;
    if (v !== last) { last = v; window.__drawn.push([Date.now() / 1000, v]); }
  }, 10);
}"""


def _rss(proc) -> int:
    """Resident memory of ``proc`` and its children, bytes."""
    import psutil

    try:
        return sum(m.memory_info().rss for m in [proc, *proc.children(recursive=True)])
    except psutil.Error:
        return 0


def concurrent_loads(folder: Path, n: int, out: Path, seconds: int) -> int:
    """``n`` page loads at once on the finished run ``folder``: latency and server memory."""
    import urllib.request

    import psutil

    server_log = out / "server_concurrent.log"
    with open(server_log, "w") as log:
        server = subprocess.Popen([str(BIN / "fourbar-view"), str(folder), "--quiet"], stdout=subprocess.PIPE,
                                  stderr=log, text=True)
    try:
        url = server.stdout.readline().strip()
        if not url:
            print(f"view_load: fourbar-view did not start: {server_log.read_text()}", file=sys.stderr)
            return 1
        proc = psutil.Process(server.pid)
        time.sleep(2.0)
        idle = _rss(proc)
        t0 = time.perf_counter()
        with urllib.request.urlopen(url, timeout=600) as response:      # the first load reads the run
            response.read()
        first = time.perf_counter() - t0
        time.sleep(10.0)               # its session dropped
        before = _rss(proc)
        barrier = threading.Barrier(n)
        latencies: list[float] = []
        failures: list[str] = []
        peak = [before]
        done = threading.Event()

        def load() -> None:
            barrier.wait()
            t0 = time.perf_counter()
            try:
                with urllib.request.urlopen(url, timeout=600) as response:
                    response.read()
                latencies.append(time.perf_counter() - t0)
            except OSError as exc:
                failures.append(str(exc))

        def sample() -> None:
            while not done.wait(0.2):
                peak[0] = max(peak[0], _rss(proc))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()

        def round_of_loads() -> float:
            threads = [threading.Thread(target=load) for _ in range(n)]
            t_all = time.perf_counter()
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            return time.perf_counter() - t_all

        wall = round_of_loads()
        after_loads = _rss(proc)
        time.sleep(15.0)               # unused sessions are dropped 5 s after their load, checked every 2 s
        after_close = _rss(proc)
        first_round = list(latencies)
        round_of_loads()               # again: memory bounded means it does not grow by a round's worth
        time.sleep(15.0)
        done.set()
        sampler.join()
        after_second = _rss(proc)
        latencies[:] = first_round
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(timeout=30)
    lat = np.array(latencies) if latencies else np.array([np.nan])
    print(f"Command: `python benchmarks/view_load.py --concurrent {n}` (`--hours {seconds / 3600:g}`). "
          f"{n} page loads at once (one thread each, an HTTP GET of the page, which builds its session) of "
          f"`fourbar-view` on a finished run of {seconds:,} s at 100 Hz; all done in {wall:.1f} s.")
    print()
    print("| measure | value |")
    print("|---|---:|")
    print(f"| page loads answered | {len(latencies)} of {n} |")
    print(f"| time to the page's last byte, median (s; first round) | {np.median(lat):.2f} |")
    print(f"| time to the page's last byte, largest (s; first round) | {np.max(lat):.2f} |")
    print(f"| first page load, alone (s; it reads the run for every later session) | {first:.2f} |")
    print(f"| server resident memory idle, before any load (MB) | {idle / 1e6:.0f} |")
    print(f"| server resident memory before the {n} loads, after the first (MB) | {before / 1e6:.0f} |")
    print(f"| server resident memory, largest during both rounds (MB) | {peak[0] / 1e6:.0f} |")
    print(f"| server resident memory after the loads (MB) | {after_loads / 1e6:.0f} |")
    print(f"| server resident memory 15 s later, the sessions closed (MB) | {after_close / 1e6:.0f} |")
    print(f"| the same after a second round of {n} loads, its sessions closed (MB) | {after_second / 1e6:.0f} |")
    if failures:
        print(f"view_load: {len(failures)} load(s) failed: {failures[0]}", file=sys.stderr)
    return 0 if not failures else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.0, help="length of the run followed (default 1)")
    parser.add_argument("--pace", type=float, default=30.0, help="times real time the rows are written (default 30)")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "benchmarks" / "view")
    parser.add_argument("--quick", action="store_true", help="smoke test: 60 s of run at 20x")
    parser.add_argument("--concurrent", type=int, metavar="N",
                        help="instead: N page loads at once on the finished run (latency, server memory)")
    args = parser.parse_args(argv)
    if args.quick:
        args.hours, args.pace = 60 / 3600, 20.0
    if args.concurrent is not None:
        if args.concurrent < 1:
            parser.error(f"--concurrent: expected a number of loads >= 1, got {args.concurrent}")
        args.out.mkdir(parents=True, exist_ok=True)
        seconds = round(args.hours * 3600)
        return concurrent_loads(source_run(args.out, seconds), args.concurrent, args.out, seconds)
    from view.headless import chromium_path, launch

    if chromium_path() is None:
        print("view_load: no Chromium (`make browser` installs it)", file=sys.stderr)
        return 2
    import psutil
    from playwright.sync_api import sync_playwright

    args.out.mkdir(parents=True, exist_ok=True)
    seconds = round(args.hours * 3600)
    source = source_run(args.out, seconds)
    live = args.out / "live"
    if live.exists():
        shutil.rmtree(live)
    live.mkdir()
    writer = Writer(source, live, args.pace)
    writer._run_json("running", 0, None)
    (live / "exchange.csv").write_bytes(writer.files["exchange.csv"][0])
    server_log = args.out / "server.log"            # a file, not a pipe: a full pipe would stall the server
    with open(server_log, "w") as log:
        server = subprocess.Popen([str(BIN / "fourbar-view"), str(live), "--quiet"], stdout=subprocess.PIPE,
                                  stderr=log, text=True)
    url = server.stdout.readline().strip()
    if not url:
        print(f"view_load: fourbar-view did not start: {server_log.read_text()}", file=sys.stderr)
        return 1
    proc = psutil.Process(server.pid)
    samples = []
    with sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(url)
        page.wait_for_selector("#state", timeout=60_000)
        cdp = page.context.new_cdp_session(page)
        cdp.send("Performance.enable")
        page.evaluate(RECORDER)
        proc.cpu_percent(None)
        writer.start()
        t_start = time.monotonic()
        while not writer.done.is_set():
            time.sleep(1.0)
            try:
                members = [proc, *proc.children(recursive=True)]
                rss = sum(m.memory_info().rss for m in members)
                cpu = proc.cpu_percent(None)
            except psutil.Error:
                break
            metrics = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
            held = page.evaluate("() => ['signal_recent','forecast_recent','statistic','signal_overview']"
                                 ".map(n => { const s = Bokeh.documents[0].get_model_by_name(n);"
                                 " const d = s.data; return d[Object.keys(d)[0]].length; })")
            samples.append((time.monotonic() - t_start, rss, cpu, metrics.get("JSHeapUsedSize", float("nan")),
                            sum(held)))
        time.sleep(2.0)
        drawn = page.evaluate("() => window.__drawn")
        browser.close()
    server.send_signal(signal.SIGTERM)
    server.wait(timeout=30)

    drawn = [(w, t) for w, t in drawn if t is not None]
    if os.environ.get("VIEW_LOAD_DEBUG"):
        Path(args.out / "debug.json").write_text(json.dumps({"written": writer.written, "drawn": drawn}))
    latencies = []
    for wall, t in writer.written:
        first = next((w for w, shown in drawn if shown >= t - 1e-9 and w >= wall - 1e-3), None)
        if first is not None:
            latencies.append(first - wall)
    lat = np.array(latencies)
    s = np.array([x[:4] for x in samples]) if samples else np.zeros((1, 4))
    held = [x[4] for x in samples] or [0]
    wall_total = samples[-1][0] if samples else 0.0
    quarter = max(1, len(s) // 4)
    print(f"Command: `python benchmarks/view_load.py{' --quick' if args.quick else ''}` "
          f"(`--hours {args.hours:g} --pace {args.pace:g}`). A run of {seconds:,} s at 100 Hz "
          f"({len(writer.files['exchange.csv'][1]):,} rows: time and {len(writer.files['exchange.csv'][0].split(b',')) - 1} "
          f"outputs, the four-bar's link centres and joint positions; the monitor's forecast.csv and evaluations.csv) "
          f"is written to a live folder at {args.pace:g}x real time in one-second blocks "
          f"({wall_total:.0f} s of wall time) while `fourbar-view` follows it and a headless Chromium page stays "
          f"open on it. {args.pace:g}x real time is {args.pace:g} times the rows per second of a live run: the CPU "
          f"figures are an upper bound for a run written at real time.")
    print()
    print("| measure | first quarter | last quarter | largest |")
    print("|---|---:|---:|---:|")
    print(f"| server resident memory (MB) | {s[:quarter, 1].mean() / 1e6:.0f} | {s[-quarter:, 1].mean() / 1e6:.0f} | "
          f"{s[:, 1].max() / 1e6:.0f} |")
    print(f"| server CPU (% of one core) | {s[:quarter, 2].mean():.0f} | {s[-quarter:, 2].mean():.0f} | "
          f"{s[:, 2].max():.0f} |")
    print(f"| browser JavaScript heap (MB) | {s[:quarter, 3].mean() / 1e6:.1f} | {s[-quarter:, 3].mean() / 1e6:.1f} | "
          f"{s[:, 3].max() / 1e6:.1f} |")
    print(f"| rows held by the page's plots | {np.mean(held[:quarter]):,.0f} | {np.mean(held[-quarter:]):,.0f} | "
          f"{max(held):,} |")
    print()
    if len(lat):
        print(f"Update latency, row written to row drawn (the page's recent-signal source), over "
              f"{len(lat):,} of {len(writer.written):,} blocks: median {np.median(lat) * 1e3:.0f} ms, 95th percentile "
              f"{np.percentile(lat, 95) * 1e3:.0f} ms, largest {lat.max() * 1e3:.0f} ms (the page polls every "
              f"250 ms). Page errors: {len(errors)}.")
    else:
        print("Update latency: no block was seen drawn.")
    if len(lat) < len(writer.written):
        print(f"view_load: {len(writer.written) - len(lat)} of {len(writer.written)} blocks were never drawn",
              file=sys.stderr)
    return 0 if len(lat) == len(writer.written) and not errors else 1


if __name__ == "__main__":
    sys.exit(main())
