"""A prismatic joint whose guide is on a moving body is drawn where that body is (issue 37).

tests/mechanisms/inverted_slider_crank.toml: a block pinned to the crank slides along a
slotted lever pivoted on the ground, which swings +/- 0.4 rad while the crank turns; a fault
moves the lever's pivot (d 1.0 -> 1.05 m at 3 s).  At every drawn frame the slider's point
(``S_x, S_y``) must lie on the guide drawn for that frame, and the ground marks must be where
the ground joints are: in the geometry both views draw from (:meth:`view.geometry.Geometry.frame`),
in the page's data sources (a headless :class:`view.page.RunPage`, stepped through the run),
and in the GIF's pixels.  Before issue 37 the guide was drawn at its t = 0 angle: the slider
was up to 0.5 m off it.
"""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from matplotlib.colors import to_rgb
from PIL import Image

from fourbar_common.contract.run_record import read_run_record
from support import FOURBAR_RUN, REPO
from view.animate import FIGURE_INCHES, GROUND_COLOUR, animate, frame_times, mechanism_axes
from view.geometry import Geometry

MECHANISM = REPO / "tests" / "mechanisms" / "inverted_slider_crank.toml"
#: m: the slider's distance from its drawn guide.  The exchange file's floats round-trip (17
#: digits) and the FMU's constraint residual is ~1e-12; the guide is drawn with cos/sin of its
#: angle (round-off ~1e-15 m).  A guide frozen at its t = 0 angle puts the slider up to 0.5 m off.
ON_GUIDE_M = 1e-9
#: Pixels: how far from a point of the expected guide its grey may be (a 1-pt line, anti-aliased).
NEAR_PX = 2
#: The GIF's palette holds the guide's grey exactly; 12 of 255 per channel allows one blend step.
COLOUR_TOL = 12

CASE = """\
name = "inverted_slider_crank"
description = "Inverted slider-crank: the lever's pivot moves 5 cm at 3 s"
fmu = {fmu!r}

[experiment]
start = 0.0
stop = 6.0
step = 0.01

[[events]]
type = "step"
time = 3.0
variable = "d"
value = 1.05

[outputs]
variables = ["x2", "y2", "x4", "y4", "theta2", "theta4"]
"""


@pytest.fixture(scope="session")
def inverted_fmu(tmp_path_factory):
    """The inverted slider-crank's native FMU, built once per session."""
    from fmu_src.native_build import find_compiler

    if find_compiler() is None:
        pytest.skip("no C compiler: the native FMU cannot be built here")
    fmu = tmp_path_factory.mktemp("inverted") / "InvertedSliderCrankNative.fmu"
    done = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(MECHANISM), "--only",
                           "native", "--fmi", "2", "--native-out", str(fmu)], cwd=REPO, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return fmu


