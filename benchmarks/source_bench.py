"""Camera-node speed per source and detector: frames/s on one core, Zenoh left out.

    python benchmarks/source_bench.py [--seconds 5] [--yolo-pose M.onnx] [--rtmo M.onnx] [--json-out F]

Each row runs the node's per-frame path as fast as it goes: the source's next frame (video
files unpaced), detection, colour signatures, ``wire.encode``. Images are 640 x 480 (the
apartment's camera 1): the scikit-image astronaut photo (one person) as an MJPG video file, the
format most webcams send. The
BlazePose worker process inherits the one-core affinity, so the figures are what one core
gives a node. YOLO-pose and RTMO rows need a user-exported model (none ships here).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from superbody.edge.messages import wire  # noqa: E402
from superbody.edge.detectors import open_detector, parse_detector  # noqa: E402
from superbody.edge.node import frame_observation  # noqa: E402
from superbody.edge.sim import SimCamera, World  # noqa: E402
from superbody.edge.site import load_site  # noqa: E402
from superbody.edge.sources.video import VideoSource  # noqa: E402
from tests.edge.photos import astronaut_video  # noqa: E402


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
    site = load_site(ROOT / "deploy" / "sites" / "wtf-apartment.toml")
    results: dict[str, dict] = {}
    print(f"one core; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{'source':<42} {'frames/s':>9} {'ms/frame':>9}")

    def report(name: str, fps: float, n: int) -> None:
        results[name] = {"fps": fps, "ms_per_frame": 1e3 / fps, "frames": n}
        print(f"{name:<42} {fps:9.1f} {1e3 / fps:9.2f}")

    cam = SimCamera(World(site, 3, seed=0), "1")
    t = [0]

    def sim_step():
        t[0] += 10**9 // 15
        obs = cam.observe(1_700_000_000 * 10**9 + t[0])[0]
        return wire.encode(obs)

    report("sim (3 people)", *_rate(sim_step, seconds))
    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(tmp) / "astronaut.avi"
        astronaut_video(clip, frames=30, fps=15.0, fourcc="MJPG")
        step, src = _video_steps(clip, None)
        report("video decode only (MJPG 640x480)", *_rate(step, seconds))
        src.close()
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
