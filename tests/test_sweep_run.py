"""Sweeps on a real 2-worker Dask LocalCluster (worker processes), with the real FMU and monitor.

One run of sweeps/smoke.toml (8 scenarios of 20 s, harmonic model) is shared by the tests
through a module fixture, and one cluster serves every run of the module.  Checked: one row
per scenario with plausible figures (larger faults detected at least as often and no
later; no false alarm without noise); a sweep stopped after a few scenarios (``limit``), then
resumed through the scheduler's address (as ``--scheduler`` does), gives the uninterrupted
table exactly (every one of its 8 rows run again in a new folder: the same sweep twice gives
identical results); a sweep stopped by Ctrl-C on the command line keeps its finished rows,
each the uninterrupted run's, and a resume skips them; a scenario whose fault cannot be
assembled (L2 -> 10 m) is a failed row carrying the FMU's message while the sweep goes on
(CLI exit 1).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pandas.testing as pdt
import pytest

from sweep import RUNTIME_COLUMNS, load_sweep, plan_scenarios, run_sweep
from sweep.cli import main
from support import REPO, case_file

pytestmark = pytest.mark.slow



def comparable(table: pd.DataFrame) -> pd.DataFrame:
    """The table without the columns that record how long and where a scenario ran."""
    return table.drop(columns=list(RUNTIME_COLUMNS)).reset_index(drop=True)


@pytest.fixture(scope="module")
def smoke_file(tmp_path_factory, fourbar_fmu) -> Path:
    directory = tmp_path_factory.mktemp("sweep_files")
    case = case_file("case1_normal", fourbar_fmu, directory)
    text = (REPO / "sweeps" / "smoke.toml").read_text()
    path = directory / "smoke.toml"
    path.write_text(text.replace('case = "../cases/case1_normal.toml"', f'case = "{case}"'))
    return path


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 worker processes, one thread each (what fourbar-sweep starts)."""
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc, \
            Client(lc) as client:
        yield client


@pytest.fixture(scope="module")
def first_run(smoke_file, cluster, tmp_path_factory):
    return run_sweep(smoke_file, tmp_path_factory.mktemp("first"), client=cluster)


def test_one_row_per_scenario_with_plausible_results(first_run, smoke_file):
    result, table = first_run, first_run.table
    plan = plan_scenarios(load_sweep(smoke_file))
    assert result.planned == len(plan) == 8 and result.ran == 8 and result.complete
    assert list(table["scenario_id"]) == [s.id for s in plan]
    assert (table["status"] == "ok").all(), table[["scenario_id", "error"]]
    for std, group in table.groupby("noise_std"):
        faults = group[group["has_fault"]].sort_values("relative_change")
        detected = faults["detected"].astype(bool).to_numpy()
        # larger faults are detected at least as often ...
        assert all(a <= b for a, b in zip(detected, detected[1:])), faults
        # ... and no later
        latency = faults["latency"].to_numpy()
        seen = latency[detected]
        assert all(a >= b for a, b in zip(seen, seen[1:])), faults
        assert detected[-1] and latency[-1] <= 1.0        # +10 % of L2 is seen within a second
    noise_free = table[table["noise_std"] == 0]
    assert (noise_free["false_alarms"] == 0).all()
    clean = noise_free[~noise_free["has_fault"]]
    assert len(clean) == 1 and clean["alarms"].iloc[0] == 0 and not clean["detected"].iloc[0]
    # every file a user is told about exists, and the Parquet table is the CSV table
    for key in ("csv", "parquet", "detection_plot", "roc_plot", "summary"):
        assert Path(result.files[key]).stat().st_size > 0
    pdt.assert_frame_equal(pd.read_parquet(result.files["parquet"]), table)
    for sid in table["scenario_id"]:
        run_dir = result.out_dir / "runs" / sid
        assert (run_dir / "exchange.csv").exists() and (run_dir / "run.json").exists()
        assert (run_dir / "monitor" / "events.jsonl").exists()


