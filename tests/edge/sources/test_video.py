"""VideoSource on real video files written here with OpenCV."""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from superbody.edge.sources.source import SourceError
from superbody.edge.sources.video import VideoSource


def write_video(path: Path, frames: int, fps: float, width: int = 64, height: int = 48) -> Path:
    """An MJPG AVI (at most 32 frames) whose frame i is a flat grey of level 8 * i (readable back within JPEG error)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, height))
    assert writer.isOpened()
    for i in range(frames):
        writer.write(np.full((height, width, 3), 8 * i, np.uint8))
    writer.release()
    return path


def level(image: np.ndarray) -> int:
    return int(round(float(image.mean()) / 8))


def test_file_frames_as_fast_as_taken_carry_their_position_in_the_file(tmp_path):
    path = write_video(tmp_path / "v.avi", 12, fps=25.0)
    src = VideoSource("video", str(path), 64, 48, realtime=False)
    t0 = time.time_ns()
    frames = list(src.frames())
    t1 = time.time_ns()
    assert [level(f.image) for f in frames] == list(range(12))
    assert all(f.image.shape == (48, 64, 3) and f.image.dtype == np.uint8 and f.people is None for f in frames)
    assert all((f.width, f.height) == (64, 48) for f in frames)
    stamps = np.array([f.stamp_ns for f in frames])
    assert t0 <= stamps[0] <= t1
    np.testing.assert_allclose(np.diff(stamps), 1e9 / 25, atol=1)  # the file's times, not the reading's
    assert t1 - t0 < 0.48e9 * 0.5  # not paced: much faster than the 0.48 s the file lasts
    src.close()


def test_file_frames_in_real_time_arrive_at_their_capture_times(tmp_path):
    path = write_video(tmp_path / "v.avi", 10, fps=50.0)
    src = VideoSource("video", str(path), 64, 48)
    arrivals, stamps = [], []
    for f in src.frames():
        arrivals.append(time.time_ns())
        stamps.append(f.stamp_ns)
    assert len(stamps) == 10 and src.skipped == 0
    late_ms = (np.array(arrivals) - np.array(stamps)) / 1e6
    assert (late_ms >= 0).all() and np.median(late_ms) < 10, late_ms  # delivered at, not before, capture time
    assert (stamps[-1] - stamps[0]) == pytest.approx(9 * 20e6, abs=1)


def test_a_slow_node_skips_frames_in_real_time(tmp_path):
    path = write_video(tmp_path / "v.avi", 30, fps=50.0)
    src = VideoSource("video", str(path), 64, 48)
    got = []
    for f in src.frames():
        got.append((f.stamp_ns, level(f.image)))
        time.sleep(0.05)  # 2.5 frame periods per frame
    first = got[0][0]
    assert 6 <= len(got) <= 16 and src.skipped == 30 - len(got)
    for stamp, lvl in got:  # each delivered frame still carries its own time and content
        assert round((stamp - first) / 20e6) == lvl


def test_loop_starts_again_and_time_goes_on(tmp_path):
    path = write_video(tmp_path / "v.avi", 5, fps=25.0)
    src = VideoSource("video", str(path), 64, 48, realtime=False, loop=True)
    frames = []
    for f in src.frames():
        frames.append(f)
        if len(frames) == 12:
            break
    src.close()
    assert [level(f.image) for f in frames] == [0, 1, 2, 3, 4] * 2 + [0, 1]
    np.testing.assert_allclose(np.diff([f.stamp_ns for f in frames]), 40e6, atol=1)


def test_wrong_size_names_both_sizes(tmp_path):
    path = write_video(tmp_path / "v.avi", 3, fps=25.0)
    with pytest.raises(SourceError, match=r"video:.*v\.avi delivers 64x48 images but the site's camera is 640x480"):
        VideoSource("video", str(path), 640, 480)


# (kind, target, fragment of the error)
UNOPENABLE = [
    ("video", "/nonexistent/clip.mp4", "video:/nonexistent/clip.mp4: no such file"),
    ("rtsp", "rtsp://127.0.0.1:1/none", "rtsp://127.0.0.1:1/none: OpenCV cannot open it"),
]


@pytest.mark.parametrize("kind,target,fragment", UNOPENABLE)
def test_sources_that_cannot_open(tmp_path, kind, target, fragment):
    with pytest.raises(SourceError) as e:
        VideoSource(kind, target, 640, 480)
    assert fragment in str(e.value)


def test_a_file_that_is_not_a_video(tmp_path):
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"\x00" * 1000)
    with pytest.raises(SourceError, match="junk.mp4"):
        VideoSource("video", str(junk), 640, 480)


# -- capture rate and a shared capture clock (edge run --fps, --start-at) -----------------------


def test_a_file_thinned_to_a_lower_rate_keeps_each_frames_own_stamp(tmp_path):
    path = write_video(tmp_path / "v.avi", 20, fps=20.0)
    src = VideoSource("video", str(path), 64, 48, realtime=False, fps=5.0, start_ns=0)
    frames = list(src.frames())
    assert [level(f.image) for f in frames] == [0, 4, 8, 12, 16]
    assert [f.stamp_ns for f in frames] == [i * 50_000_000 for i in (0, 4, 8, 12, 16)]  # the file's times, frame by frame
    assert src.skipped == 0  # thinning is not a slow node's skipping


def test_vtest_thinned_from_10_to_4_fps_is_the_files_frames(tmp_path):
    """OpenCV's sample video (10 fps) at 4 fps: frames 0, 3, 5, 8, 10, decoded as a plain read decodes them."""
    from tests.media import VTEST_SIZE, media_path, vtest_frames

    src = VideoSource("video", str(media_path("vtest.avi")), *VTEST_SIZE, realtime=False, fps=4.0, start_ns=0)
    got = []
    for f in src.frames():
        got.append(f)
        if len(got) == 5:
            break
    src.close()
    assert src.fps == 10.0 and [f.stamp_ns for f in got] == [i * 100_000_000 for i in (0, 3, 5, 8, 10)]
    expected = vtest_frames([0, 3, 5, 8, 10])
    for f, i in zip(got, (0, 3, 5, 8, 10)):
        assert np.array_equal(f.image, expected[i]), i


def test_a_rate_above_the_files_is_refused_naming_both(tmp_path):
    path = write_video(tmp_path / "v.avi", 3, fps=15.0)
    with pytest.raises(SourceError, match=r"--fps 20 is above the frame rate of video:.*v\.avi \(15 fps\).*give --fps in \(0, 15\]"):
        VideoSource("video", str(path), 64, 48, fps=20.0)


def test_files_given_one_start_share_one_capture_clock(tmp_path):
    """Two nodes started at different times with the same start stamp frame k of their files alike."""
    a = write_video(tmp_path / "a.avi", 8, fps=25.0)
    b = write_video(tmp_path / "b.avi", 8, fps=25.0)
    start = time.time_ns() + 150_000_000  # shortly ahead, as `--start-at $(( $(date +%s) + 5 ))` is
    first = VideoSource("video", str(a), 64, 48, start_ns=start)
    arrivals, stamps_a = [], []
    for f in first.frames():
        arrivals.append(time.time_ns())
        stamps_a.append(f.stamp_ns)
    second = VideoSource("video", str(b), 64, 48, start_ns=start, realtime=False)  # opened after the first ended
    stamps_b = [f.stamp_ns for f in second.frames()]
    assert stamps_a == stamps_b == [start + k * 40_000_000 for k in range(8)]
    assert arrivals[0] >= start  # nothing before the shared start
    assert first.skipped == 0
