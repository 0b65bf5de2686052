"""Camera nodes as separate processes over real Zenoh on loopback."""

from __future__ import annotations

import threading
import time
from collections import defaultdict

import cv2
import numpy as np
import pytest
import zenoh

from superbody.edge import transport
from superbody.edge.body import INDEX
from superbody.edge.messages import wire
from superbody.edge.node import SourceSpec, box_histogram, frame_observation, parse_source
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.edge.sources.source import Frame
from tests.conftest import LAB_SITE, WTF_SITE, free_port
from tests.edge.photos import TOLERANCE_PX, astronaut_video

SITE = str(LAB_SITE)


class Listener:
    """A subscriber session listening on a loopback port, recording what arrives."""

    def __init__(self, port: int, site: str = "lab-example"):
        self.received: dict[str, list[tuple[float, object]]] = defaultdict(list)
        self.arrived_ns: dict[str, list[int]] = defaultdict(list)  # wall clock at each arrival, as received
        self.errors: list[str] = []
        self.alive: list[tuple[str, str]] = []
        self.event = threading.Condition()
        conf = transport.session_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
        self.session = zenoh.open(conf)
        self.sub = self.session.declare_subscriber(transport.observation_key(site), self._on_obs)
        self.live = self.session.liveliness().declare_subscriber(transport.camera_alive_key(site), self._on_alive, history=True)

    def _on_obs(self, sample) -> None:
        try:
            wall_ns = time.time_ns()
            obs = wire.decode(sample.payload.to_bytes())
            with self.event:
                self.received[obs.camera].append((time.monotonic(), obs))
                self.arrived_ns[obs.camera].append(wall_ns)
                self.event.notify_all()
        except wire.DecodeError as e:
            self.errors.append(str(e))

    def _on_alive(self, sample) -> None:
        with self.event:
            kind = "PUT" if sample.kind == zenoh.SampleKind.PUT else "DELETE"
            self.alive.append((transport.camera_from_key(str(sample.key_expr)), kind))
            self.event.notify_all()

    def wait_for(self, predicate, timeout: float) -> bool:
        with self.event:
            return self.event.wait_for(predicate, timeout=timeout)

    def close(self) -> None:
        self.session.close()


@pytest.fixture
def listener():
    port = free_port()
    lst = Listener(port)
    lst.port = port
    yield lst
    lst.close()


def _node(processes, port: int, camera: str, *extra: str):
    return processes.start("edge", "run", "--site", SITE, "--camera", camera, "--source", "sim", "--seed", "7",
                           "--connect", f"tcp/127.0.0.1:{port}", *extra)


def test_three_nodes_publish_decodable_observations_at_their_fps(processes, listener):
    cams = ("nw", "ne", "se")
    for c in cams:
        _node(processes, listener.port, c)
    assert listener.wait_for(lambda: all(len(listener.received[c]) >= 2 for c in cams), timeout=30), dict(listener.received)
    # Measure over 4 s once all three publish.
    counts0 = {c: len(listener.received[c]) for c in cams}
    t0 = time.monotonic()
    listener.wait_for(lambda: time.monotonic() - t0 > 4.0, timeout=4.5)
    elapsed = time.monotonic() - t0
    assert not listener.errors
    for c in cams:
        rate = (len(listener.received[c]) - counts0[c]) / elapsed
        assert abs(rate - 15.0) <= 1.5, f"camera {c}: {rate:.2f} msgs/s, expected 15 +- 10%"
        stamps = np.array([o.stamp_ns for _, o in listener.received[c]])
        # Capture grid at the fps: every gap a whole number of periods (a node that falls behind
        # skips to the next frame in the future, by design), nearly all of them one period.
        periods = np.diff(stamps) / (1e9 / 15)
        np.testing.assert_allclose(periods, np.round(periods), atol=0.01)
        assert periods.min() >= 0.99 and np.mean(np.round(periods) == 1) >= 0.95, periods
        seqs = [o.seq for _, o in listener.received[c]]
        assert seqs == sorted(seqs)
    assert {c for c, kind in listener.alive if kind == "PUT"} >= set(cams)