@pytest.fixture(scope="module")
def inverted_run(inverted_fmu, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("inverted_run")
    case = tmp / "inverted_slider_crank.toml"
    case.write_text(CASE.format(fmu=str(inverted_fmu)))
    out = tmp / "run"
    done = subprocess.run([FOURBAR_RUN, str(case), "--out", str(out), "--quiet"], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return out


def _distance_to_guide(px: float, py: float, xs, ys) -> tuple[float, float]:
    """(distance of (px, py) from the line through the segment, where along it: 0 and 1 at its ends)."""
    (x0, x1), (y0, y1) = xs, ys
    dx, dy = x1 - x0, y1 - y0
    length = math.hypot(dx, dy)
    along = ((px - x0) * dx + (py - y0) * dy) / length ** 2
    return abs((px - x0) * dy - (py - y0) * dx) / length, along


def test_the_run_has_a_turning_guide(inverted_run):
    """The test means something: the guide's angle swings, and the pivot moves at the fault."""
    rows = pd.read_csv(inverted_run / "exchange.csv")
    assert np.ptp(rows["S_gangle"]) > 0.6                      # the lever swings +/- asin(r/d)
    assert np.ptp(rows["theta2"]) > 2 * math.pi                # the crank turns
    assert rows["O4_x"].iloc[0] == -1.0 and rows["O4_x"].iloc[-1] == pytest.approx(-1.05, abs=1e-12)


def test_every_frame_puts_the_slider_on_its_guide(inverted_run):
    record = read_run_record(inverted_run / "run.json")
    rows = pd.read_csv(inverted_run / "exchange.csv")
    geometry = Geometry(record.drawing)
    scene = geometry.scene(rows)
    worst = 0.0
    for _, row in rows.iterrows():
        frame = geometry.frame(row, scene)
        assert len(frame.guides) == 1
        distance, along = _distance_to_guide(row["S_x"], row["S_y"], *frame.guides[0])
        worst = max(worst, distance)
        assert 0.0 < along < 1.0, (row["time"], along)        # on the drawn segment, not past its ends
        # the ground marks: under O2 and the lever's pivot O4 (which the fault moves)
        assert frame.ground == ((row["O2_x"], row["O2_y"]), (row["O4_x"], row["O4_y"])), row["time"]
    assert worst <= ON_GUIDE_M, worst


def test_the_page_draws_the_guide_of_each_instant(inverted_run):
    """The page's ``guides``, ``joints`` and ``ground`` data sources, the clock stepped over the run."""
    from view.page import PageSettings, RunPage

    rows = pd.read_csv(inverted_run / "exchange.csv")
    page = RunPage(inverted_run, PageSettings(at=0.0))
    checked = 0
    for t in np.arange(0.0, 6.0, 0.13):
        page.clock = float(t)
        page.tick()
        i = int(np.searchsorted(rows["time"].to_numpy(), t + 1e-9)) - 1      # the row the page shows
        joints = dict(zip(page.src["joints"].data["name"],
                          zip(page.src["joints"].data["x"], page.src["joints"].data["y"])))
        assert joints["S"] == (rows["S_x"].iloc[i], rows["S_y"].iloc[i]), t
        (xs,), (ys,) = page.src["guides"].data["xs"], page.src["guides"].data["ys"]
        distance, along = _distance_to_guide(*joints["S"], xs, ys)
        assert distance <= ON_GUIDE_M and 0.0 < along < 1.0, (t, distance, along)
        assert page.src["ground"].data["x"][1] == rows["O4_x"].iloc[i], t
        checked += 1
    assert checked == 47


def test_the_gif_draws_the_guide_of_each_frame(inverted_run, tmp_path):
    """In a few frames of the GIF, the guide's grey lies along the guide of that frame's row
    beyond the block (between the block and the guide's end, where no body covers it)."""
    fps, start, stop = 2.0, 0.5, 5.5
    result = animate(inverted_run, tmp_path / "inverted.gif", fps=fps, start=start, stop=stop)
    rows = pd.read_csv(inverted_run / "exchange.csv")
    times = rows["time"].to_numpy()
    index = np.abs(times[:, None] - frame_times(start, stop, fps, 1.0)[None, :]).argmin(axis=0)
    assert result.frames == len(index) == 11
    scene = Geometry(read_run_record(inverted_run / "run.json").drawing).scene(rows.iloc[np.unique(index)])
    (span_name, _, s1), = scene.guide_spans
    grey = np.array([round(255 * v) for v in to_rgb(GROUND_COLOUR)])
    with Image.open(result.path) as im:
        width, height = im.size
        left, bottom, side, _ = mechanism_axes()
        assert width / height == FIGURE_INCHES[0] / FIGURE_INCHES[1]
        x0, y0 = scene.x_range[0], scene.y_range[0]
        per_m = side * width / (scene.x_range[1] - x0)             # px per metre, both ways (a square panel)

        def pixel(x: float, y: float) -> tuple[int, int]:
            return (round(left * width + (x - x0) * per_m), round(height - (bottom * height + (y - y0) * per_m)))

        for k, i in enumerate(index):
            im.seek(k)
            frame = np.asarray(im.convert("RGB")).astype(int)
            is_grey = (np.abs(frame - grey) <= COLOUR_TOL).all(axis=-1)
            row = rows.iloc[i]
            gx, gy, ga = row["S_gx"], row["S_gy"], row["S_gangle"]
            s_block = (row["S_x"] - gx) * math.cos(ga) + (row["S_y"] - gy) * math.sin(ga)
            along = np.linspace(s_block + 0.9 * scene.block_size, s1 - 0.2 * scene.block_size, 8)
            assert along[0] < along[-1], (k, s_block, s1)
            found = 0
            for s in along:
                c, r = pixel(gx + s * math.cos(ga), gy + s * math.sin(ga))
                found += bool(is_grey[r - NEAR_PX:r + NEAR_PX + 1, c - NEAR_PX:c + NEAR_PX + 1].any())
            assert found == len(along), (k, row["time"], found)
