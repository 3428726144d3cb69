"""view.animate: a run folder as a GIF, on short real runs of the native FMUs.

Case 2 cut at 15 s (the fault at 10 s, the monitor's alarm at 10.01 s) and the slider-crank's
fault case cut at 15 s without the monitor.  The frames are read back with Pillow and judged
by their pixels: a colour counts where all three channels are within COLOUR_TOL of it.
"""
from __future__ import annotations

import json
import math
import shutil
import subprocess

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from PIL import Image
from support import FOURBAR_MONITOR, FOURBAR_RUN, case_file

from fourbar_common.contract.run_record import read_run_record
from view.animate import (ALARM_COLOUR, BODY_COLOUR, FAULT_COLOUR, AnimationError, animate, default_window,
                          frame_times)
from view.sources import RunFolderError

# The GIF's palette holds each drawing colour exactly (view.animate reduces every frame to it
# without dithering); 12 of 255 per channel allows a blend step, never another colour.
COLOUR_TOL = 12
# A body 5 pt wide and over 0.5 m long in a panel of ~290 px for ~7 m: hundreds of pixels.
# 100 is far above anti-aliasing specks and far below a drawn body.
BODY_PIXELS = 100


def _run(case: str, fmu, folder, monitor: bool):
    out = folder / "run"
    toml = case_file(case, fmu, folder)
    subprocess.run([FOURBAR_RUN, str(toml), "--fmu", str(fmu), "--stop", "15", "--out", str(out), "--quiet"],
                   check=True, capture_output=True)
    if monitor:
        subprocess.run([FOURBAR_MONITOR, str(out / "exchange.csv")], capture_output=True)   # exit 1: alarm
    return out


@pytest.fixture(scope="module")
def case2_run(native_fmu, tmp_path_factory):
    return _run("case2_fault_L2", native_fmu, tmp_path_factory.mktemp("case2"), monitor=True)


@pytest.fixture(scope="module")
def slider_run(mechanism_fmus, tmp_path_factory):
    return _run("slider_crank_fault_L3", mechanism_fmus.get("slider_crank", "native"),
                tmp_path_factory.mktemp("slider"), monitor=False)


def _frames(path) -> list[np.ndarray]:
    with Image.open(path) as im:
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB")).astype(int))
    return frames


def _count(pixels: np.ndarray, colour: str) -> int:
    want = np.array([round(255 * v) for v in to_rgb(colour)])
    return int((np.abs(pixels - want) <= COLOUR_TOL).all(axis=-1).sum())