def test_nodes_share_the_world_clock(processes, listener):
    """What a node process publishes is what any process computes for the same site, seed and instant."""
    _node(processes, listener.port, "ne")
    # At some instants camera ne sees nobody (the scene follows the wall clock): wait for frames
    # until one has people, and check every frame received by then, empty ones included.
    got = listener.received["ne"]
    assert listener.wait_for(lambda: len(got) >= 3 and any(o.people for _, o in got), timeout=60), f"{len(got)} frames, none with people"
    cam = SimCamera(World(load_site(SITE), 3, seed=7), "ne")
    received = [o for _, o in list(got)]
    for obs in received:
        # Compare after the same wire rounding.
        assert wire.decode(wire.encode(cam.observe(obs.stamp_ns)[0])).people == obs.people, obs.seq
    assert any(o.people for o in received)


def test_a_late_node_delivers_each_observation_after_its_capture_with_its_stamp(processes, listener):
    """`--delay 0.5 --fps 5`: observations captured on a 5 fps grid arrive ~0.5 s after their
    capture stamps, in order, and are what any process computes for the same site, seed and instant."""
    _node(processes, listener.port, "se", "--delay", "0.5", "--fps", "5")
    got = listener.received["se"]
    assert listener.wait_for(lambda: len(got) >= 12, timeout=60), f"{len(got)} observations"
    with listener.event:
        received = [o for _, o in got]
        late_s = (np.array(listener.arrived_ns["se"][:len(received)]) - np.array([o.stamp_ns for o in received])) / 1e9
    assert not listener.errors
    # Delivered 0.5 s after capture: never before, and not much after (a loaded machine wakes late).
    assert late_s.min() >= 0.5 and np.median(late_s) < 0.6 and late_s.max() < 0.9, late_s
    stamps = np.array([o.stamp_ns for o in received])
    periods = np.diff(stamps) / 200e6  # the capture grid at 5 fps: stamps unchanged by the delay
    np.testing.assert_allclose(periods, np.round(periods), atol=0.01)
    assert periods.min() >= 0.99 and [o.seq for o in received] == sorted(o.seq for o in received)
    cam = SimCamera(World(load_site(SITE), 3, seed=7), "se", fps=5.0)
    for obs in received[:4]:
        assert wire.decode(wire.encode(cam.observe(obs.stamp_ns)[0])).people == obs.people, obs.seq


def test_node_started_before_the_listener_retries_and_publishes(processes):
    port = free_port()
    _node(processes, port, "sw")
    time.sleep(1.5)  # the node is up with nothing to connect to
    lst = Listener(port)
    try:
        assert lst.wait_for(lambda: len(lst.received["sw"]) >= 5, timeout=20)
    finally:
        lst.close()


def test_killed_node_drops_its_liveliness_token(processes, listener):
    proc = _node(processes, listener.port, "nw")
    assert listener.wait_for(lambda: ("nw", "PUT") in listener.alive, timeout=30)
    proc.kill()
    assert listener.wait_for(lambda: ("nw", "DELETE") in listener.alive, timeout=10)


# (arguments, text the error must contain)
BAD_ARGS = [
    (["--camera", "zz"], "nw, ne, se, sw"),  # unknown camera lists the valid ones
    (["--camera", "nw", "--people", "500"], "--people must be in [0, 64]"),
    (["--camera", "nw", "--source", "kinect"], "--source must be one of sim, oak[:DEVICE_ID], video:PATH, webcam:INDEX, rtsp://..., replay:PATH.mcap, got 'kinect'"),
    (["--camera", "nw", "--clock-scale", "-1"], "positive"),
]


