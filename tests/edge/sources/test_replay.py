"""``--source replay:F.mcap``: a recording re-published as a camera's frames, and its errors.

The recordings here are written with ``superbody record``'s own ``Recorder`` (the real MCAP
writer) from simulated Observations; the live round trip through processes is in
tests/host/test_replay_process.py.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from superbody.edge import transport
from superbody.edge.messages import wire
from superbody.edge.node import SourceSpec, parse_source
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.edge.sources.replay import ReplaySource, scan_recording
from superbody.edge.sources.source import SourceError
from superbody.host.outputs.record import Recorder
from tests.conftest import LAB_SITE, WTF_SITE
from tests.edge.test_node import _cli

T0 = 1_700_000_000 * 10**9  # recorded long ago: the replay must shift the stamps


def _record(path, site_file, stamps: dict[str, list[int]], people: int = 2, extra: list[tuple[str, bytes]] = ()):
    """Write an MCAP with each camera's simulated Observations at the given stamps (ns)."""
    site = load_site(site_file)
    world = World(site, people, seed=4)
    msgs = []
    for cam, ts in stamps.items():
        sim = SimCamera(world, cam)
        for seq, t in enumerate(ts):
            obs = sim.observe(t)[0]
            obs = type(obs)(site.name, cam, seq, t, obs.width, obs.height, obs.people)
            msgs.append((t, transport.observation_key(site.name, cam), wire.encode(obs)))
    msgs.sort()
    with open(path, "wb") as f:
        rec = Recorder(f)
        for t, key, payload in msgs:
            rec.add(key, payload, t + 5_000_000)
        for key, payload in extra:
            rec.add(key, payload, msgs[-1][0] + 10_000_000)
        rec.close()
    return site


def test_parse_replay_source():
    assert parse_source("replay:a/b.mcap") == SourceSpec("replay", "a/b.mcap")
    assert str(parse_source("replay:x.mcap")) == "replay:x.mcap"
    assert not parse_source("replay:x.mcap").needs_detector
    with pytest.raises(ValueError, match="path after 'replay:' is empty"):
        parse_source("replay:")


def test_replay_keeps_the_gaps_and_shifts_every_camera_by_one_constant(tmp_path):
    # Irregular gaps (a dropped frame, jitter); camera 2 starts 30 ms after camera 1.
    gaps = np.array([0, 66, 133, 266, 300, 366, 380, 450]) * 10**6
    path = tmp_path / "r.mcap"
    site = _record(path, WTF_SITE, {"1": list(T0 + gaps), "2": list(T0 + 30 * 10**6 + gaps)})
    start = time.time_ns() + 200 * 10**6
    src = ReplaySource(path, site, "2", start_ns=start)
    got = []
    for frame in src.frames():
        got.append((frame, time.time_ns()))
    src.close()
    assert len(got) == len(gaps) and src.skipped == 0 and src.rejected == 0
    stamps = np.array([f.stamp_ns for f, _ in got])
    # One shift for the whole recording: the recording's first stamp (camera 1's) lands on start.
    assert np.array_equal(stamps, start + 30 * 10**6 + gaps)
    arrived = np.array([t for _, t in got])
    assert np.all(arrived >= stamps)  # delivered when its (shifted) capture time has come
    assert np.all(arrived - stamps < 100 * 10**6), (arrived - stamps) / 1e6  # ... not long after (loaded CI machine)
    sim = SimCamera(World(site, 2, seed=4), "2")
    for (frame, _), t in zip(got, T0 + 30 * 10**6 + gaps):
        expected = sim.observe(int(t))[0]
        assert frame.image is None and (frame.width, frame.height) == (expected.width, expected.height)
        assert len(frame.people) == len(expected.people)
        for a, b in zip(frame.people, expected.people):
            np.testing.assert_allclose(a.keypoints, b.keypoints, atol=0.01, equal_nan=True)  # wire rounding
            np.testing.assert_allclose(a.histogram, b.histogram, atol=1e-4)


def test_replay_loops_with_stamps_counting_up_and_skips_what_is_late(tmp_path):
    path = tmp_path / "r.mcap"
    gaps = [0, 50 * 10**6, 100 * 10**6]
    site = _record(path, WTF_SITE, {"1": [T0 + g for g in gaps]})
    period = 100 * 10**6 + int(1e9 / max(c.fps for c in site.cameras))
    # Started 1 s ago: the first pass is late by more than 0.5 s and skipped; later passes play.
    start = time.time_ns() - 10**9
    src = ReplaySource(path, site, "1", start_ns=start, loop=True)
    stamps = []
    for frame in src.frames():
        stamps.append(frame.stamp_ns)
        if len(stamps) == 6:
            src.close()
    assert len(stamps) == 6 and src.skipped >= 3
    assert np.all(np.diff(stamps) > 0)
    rel = [(s - start) % period for s in stamps]
    assert all(r in gaps for r in rel), rel  # every pass: the recording's gaps, one loop period later
    assert all(b == gaps[(gaps.index(a) + 1) % len(gaps)] for a, b in zip(rel, rel[1:])), rel