def _mechanism_panel(frame: np.ndarray) -> np.ndarray:
    """The left square (where view.animate draws the mechanism) without its bottom tenth (the
    fault note) or its top tenth (the title)."""
    h, w, _ = frame.shape
    return frame[h // 10: h - h // 10, : int(0.9 * h)]


def _signal_panel(frame: np.ndarray) -> np.ndarray:
    h, w, _ = frame.shape
    return frame[:, int(0.9 * h) + 10:]


def test_case2_gif_frames_size_fault_colour_and_alarm(case2_run, tmp_path):
    out = tmp_path / "case2.gif"
    calls = []
    result = animate(case2_run, out, fps=10, speed=3, progress=lambda done, total: calls.append((done, total)))
    # the default window, 5 s before the fault to 10 s after it, is the whole of this 15 s run
    expected = math.floor((15 - 0) * 10 / 3) + 1
    assert (result.start, result.stop, result.frames) == (0.0, 15.0, expected)
    assert result.signal == "x2" and result.not_drawn is None          # the monitor's signal, drawn mechanism
    assert calls == [(k, expected) for k in range(1, expected + 1)]
    assert result.bytes == out.stat().st_size
    with Image.open(out) as im:
        assert (im.n_frames, im.size, im.info["duration"]) == (expected, (640, 320), 100)   # 1000 ms / 10 fps
    # 51 frames of a 640 x 320 picture: more than a blank GIF, well under a README's 2 MB
    assert 20_000 < result.bytes < 1_000_000

    frames = _frames(out)
    times = frame_times(0.0, 15.0, 10, 3)
    before = [f for f, t in zip(frames, times) if t <= 10.0]          # the row at 10 s shows the old L2
    after = [f for f, t in zip(frames, times) if t > 10.0]
    assert all(_count(_mechanism_panel(f), FAULT_COLOUR) == 0 for f in before)
    assert all(_count(_mechanism_panel(f), BODY_COLOUR) >= BODY_PIXELS for f in before)
    assert all(_count(_mechanism_panel(f), FAULT_COLOUR) >= BODY_PIXELS for f in after)   # the crank
    # the alarm (10.01 s, the monitor's events.jsonl) is marked once the cursor reaches it
    alarm = next(json.loads(line)["time"] for line in (case2_run / "monitor" / "events.jsonl").read_text().splitlines()
                 if json.loads(line)["event"] == "alarm")
    assert 10.0 < alarm < 15.0, "precondition: the monitor alarms on Case 2 between the fault and the end"
    for f, t in zip(frames, times):
        assert (_count(_signal_panel(f), ALARM_COLOUR) > 20) == (t >= alarm), t


def test_slider_crank_without_monitor_shows_its_first_output(slider_run, tmp_path):
    out = tmp_path / "slider.gif"
    result = animate(slider_run, out, fps=5, speed=2, start=8.0, stop=14.0, width_px=400)
    expected = math.floor((14 - 8) * 5 / 2) + 1
    assert (result.frames, result.start, result.stop) == (expected, 8.0, 14.0)
    assert result.signal == read_run_record(slider_run / "run.json").outputs[0]
    frames = _frames(out)
    assert len(frames) == expected and frames[0].shape == (200, 400, 3)
    times = frame_times(8.0, 14.0, 5, 2)
    for f, t in zip(frames, times):
        # the rod (L3) turns after 10 s; before, every body is in the body colour (after, the
        # faulted rod is drawn in front and may hide the crank near a dead centre)
        assert (_count(_mechanism_panel(f), FAULT_COLOUR) >= BODY_PIXELS / 2) == (t > 10.0), t
        if t <= 10.0:
            assert _count(_mechanism_panel(f), BODY_COLOUR) >= BODY_PIXELS / 2, t
    # it moves: the mechanism panel changes between consecutive frames
    assert all((a != b).any() for a, b in zip(frames, frames[1:]))


@pytest.mark.parametrize("how", ["drawing null", "column missing"])
def test_a_run_without_drawing_still_animates_the_signal(case2_run, tmp_path, how):
    folder = tmp_path / "run"
    shutil.copytree(case2_run, folder)
    if how == "drawing null":
        data = json.loads((folder / "run.json").read_text())
        data["drawing"] = None
        (folder / "run.json").write_text(json.dumps(data))
    else:
        lines = (folder / "exchange.csv").read_text().splitlines()
        drop = lines[0].split(",").index("A_x")
        (folder / "exchange.csv").write_text(
            "\n".join(",".join(v for i, v in enumerate(line.split(",")) if i != drop) for line in lines) + "\n")
    result = animate(folder, tmp_path / "a.gif", fps=2, speed=5)
    assert result.frames == math.floor((15 - 0) * 2 / 5) + 1
    assert ("no drawing" in result.not_drawn) if how == "drawing null" else ("A_x" in result.not_drawn)
    last = _frames(tmp_path / "a.gif")[-1]
    assert _count(_mechanism_panel(last), BODY_COLOUR) == 0           # no bodies
    assert _count(_mechanism_panel(last), FAULT_COLOUR) == 0
    assert _count(_signal_panel(last), BODY_COLOUR) >= BODY_PIXELS    # the signal is there


def test_bad_output_and_options_are_clear_errors(case2_run, tmp_path, monkeypatch):
    with pytest.raises(AnimationError, match=r"\.png.*\.gif.*\.mp4"):
        animate(case2_run, tmp_path / "x.png")
    with pytest.raises(AnimationError, match="does not exist"):
        animate(case2_run, tmp_path / "no" / "x.gif")
    with pytest.raises(AnimationError, match="fps = 0"):
        animate(case2_run, tmp_path / "x.gif", fps=0)
    with pytest.raises(AnimationError, match=r"stop = 99 s; the run's exchange.csv covers 0 to 15 s"):
        animate(case2_run, tmp_path / "x.gif", stop=99)
    from matplotlib import animation
    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    with pytest.raises(AnimationError, match="ffmpeg.*install"):
        animate(case2_run, tmp_path / "x.mp4")
    assert not any(tmp_path.iterdir())                                # nothing written


def test_a_folder_that_is_not_a_run(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(RunFolderError, match="not a run folder"):
        animate(tmp_path / "empty", tmp_path / "x.gif")
    assert not (tmp_path / "x.gif").exists()


def test_default_window_and_frame_times():
    assert default_window(0.0, 100.0, 10.0) == (5.0, 20.0)            # around the fault
    assert default_window(0.0, 12.0, 10.0) == (0.0, 12.0)             # a short run: whole
    assert default_window(0.0, 100.0, 98.0) == (85.0, 100.0)          # clipped at the end, still 15 s
    assert default_window(0.0, 100.0, None, 40.0) == (35.0, 50.0)     # no fault: around the first alarm
    assert default_window(0.0, 100.0, None) == (0.0, 15.0)
    t = frame_times(5.0, 20.0, 20, 1)
    assert len(t) == 301
    np.testing.assert_allclose(t[-1], 20.0, rtol=0, atol=1e-12)       # an integer count, no drift
    assert len(frame_times(5.0, 15.0, 3, 1)) == 31                    # 10 s at 3 fps: 30 steps of 1/3 s


def test_an_interrupted_animation_leaves_no_partial_file_and_keeps_the_old_one(case2_run, tmp_path):
    out = tmp_path / "a.gif"
    out.write_bytes(b"the previous animation")

    def stop_at_third(done, total):
        if done == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        animate(case2_run, out, fps=2, speed=5, progress=stop_at_third)
    assert out.read_bytes() == b"the previous animation"
    assert [p.name for p in tmp_path.iterdir()] == ["a.gif"]


def test_an_mp4_when_ffmpeg_exists(case2_run, tmp_path):
    """With ffmpeg on the machine (Debian's ffmpeg; CI has none, so this skips there) .mp4 is
    written through matplotlib's FFmpeg writer: ffprobe reads back its frames and size."""
    import shutil
    import subprocess

    from matplotlib import animation
    if not animation.writers.is_available("ffmpeg") or shutil.which("ffprobe") is None:
        pytest.skip("no ffmpeg/ffprobe: .mp4 needs them (apt-get install ffmpeg)")
    result = animate(case2_run, tmp_path / "x.mp4", start=5.0, stop=7.0, fps=10)
    assert result.frames == 21                            # 2 s at 10 frames per run second, both ends
    probe = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
                            "stream=nb_read_frames,width,height", "-of", "csv=p=0", str(result.path)],
                           capture_output=True, text=True, check=True)
    width, height, frames = (int(v) for v in probe.stdout.strip().split(","))
    assert (width, height, frames) == (640, 320, 21), probe.stdout