def test_stopped_after_k_scenarios_then_resumed_equals_uninterrupted(first_run, smoke_file, cluster, tmp_path,
                                                                     monkeypatch):
    """Also the same sweep twice: the 3 + 5 rows run here in a new folder equal the module's
    first run exactly (a separate 8-scenario rerun checked only that, and cost a quarter of
    the module)."""
    import sweep.runner

    monkeypatch.setattr(sweep.runner, "PARQUET_INTERVAL", 0.0)    # results.parquet after every row too
    out = tmp_path / "resumed"
    part = run_sweep(smoke_file, out, client=cluster, limit=3)
    assert part.ran == 3 and len(part.table) == 3 and not part.complete
    pdt.assert_frame_equal(pd.read_parquet(out / "results.parquet"), part.table)
    # the rest through the scheduler's address, as `fourbar-sweep --scheduler ADDRESS` connects
    rest = run_sweep(smoke_file, out, scheduler=cluster.scheduler.address)
    assert rest.skipped == 3 and rest.ran == 5 and rest.complete
    pdt.assert_frame_equal(comparable(rest.table), comparable(first_run.table), check_exact=True)
    nothing = run_sweep(smoke_file, out, client=cluster)
    assert nothing.ran == 0 and nothing.skipped == 8


def test_ctrl_c_on_the_command_line_keeps_rows_and_resumes(first_run, smoke_file, cluster, tmp_path):
    out = tmp_path / "interrupted"
    csv = out / "results.csv"
    # its own process group, so SIGINT reaches the sweep and its workers, as Ctrl-C in a terminal does
    proc = subprocess.Popen([sys.executable, "-m", "sweep.cli", str(smoke_file), "--workers", "2", "--out", str(out),
                             "--quiet"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 90
        rows = 0
        while time.monotonic() < deadline and proc.poll() is None:
            rows = csv.read_text().count("\n") - 1 if csv.exists() else 0
            if rows >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"the sweep ended before it could be interrupted: {proc.communicate()}"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert "run the same command again to resume" in err and "Traceback" not in err, err
    kept = pd.read_parquet(out / "results.parquet")
    assert 2 <= len(kept) < 8, err
    # a resume skips the kept rows and goes on from them: one more scenario shows it (the whole
    # resumed table equal to the uninterrupted one is test_stopped_after_k_scenarios_...'s; the
    # rows here are compared with the uninterrupted run's, row by row)
    resumed = run_sweep(smoke_file, out, client=cluster, limit=1)
    assert resumed.skipped == len(kept) and resumed.ran == 1 and not resumed.complete
    ids = list(resumed.table["scenario_id"])
    assert len(ids) == len(kept) + 1 and set(kept["scenario_id"]) < set(ids)
    expected = first_run.table.set_index("scenario_id", drop=False).loc[ids]
    pdt.assert_frame_equal(comparable(resumed.table), comparable(expected), check_exact=True)


def test_a_failing_scenario_is_a_failed_row_and_the_sweep_goes_on(smoke_file, cluster, tmp_path, capsys):
    case = smoke_file.parent / "case1_normal.toml"
    path = tmp_path / "fail.toml"
    path.write_text(f'case = "{case}"\nstop = 12.0\n[fault]\nvariable = "L2"\nvalue = [10.0, 1.05]\ntime = 10.0\n'
                    '[monitor]\nmodel = "harmonic"\n')
    out = tmp_path / "fail"
    # the command line, on the module's cluster (--scheduler): exit 1 because a scenario failed
    assert main([str(path), "--scheduler", cluster.scheduler.address, "--out", str(out), "--quiet"]) == 1
    assert "1 scenario(s) failed" in capsys.readouterr().err
    table = pd.read_parquet(out / "results.parquet")
    assert len(table) == 2
    bad = table[table["fault_value"] == 10.0].iloc[0]
    good = table[table["fault_value"] == 1.05].iloc[0]
    assert bad["status"] == "failed" and "cannot apply L2" in bad["error"] and "loop cannot be closed" in bad["error"]
    assert pd.isna(bad["detected"]) and bad["rows_written"] > 0
    assert good["status"] == "ok" and good["detected"]
    # a failed row counts as done; --retry-failed runs it again and keeps the old row in stale.csv
    assert run_sweep(path, out, client=cluster).ran == 0
    again = run_sweep(path, out, client=cluster, retry_failed=True)
    assert again.ran == 1 and again.failed == 1
    stale = pd.read_csv(out / "stale.csv")
    assert list(stale["scenario_id"]) == [bad["scenario_id"]] and "retry" in stale["stale_reason"][0]


def test_new_latency_limit_rescores_without_running(first_run, smoke_file, cluster, tmp_path):
    import shutil

    out = tmp_path / "rescored"
    shutil.copytree(first_run.out_dir, out)
    path = smoke_file.parent / "smoke_limit1.toml"
    path.write_text(smoke_file.read_text().replace("latency_limit = 2.0", "latency_limit = 1.0"))
    result = run_sweep(path, out, client=cluster)
    assert result.ran == 0 and result.skipped == 8
    table, before = result.table, first_run.table
    assert (table["latency_limit"][table["status"] == "ok"] == 1.0).all()
    faults = table["has_fault"].to_numpy(dtype=bool)
    # a shorter horizon can only lower the early score; everything else is unchanged
    assert (table["score_early"][faults] <= before["score_early"][faults]).all()
    same = [c for c in table.columns if c not in ("score_early", "latency_limit")]
    pdt.assert_frame_equal(table[same], before[same])


def _pixels_of(png: Path, color: str, box: tuple[float, float, float, float]) -> int:
    """Pixels within 0.12 (per channel, of 1) of ``color`` in ``box`` = (x0, x1, y0, y1),
    fractions of the image's width and height from its top left corner."""
    import numpy as np
    from matplotlib.image import imread

    img = imread(png)[..., :3]
    h, w = img.shape[:2]
    x0, x1, y0, y1 = box
    part = img[int(y0 * h):int(y1 * h), int(x0 * w):int(x1 * w)]
    rgb = np.array([int(color[i:i + 2], 16) for i in (1, 3, 5)]) / 255
    return int((np.abs(part - rgb).max(axis=-1) < 0.12).sum())


def test_series_that_coincide_stay_visible(first_run):
    """In the smoke sweep both noise levels detect every fault (a detection rate of 1.0 along
    the top of detection.png's left panel) and have the same ROC curve (along roc.png's top
    edge).  Both colours must show there.  Drawn one over the other, the first series left
    0 and 103 pixels in those bands; layered, it leaves about 1700 and 2400."""
    blue, orange = "#1f77b4", "#ff7f0e"        # matplotlib's first two colours: no noise, noise
    bands = {"detection_plot": (0.0, 0.5, 0.08, 0.25), "roc_plot": (0.1, 0.95, 0.03, 0.2)}
    for key, box in bands.items():
        png = Path(first_run.files[key])
        for color in (blue, orange):
            assert _pixels_of(png, color, box) >= 300, (png.name, color)


def _occupy(port: int):
    """A socket listening on 127.0.0.1:``port``, or None when something else already holds the
    port (then it is taken either way, which is what the test needs)."""
    import socket

    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.bind(("127.0.0.1", port))
        sock.listen(1)
    except OSError:
        sock.close()
        return None
    return sock


def _http_status(url: str) -> int:
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status
    except urllib.error.HTTPError as exc:
        return exc.code


def test_a_local_cluster_without_dashboard_says_nothing_about_port_8787():
    """fourbar-sweep without --dashboard, while port 8787 is taken (another sweep, a
    dashboard): distributed's scheduler still bound its HTTP API to 8787 by default and
    warned "Port 8787 is already in use ... Hosting the HTTP server on port N instead".
    Now that API takes any free loopback port: no warning, no dashboard, nothing on 8787."""
    import warnings

    from sweep.runner import open_client

    holder = _occupy(8787)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with open_client(workers=1) as client:
                http = client.cluster.scheduler.http_server
                assert http.port != 8787 and http.address == "127.0.0.1", (http.address, http.port)
                base = f"http://127.0.0.1:{http.port}"
                assert _http_status(f"{base}/health") == 200          # the scheduler's API answers ...
                assert _http_status(f"{base}/status") == 404          # ... but serves no dashboard
    finally:
        if holder is not None:
            holder.close()
    said = [str(w.message) for w in caught if "port" in str(w.message).lower() or "dashboard" in str(w.message).lower()]
    assert said == [], said


def _get(host: str, port: int, path: str, headers: dict[str, str]) -> int:
    """Status of a GET to 127.0.0.1:port with these headers (Host among them)."""
    import http.client

    c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    try:
        c.putrequest("GET", path, skip_host=True)
        for k, v in {"Host": host, **headers}.items():
            c.putheader(k, v)
        c.endheaders()
        r = c.getresponse()
        r.read()
        return r.status
    finally:
        c.close()


def _listening(port: int) -> set[str]:
    import psutil

    return {c.laddr.ip for c in psutil.Process().net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN and c.laddr.port == port}


def test_a_local_cluster_with_dashboard_serves_it_where_asked():
    """--dashboard :0 serves the Bokeh dashboard on 127.0.0.1 (a port given alone is loopback;
    distributed binds ":PORT" to every interface), the link names the port really bound,
    requests naming another host get 403 (DNS rebinding), and its websocket refuses another
    origin even with BOKEH_ALLOW_WS_ORIGIN set (distributed's default origin list is "*")."""
    from sweep.runner import dashboard_link, open_client
    from view.served import ignore_bokeh_environment

    os.environ["BOKEH_ALLOW_WS_ORIGIN"] = "evil.example"
    ignore_bokeh_environment()                    # what fourbar-sweep --dashboard does first
    assert "BOKEH_ALLOW_WS_ORIGIN" not in os.environ
    with open_client(workers=1, dashboard=":0") as client:
        http = client.cluster.scheduler.http_server
        assert _listening(http.port) == {"127.0.0.1"}
        link = dashboard_link(client)
        assert link == f"http://127.0.0.1:{http.port}/status"
        assert _http_status(link) == 200                             # .../status: the dashboard page
        assert _get(f"localhost:{http.port}", http.port, "/status", {}) == 200
        assert _get(f"evil.example:{http.port}", http.port, "/status", {}) == 403
        assert _get("evil.example", http.port, "/health", {}) == 403
        ws = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
              "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}
        assert _get(f"127.0.0.1:{http.port}", http.port, "/status/ws", {**ws, "Origin": "http://evil.example"}) == 403
        assert _get(f"127.0.0.1:{http.port}", http.port, "/status/ws",
                    {**ws, "Origin": f"http://127.0.0.1:{http.port}"}) == 101


def test_a_dashboard_on_another_address_is_warned_about_and_bad_ones_refused(smoke_file, tmp_path):
    """--dashboard 0.0.0.0:8787 says the dashboard is reachable and has no authentication
    (--dry-run: nothing is served); an address that is not one exits 2 naming it."""
    done = subprocess.run([sys.executable, "-m", "sweep.cli", str(smoke_file), "--dashboard", "0.0.0.0:8787",
                           "--dry-run", "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "warning" in done.stderr and "0.0.0.0:8787" in done.stderr and "no authentication" in done.stderr
    for bad in ("0.0.0.0:99999", "tcp://x:1", "no.such.host.invalid:8787", "192.0.2.1:8787"):  # TEST-NET-1
        done = subprocess.run([sys.executable, "-m", "sweep.cli", str(smoke_file), "--dashboard", bad, "--dry-run",
                               "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
        assert done.returncode == 2 and "--dashboard" in done.stderr and "Traceback" not in done.stderr, done.stderr