@pytest.mark.parametrize("args,message", BAD_ARGS)
def test_bad_arguments_exit_2_with_a_clear_message(processes, args, message):
    p = processes.start("edge", "run", "--site", SITE, *args)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and message in err, err


def test_missing_site_file(processes, tmp_path):
    p = processes.start("edge", "run", "--site", str(tmp_path / "none.toml"), "--camera", "1")
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and "cannot read site file" in err


def test_a_frame_that_cannot_be_encoded_is_skipped_not_fatal(listener):
    """A source that produces an invalid observation: the node logs it, skips it and goes on."""
    import numpy as np

    from superbody.edge.messages.observation import PersonView
    from superbody.edge.node import run_node
    from superbody.edge.sources.sim_source import SimSource
    from superbody.edge.sources.source import Frame

    site = load_site(SITE)
    bad_view = PersonView(np.full((17, 3), np.nan, np.float32), np.array([5, 5, 1, 1], np.float32), np.zeros((16, 8), np.float32))

    class EveryOtherBad:
        """The simulated camera's frames, every other one with a view no subscriber accepts."""

        def __init__(self):
            self.sim = SimSource(site, "nw", seed=0, people=1)

        def frames(self):
            for f in self.sim.frames():
                if (f.stamp_ns // (10**9 // 15)) % 2:
                    f = Frame(f.stamp_ns, f.width, f.height, None, (bad_view,))
                yield f

        def close(self):
            self.sim.close()

    conf = transport.session_config("peer", connect=[f"tcp/127.0.0.1:{listener.port}"])
    published = run_node(conf, site, "nw", EveryOtherBad(), duration_s=2.0)
    assert 10 <= published <= 22  # about half of 2 s x 15 fps
    assert listener.wait_for(lambda: len(listener.received["nw"]) >= 10, timeout=10)
    assert not listener.errors


# -- sources -------------------------------------------------------------------------------------

# (--source value, expected spec)
GOOD_SOURCES = [
    ("sim", SourceSpec("sim")),
    ("oak", SourceSpec("oak")),  # the first OAK found
    ("oak:18443010C1E4F41200", SourceSpec("oak", "18443010C1E4F41200")),  # by device id
    ("oak:1.3", SourceSpec("oak", "1.3")),  # by USB path
    ("video:clips/walk.mp4", SourceSpec("video", "clips/walk.mp4")),
    ("video:/abs/with:colon.avi", SourceSpec("video", "/abs/with:colon.avi")),
    ("webcam:0", SourceSpec("webcam", 0)),
    ("webcam:12", SourceSpec("webcam", 12)),
    ("rtsp://10.0.0.5:554/stream1", SourceSpec("rtsp", "rtsp://10.0.0.5:554/stream1")),
    ("rtsps://user:pw@cam.local/live", SourceSpec("rtsp", "rtsps://user:pw@cam.local/live")),
]


@pytest.mark.parametrize("text,spec", GOOD_SOURCES)
def test_parse_source(text, spec):
    assert parse_source(text) == spec
    assert str(spec) == text


# (--source value, fragment of the error)
BAD_SOURCES = [
    ("kinect", "--source must be one of sim, oak[:DEVICE_ID], video:PATH, webcam:INDEX, rtsp://..., replay:PATH.mcap, got 'kinect'"),
    ("", "got ''"),
    ("SIM", "got 'SIM'"),
    ("oak:", "the OAK device id after 'oak:' is empty"),
    ("video:", "the video file path after 'video:' is empty"),
    ("video", "got 'video'"),
    ("webcam:", "webcam index must be an integer in [0, 63], got ''"),
    ("webcam:-1", "got '-1'"),
    ("webcam:64", "got '64'"),
    ("webcam:cam0", "got 'cam0'"),
    ("rtsp://", "the RTSP URL has no host"),
    ("rtsp:/x", "got 'rtsp:/x'"),
    ("http://cam/stream", "got 'http://cam/stream'"),
]


@pytest.mark.parametrize("text,fragment", BAD_SOURCES)
def test_parse_source_rejects(text, fragment):
    with pytest.raises(ValueError) as e:
        parse_source(text)
    assert fragment in str(e.value)


def test_box_histogram_is_the_colour_of_the_box():
    image = np.full((100, 200, 3), (0, 255, 0), np.uint8)  # green
    image[20:60, 50:90] = (0, 0, 255)  # red patch
    h = box_histogram(image, np.array([50, 20, 90, 60], np.float32))
    assert h.sum() == pytest.approx(1.0) and h[0].sum() == pytest.approx(1.0)  # all in the red hue bins
    h2 = box_histogram(image, np.array([-30, -30, 400, 400], np.float32))  # clipped to the image
    assert h2.sum() == pytest.approx(1.0) and h2[0].sum() == pytest.approx(40 * 40 / (100 * 200))
    assert box_histogram(image, np.array([150, 80, 150, 90], np.float32)).sum() == 0  # empty box
    assert box_histogram(image, np.array([np.nan, 0, 10, 10], np.float32)).sum() == 0


def test_frame_observation_runs_the_detector_and_colours_each_box():
    image = np.zeros((48, 64, 3), np.uint8)
    image[:, 32:] = (255, 0, 0)  # right half blue

    class TwoPeople:
        def detect(self, img):
            assert img is image
            kps = np.full((2, 17, 3), np.nan, np.float32)
            kps[:, 0] = [[10, 10, 0.9], [50, 10, 0.8]]
            return kps, np.array([[0, 0, 30, 48], [34, 0, 64, 48]], np.float32)

        def close(self):
            pass

    obs = frame_observation("s", "c", 7, Frame(123, 64, 48, image, None), TwoPeople())
    assert (obs.site, obs.camera, obs.seq, obs.stamp_ns, obs.width, obs.height) == ("s", "c", 7, 123, 64, 48)
    assert len(obs.people) == 2
    assert obs.people[0].histogram.sum() == pytest.approx(1.0) and obs.people[1].histogram.sum() == pytest.approx(1.0)
    assert not np.array_equal(obs.people[0].histogram, obs.people[1].histogram)  # black vs blue
    # A source that detected people itself keeps its histograms when it has no image ...
    sim = SimCamera(World(load_site(SITE), 2, seed=1), "nw").observe(5 * 10**9)[0]
    same = frame_observation("s", "c", 0, Frame(1, 1280, 720, None, sim.people))
    assert same.people == sim.people
    # ... and gets them from its image when it has one.
    recoloured = frame_observation("s", "c", 0, Frame(1, 64, 48, image, obs.people))
    assert np.array_equal(recoloured.people[1].histogram, obs.people[1].histogram)


def _cli(capsys, *args: str) -> tuple[int, str]:
    from superbody.edge.cli import main

    try:
        code = main(["edge", "run", *args])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    return code, capsys.readouterr().err


def test_cli_source_errors_are_one_line_and_exit_2(capsys, tmp_path):
    small = tmp_path / "small.avi"
    writer = cv2.VideoWriter(str(small), cv2.VideoWriter_fourcc(*"MJPG"), 15.0, (64, 48))
    for _ in range(3):
        writer.write(np.zeros((48, 64, 3), np.uint8))
    writer.release()
    hd = tmp_path / "hd.avi"  # the site camera's size, 15 fps
    writer = cv2.VideoWriter(str(hd), cv2.VideoWriter_fourcc(*"MJPG"), 15.0, (1280, 720))
    writer.write(np.zeros((720, 1280, 3), np.uint8))
    writer.release()
    cases = [  # (arguments, text of the error)
        (["--source", f"video:{small}"], f"--source video:{small} needs --detector, one of blazepose, yolo-pose:PATH.onnx, rtmo:PATH.onnx"),
        (["--detector", "blazepose"], "--detector is for video, webcam and RTSP sources; --source sim detects people itself"),
        (["--source", f"video:{small}", "--detector", "openpose"], "--detector must be one of blazepose"),
        (["--source", f"video:{small}", "--detector", "blazepose"], f"video:{small} delivers 64x48 images but the site's camera is 1280x720"),
        (["--source", f"video:{tmp_path / 'none.avi'}", "--detector", "blazepose"], "none.avi: no such file"),
        (["--source", "webcam:x", "--detector", "blazepose"], "webcam index must be an integer in [0, 63], got 'x'"),
        (["--nn-archive", "a.tar.xz"], "--nn-archive is for --source oak, not --source sim"),
        (["--source", f"video:{small}", "--detector", "blazepose", "--people", "2"], "--people is for --source sim"),
        (["--fast"], "--fast is for --source video, not --source sim"),
        (["--source", f"video:{small}", "--detector", "blazepose", "--clock-scale", "2"], "--clock-scale and --clock-anchor-ns are for simulated sources"),
        (["--source", f"video:{small}", "--detector", "blazepose", "--depth"], "--depth is for --source sim and oak"),
        (["--source", "oak", "--detector", "blazepose"], "--detector is for video, webcam and RTSP sources; --source oak"),
        # camera timing: each flag's range, and the sources each flag is for
        (["--delay", "-0.1"], "--delay must be a number in [0, 30], got '-0.1'"),
        (["--delay", "31"], "--delay must be a number in [0, 30], got '31'"),
        (["--jitter", "nan"], "--jitter must be a number in [0, 10], got 'nan'"),
        (["--fps", "0"], "--fps must be a number in [0.1, 1000], got '0'"),
        (["--fps", "fast"], "--fps must be a number in [0.1, 1000], got 'fast'"),
        (["--start-at", "-5"], "--start-at must be a number in [0, 9.2e+09], got '-5'"),
        (["--source", "webcam:0", "--detector", "blazepose", "--fps", "5"], "--fps is for --source sim, video, replay, not --source webcam:0"),
        (["--source", "oak", "--fps", "5"], "--fps is for --source sim, video, replay, not --source oak"),
        (["--start-at", "1800000000"], "--start-at is for --source video and replay, not --source sim"),
        (["--source", f"video:{hd}", "--detector", "blazepose", "--fps", "20"],
         f"--fps 20 is above the frame rate of video:{hd} (15 fps): a file can only be thinned, give --fps in (0, 15]"),
        (["--source", f"video:{hd}", "--detector", "blazepose", "--start-at", "1", "--replay-start-ns", "1"],
         "--replay-start-ns is for --source replay, not --source video"),
        (["--source", f"video:{small}", "--detector", "blazepose", "--fast", "--delay", "0.5"],
         "--delay and --jitter are for sources paced in real time; --fast reads the file as fast"),
    ]
    for args, message in cases:
        code, err = _cli(capsys, "--site", SITE, "--camera", "nw", *args)
        assert code == 2 and message in err, (args, err)
        assert "Traceback" not in err
        lines = [ln for ln in err.splitlines() if ln.startswith("superbody")]
        assert len(lines) == 1 and lines[0].startswith("superbody edge run: error:"), err


def test_a_video_at_another_rate_than_the_sites_camera_plays_at_its_own_with_a_warning(tmp_path, caplog):
    """The file's timing is what happened: a 10 fps file on a 15 fps camera publishes at 10 fps and
    says so, naming both rates and --fps; with --fps it publishes at that rate without a word."""
    import logging

    from superbody.edge.node import open_source

    clip = tmp_path / "ten.avi"
    writer = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (640, 480))
    for _ in range(6):
        writer.write(np.zeros((480, 640, 3), np.uint8))
    writer.release()
    site = load_site(WTF_SITE)
    assert site.camera("1").fps == 15.0
    spec = SourceSpec("video", str(clip))
    with caplog.at_level(logging.WARNING, logger="superbody.edge"):
        src = open_source(spec, site, "1", realtime=False)
    assert f"camera 1: video:{clip} runs at 10 fps, the site's camera at 15 fps: publishing every frame at the file's 10 fps" in caplog.text
    assert "--fps F thins it" in caplog.text
    assert np.allclose(np.diff([f.stamp_ns for f in src.frames()]), 100e6, atol=1)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="superbody.edge"):
        src = open_source(spec, site, "1", realtime=False, fps=5.0)
    assert not caplog.records
    assert np.allclose(np.diff([f.stamp_ns for f in src.frames()]), 200e6, atol=1)
    # --start-at reaches the file's capture clock: its first frame is stamped at the start.
    start = 1_800_000_000 * 10**9
    src = open_source(spec, site, "1", realtime=False, start_ns=start)
    assert [f.stamp_ns for f in src.frames()][:2] == [start, start + 100_000_000]