def test_replay_skips_messages_that_do_not_decode(tmp_path):
    path = tmp_path / "r.mcap"
    key = transport.observation_key("wtf-apartment", "1")
    site = _record(path, WTF_SITE, {"1": [T0, T0 + 66 * 10**6]}, extra=[(key, b'{"schema": "superbody.observation"}'), (key, b"\xff")])
    src = ReplaySource(path, site, "1", start_ns=time.time_ns())
    assert len(list(src.frames())) == 2 and src.rejected == 2


def test_scan_lists_sites_and_cameras(tmp_path):
    path = tmp_path / "r.mcap"
    _record(path, WTF_SITE, {"1": [T0, T0 + 10], "3": [T0 + 5]})
    info = scan_recording(path, "wtf-apartment")
    assert info.cameras == {"wtf-apartment": ("1", "3")} and (info.t0_ns, info.t_end_ns) == (T0, T0 + 10)


def test_replay_errors_are_one_line_and_exit_2(capsys, tmp_path):
    wtf = tmp_path / "wtf.mcap"
    _record(wtf, WTF_SITE, {"1": [T0], "3": [T0 + 10**6]})
    lab = tmp_path / "lab.mcap"
    _record(lab, LAB_SITE, {"nw": [T0]})
    text = tmp_path / "notes.mcap"
    text.write_text("not a recording\n")
    truncated = tmp_path / "cut.mcap"
    truncated.write_bytes(wtf.read_bytes()[:40])
    fast = tmp_path / "fast.mcap"
    _record(fast, WTF_SITE, {"1": [T0 + round(k * 1e9 / 15) for k in range(5)]})
    no_obs = tmp_path / "status.mcap"
    with open(no_obs, "wb") as f:
        rec = Recorder(f)
        rec.add(transport.host_status_key("wtf-apartment"), b"{}", T0)
        rec.close()
    cases = [  # (camera, arguments, text of the error)
        ("1", ["--source", f"replay:{tmp_path / 'none.mcap'}"], "none.mcap: no such file"),
        ("1", ["--source", f"replay:{text}"], "notes.mcap: not an MCAP file"),
        ("1", ["--source", f"replay:{truncated}"], "cut.mcap: damaged MCAP file"),
        ("1", ["--source", f"replay:{no_obs}"], "status.mcap: the recording holds no camera observations"),
        ("2", ["--source", f"replay:{wtf}"], "no observations of camera '2' of site 'wtf-apartment'; cameras present: 1, 3"),
        ("1", ["--source", f"replay:{lab}"], "a recording of site(s) lab-example, not of site 'wtf-apartment'"),
        ("1", ["--source", "replay:"], "the MCAP recording path after 'replay:' is empty"),
        ("1", ["--replay-start-ns", "5"], "--replay-start-ns is for --source replay, not --source sim"),
        ("1", ["--loop"], "--loop is for --source video and replay, not --source sim"),
        ("1", ["--source", f"replay:{wtf}", "--replay-start-ns", "-1"], "--replay-start-ns must be in [0, "),
        ("1", ["--source", f"replay:{wtf}", "--detector", "blazepose"], "--detector is for video, webcam and RTSP sources"),
        ("1", ["--source", f"replay:{wtf}", "--start-at", "5", "--replay-start-ns", "5"],
         "--start-at and --replay-start-ns say the same thing: give one"),
        ("1", ["--source", f"replay:{fast}", "--fps", "20"],
         f"--fps 20 is above camera 1's recorded frame rate in replay:{fast} (15 fps): a recording can only be thinned, give --fps in (0, 15]"),
    ]
    for camera, args, message in cases:
        code, err = _cli(capsys, "--site", str(WTF_SITE), "--camera", camera, *args)
        assert code == 2 and message in err, (args, err)
        assert "Traceback" not in err
        lines = [ln for ln in err.splitlines() if ln.startswith("superbody")]
        assert len(lines) == 1 and lines[0].startswith("superbody edge run: error:"), err


def test_replay_refuses_another_image_size(tmp_path):
    path = tmp_path / "r.mcap"
    site = _record(path, WTF_SITE, {"1": [T0]})
    cam = site.camera("1")
    small = replace(site, cameras=tuple(replace(c, width=c.width // 2) if c.id == "1" else c for c in site.cameras))
    with pytest.raises(SourceError, match=f"recorded at {cam.width}x{cam.height}, the site's camera is {cam.width // 2}x{cam.height}"):
        ReplaySource(path, small, "1")


def test_replay_thinned_to_a_lower_rate_on_a_shared_start(tmp_path):
    """`--fps 5 --start-at T` on a 15 fps recording: every third observation, the recording's
    first stamp at T, each frame its own (shifted) stamp."""
    path = tmp_path / "r.mcap"
    stamps = [T0 + round(k * 1e9 / 15) for k in range(10)]
    site = _record(path, WTF_SITE, {"1": stamps})
    start = time.time_ns() + 100 * 10**6
    src = ReplaySource(path, site, "1", start_ns=start, fps=5.0)
    assert src.fps == pytest.approx(15.0, rel=1e-6)
    got = [f.stamp_ns for f in src.frames()]
    assert got == [start + s - T0 for s in stamps[::3]]
