"""How well ``superbody calibrate board`` recovers each camera of a site, on rendered boards.

    python scripts/board_accuracy.py [--site deploy/sites/wtf-apartment.toml] [--distance 2.5]
        [--yaws 0,45,90,180] [--seeds 5] [--save DIR] [--json-out F]

For each camera, the board (5x7 squares of 0.16 m, 0.12 m DICT_5X5_100 markers) lies on the
floor with its centre ``--distance`` metres in front of the camera, turned by each of ``--yaws``
degrees; ``edge.calibration.board.render_board`` draws what the camera sees (anti-aliased, blurred, noisy,
unevenly lit; a new floor pattern, light and noise per seed), and the real command
``superbody calibrate board`` solves the camera's pose from the image. The table gives the
distance between the solved and true optical centres and the angle between the solved and true
rotations, median and worst over the runs. ``--save DIR`` keeps the images and prints the
command line of each run, to try by hand.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from superbody.edge.calibration.board import BoardSpec  # noqa: E402
from superbody.edge.calibration.render import placement_in_front, render_board  # noqa: E402
from superbody.edge.cli import main as superbody  # noqa: E402
from superbody.edge.site import load_site  # noqa: E402

SPEC = BoardSpec(5, 7, 0.16, 0.12, "DICT_5X5_100")
FLAGS = ["--squares", "5x7", "--square", "0.16", "--marker", "0.12", "--dict", "DICT_5X5_100"]


def _angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip((np.trace(Ra @ Rb.T) - 1.0) / 2.0, -1.0, 1.0)))


def main(site_path: str, distance: float, yaws: list[float], seeds: int, save: str | None, json_out: str | None) -> int:
    site = load_site(site_path)
    folder = Path(save) if save else Path(tempfile.mkdtemp(prefix="board-"))
    folder.mkdir(parents=True, exist_ok=True)
    report: dict[str, dict] = {}
    print(f"site {site.name}: board {SPEC.squares_x}x{SPEC.squares_y} x {SPEC.square_m} m, centre {distance} m in front, "
          f"yaws {yaws} deg, {seeds} seeds")
    print(f"{'camera':>6} {'runs':>5} {'corners':>8} {'rms_px':>7} {'pos_cm med':>11} {'pos_cm max':>11} {'ang_deg med':>12} {'ang_deg max':>12}")
    for cam in site.cameras:
        pos_err, ang_err, corners, rms = [], [], [], []
        for yaw_offset in yaws:
            origin, yaw = placement_in_front(cam, SPEC, distance, math.radians(yaw_offset))
            for seed in range(seeds):
                image = folder / f"cam{cam.id}_yaw{yaw_offset:g}_seed{seed}.png"
                cv2.imwrite(str(image), render_board(SPEC, cam, origin, yaw, seed=seed))
                out = folder / f"{image.stem}.json"
                argv = ["calibrate", "board", "--site", site_path, "--camera", cam.id, "--image", str(image), *FLAGS,
                        f"--origin={origin[0]:.6f},{origin[1]:.6f}", f"--yaw={math.degrees(yaw):.6f}", "--json-out", str(out)]
                if save:
                    print("superbody " + " ".join(argv))
                if superbody(argv) != 0:
                    return 1
                doc = json.loads(out.read_text())
                pos_err.append(100.0 * float(np.linalg.norm(np.array(doc["position_m"]) - cam.t)))
                ang_err.append(_angle_deg(np.array(doc["rotation"]), cam.R))
                corners.append(doc["corners"])
                rms.append(doc["reprojection_px"])
        row = {
            "runs": len(pos_err), "corners_median": float(np.median(corners)), "rms_px_median": float(np.median(rms)),
            "position_cm_median": float(np.median(pos_err)), "position_cm_max": float(np.max(pos_err)),
            "angle_deg_median": float(np.median(ang_err)), "angle_deg_max": float(np.max(ang_err)),
        }
        report[cam.id] = row
        print(f"{cam.id:>6} {row['runs']:>5} {row['corners_median']:>8.0f} {row['rms_px_median']:>7.3f} "
              f"{row['position_cm_median']:>11.2f} {row['position_cm_max']:>11.2f} {row['angle_deg_median']:>12.3f} {row['angle_deg_max']:>12.3f}")
    if json_out:
        Path(json_out).write_text(json.dumps({"site": site_path, "distance_m": distance, "yaws_deg": yaws, "cameras": report}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--site", default=str(ROOT / "deploy" / "sites" / "wtf-apartment.toml"))
    p.add_argument("--distance", type=float, default=2.5, help="metres from the camera's foot to the board's centre")
    p.add_argument("--yaws", default="0,45,90,180", help="board yaws relative to facing the camera, degrees, comma-separated")
    p.add_argument("--seeds", type=int, default=5, help="renders per camera and yaw")
    p.add_argument("--save", help="keep the images here and print each command line")
    p.add_argument("--json-out")
    a = p.parse_args()
    sys.exit(main(a.site, a.distance, [float(y) for y in a.yaws.split(",")], a.seeds, a.save, a.json_out))