def test_cli_detector_that_cannot_open(capsys, tmp_path):
    frame = np.zeros((720, 1280, 3), np.uint8)
    clip = tmp_path / "hd.avi"
    writer = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 15.0, (1280, 720))
    writer.write(frame)
    writer.release()
    code, err = _cli(capsys, "--site", SITE, "--camera", "nw", "--source", f"video:{clip}", "--detector", f"yolo-pose:{tmp_path / 'y.onnx'}")
    assert code == 2 and f"superbody edge run: error: --detector yolo-pose:{tmp_path / 'y.onnx'}: model file" in err and "does not exist" in err


def test_cli_oak_without_a_device_or_support_exits_2(capsys):
    """Whatever is missing here (the depthai package, the OAK module, a device), one line and exit 2."""
    code, err = _cli(capsys, "--site", SITE, "--camera", "nw", "--source", "oak:NO-SUCH-DEVICE")
    assert code == 2 and err.strip().splitlines()[-1].startswith("superbody edge run: error:") and "oak" in err.lower(), err


def test_video_node_publishes_the_person_where_the_photo_shows_them(processes, tmp_path):
    """`edge run --source video:F --detector blazepose` on the apartment's camera 1: a real photo
    in a real video through the real BlazePose; nose, eyes and shoulders within 30 px."""
    clip = tmp_path / "astronaut.avi"
    marks = astronaut_video(clip, frames=60, fps=15.0)  # 4 s
    port = free_port()
    lst = Listener(port, site="wtf-apartment")
    try:
        p = processes.start("edge", "run", "--site", str(WTF_SITE), "--camera", "1", "--source", f"video:{clip}",
                            "--detector", "blazepose", "--connect", f"tcp/127.0.0.1:{port}")
        _, err = p.communicate(timeout=60)  # the node ends with the file
        assert p.returncode == 0, err
        # 60 frames in 4 s; a loaded machine skips some (frames are dropped, not delayed).
        assert lst.wait_for(lambda: len(lst.received["1"]) >= 5, timeout=5), (len(lst.received["1"]), err)
    finally:
        lst.close()
    assert not lst.errors
    observations = [o for _, o in lst.received["1"]]
    stamps = np.array([o.stamp_ns for o in observations])
    steps = np.diff(stamps) / (1e9 / 15)
    assert np.allclose(steps, np.round(steps), atol=1e-5) and (np.round(steps) >= 1).all()  # on the file's frame grid
    for obs in observations:
        assert (obs.width, obs.height) == (640, 480) and len(obs.people) == 1
        person = obs.people[0]
        for name, (x, y) in marks.items():
            u, v, _ = person.keypoints[INDEX[name]]
            assert np.hypot(u - x, v - y) <= TOLERANCE_PX, (name, (u, v), (x, y))
        assert person.histogram.sum() == pytest.approx(1.0, abs=1e-3)
        x0, y0, x1, y1 = person.bbox
        assert 0 <= x0 < x1 <= 640 and 0 <= y0 < y1 <= 480
