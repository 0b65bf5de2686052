"""Camera-node speed per source and detector: frames/s on one core, Zenoh left out.

    python -m benchmarks.source_bench [--seconds 5] [--yolo-pose M.onnx] [--rtmo M.onnx] [--json-out F]

(from the repository: the test video comes from ``tests.edge.photos``.)

Each row runs the node's per-frame path as fast as it goes: the source's next frame (video
files unpaced), detection, colour signatures, ``wire.encode``. Images are 640 x 480 (the
apartment's camera 1): the scikit-image astronaut photo (one person) as an MJPG video file, the
format most webcams send. The
BlazePose worker process inherits the one-core affinity, so the figures are what one core
gives a node. YOLO-pose and RTMO rows need a user-exported model (none ships here).

Absolute rates on shared machines move 2-3x between runs and machines, so every row also gives
its time per frame over that of decoding the same video's frames alone (the first row, timed in
the same run on the same core): ``ms_per_frame_over_video_decode`` in ``--json-out``'s
``{row: {fps, ms_per_frame, frames, ms_per_frame_over_video_decode}}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from superbody.edge.detectors import open_detector, parse_detector
from superbody.edge.messages import wire
from superbody.edge.node import frame_observation
from superbody.edge.resources import site_path
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.edge.sources.video import VideoSource

try:
    from tests.edge.photos import astronaut_video
except ModuleNotFoundError:  # the test video's writer lives in the repository's tests package
    sys.exit("source_bench: run it from the repository as: python -m benchmarks.source_bench")


def _rate(step, seconds: float) -> tuple[float, int]:
    """Frames per second of ``step()`` over ``seconds`` after 3 warm-up calls."""
    for _ in range(3):
        step()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        step()
        n += 1
    return n / (time.perf_counter() - t0), n


def _video_steps(path: Path, detector):
    src = VideoSource("video", str(path), 640, 480, realtime=False, loop=True)
    frames = src.frames()
    seq = [0]

    def step():
        frame = next(frames)
        if detector is None:
            return frame
        obs = frame_observation("wtf-apartment", "1", seq[0], frame, detector)
        seq[0] += 1
        return wire.encode(obs)

    return step, src


def main(seconds: float, yolo: str | None, rtmo: str | None, json_out: str | None) -> int:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, inherited by the BlazePose worker
    site = load_site(site_path("wtf-apartment"))
    results: dict[str, dict] = {}
    print(f"one core; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; "
          "x decode = ms/frame over the video decode's, timed in this run on this core")
    print(f"{'source':<42} {'frames/s':>9} {'ms/frame':>9} {'x decode':>9}")
    decode_ms: list[float] = []

    def report(name: str, fps: float, n: int) -> None:
        results[name] = {"fps": fps, "ms_per_frame": 1e3 / fps, "frames": n}
        if decode_ms:
            results[name]["ms_per_frame_over_video_decode"] = 1e3 / fps / decode_ms[0]
        ratio = f"{1e3 / fps / decode_ms[0]:9.2f}" if decode_ms else f"{'ref':>9}"
        print(f"{name:<42} {fps:9.1f} {1e3 / fps:9.2f} {ratio}")

    cam = SimCamera(World(site, 3, seed=0), "1")
    t = [0]

    def sim_step():
        t[0] += 10**9 // 15
        obs = cam.observe(1_700_000_000 * 10**9 + t[0])[0]
        return wire.encode(obs)

    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(tmp) / "astronaut.avi"
        astronaut_video(clip, frames=30, fps=15.0, fourcc="MJPG")
        step, src = _video_steps(clip, None)
        report("video decode only (MJPG 640x480)", *_rate(step, seconds))  # the reference
        decode_ms.append(results["video decode only (MJPG 640x480)"]["ms_per_frame"])
        src.close()
        report("sim (3 people)", *_rate(sim_step, seconds))
        detectors = [("blazepose", "blazepose (per-frame detection)", {}),
                     ("blazepose", "blazepose (tracking)", {"tracking": True})]
        detectors += [(f"yolo-pose:{yolo}", "yolo-pose", {})] if yolo else []
        detectors += [(f"rtmo:{rtmo}", "rtmo", {})] if rtmo else []
        for spec, name, opts in detectors:
            if opts:
                from superbody.edge.detectors.blazepose import BlazePose

                det = BlazePose(**opts)
            else:
                det = open_detector(parse_detector(spec))
            step, src = _video_steps(clip, det)
            report(f"video + {name}", *_rate(step, seconds))
            src.close()
            det.close()
    if not (yolo and rtmo):
        print("yolo-pose / rtmo: pass --yolo-pose / --rtmo with an exported model to measure them")
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=5.0, help="time per measurement")
    p.add_argument("--yolo-pose", help="a YOLO-pose ONNX export to measure")
    p.add_argument("--rtmo", help="an RTMO ONNX export to measure")
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.seconds, a.yolo_pose, a.rtmo, a.json_out))
