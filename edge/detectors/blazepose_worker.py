"""BlazePose worker: runs in its own interpreter (mediapipe 0.10.21, numpy < 2), never imported.

``edge/detectors/blazepose.py`` starts ``PYTHON edge/detectors/blazepose_worker.py [--static]`` and talks to it over
its standard input and output with little-endian binary frames:

- worker -> node, once the model is loaded: ``b"RDY0"``, uint32 0;
- node -> worker, per image: ``b"IMG0"``, uint32 height, uint32 width, then height * width * 3
  uint8 BGR bytes;
- worker -> node, per image: ``b"LMK0"``, uint32 n (0 or 1 person), then n * 33 * 4 float32:
  BlazePose's 33 landmarks as (x, y, visibility, presence), x and y normalised to [0, 1] by the
  image's width and height.

The worker ends at end of input. It imports only the standard library, numpy and mediapipe.
"""

from __future__ import annotations

import argparse
import os
import struct
import sys

HEADER = struct.Struct("<4sII")
REPLY = struct.Struct("<4sI")


def _read(stream, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        b = stream.read(n - got)
        if not b:
            break
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--static", action="store_true", help="detect on every image (no tracking across frames)")
    parser.add_argument("--min-detection", type=float, default=0.5)
    parser.add_argument("--min-tracking", type=float, default=0.5)
    args = parser.parse_args(argv)

    # Keep the protocol's stream to ourselves: anything a library prints goes to stderr.
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    inp = sys.stdin.buffer

    import numpy as np
    from mediapipe.python.solutions import pose as mp_pose

    # model_complexity=1 (pose_landmark_full) is the only landmark model the wheel bundles.
    pose = mp_pose.Pose(static_image_mode=args.static, model_complexity=1, smooth_landmarks=not args.static,
                        enable_segmentation=False, min_detection_confidence=args.min_detection,
                        min_tracking_confidence=args.min_tracking)
    out.write(REPLY.pack(b"RDY0", 0))
    out.flush()
    while True:
        head = _read(inp, HEADER.size)
        if len(head) < HEADER.size:
            return 0
        tag, height, width = HEADER.unpack(head)
        if tag != b"IMG0" or not (0 < height <= 16384 and 0 < width <= 16384):
            print(f"blazepose worker: bad frame header {head!r}", file=sys.stderr)
            return 2
        data = _read(inp, height * width * 3)
        if len(data) < height * width * 3:
            return 0
        bgr = np.frombuffer(data, np.uint8).reshape(height, width, 3)
        result = pose.process(np.ascontiguousarray(bgr[:, :, ::-1]))  # mediapipe wants RGB
        if result.pose_landmarks is None:
            out.write(REPLY.pack(b"LMK0", 0))
        else:
            lm = np.array([(p.x, p.y, p.visibility, p.presence) for p in result.pose_landmarks.landmark], np.float32)
            out.write(REPLY.pack(b"LMK0", 1) + lm.astype("<f4").tobytes())
        out.flush()


if __name__ == "__main__":
    sys.exit(main())
