"""Fuzz the two decoders every subscriber runs: Observation (edge.wire) and PoseArray (host.messages.pose).

    python benchmarks/fuzz.py [--n 100000] [--seed 0]        (make fuzz; not part of the test suite)

Each payload starts from a valid one (simulated people, 0-10 of them) and is mutated: bit and
byte flips, truncation, splices of two payloads, random bytes, and structural JSON mutations
(a value replaced by another type, a huge or non-finite number, deep nesting, a key dropped,
added or duplicated, an array grown or emptied). Every payload must either decode or raise the
documented ``DecodeError`` (``PoseDecodeError`` for poses) with a reason from ``REASONS``;
anything else is a defect. Prints counts by outcome and reason; exit code 1 on any defect.
"""

from __future__ import annotations

import argparse
import copy
import json
import random
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from superbody.edge.messages import wire
from superbody.edge.messages.payload import REASONS, DecodeError
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.messages import pose as pose_msg

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "deploy" / "sites" / "wtf-apartment.toml"
T0 = 1_718_000_000 * 10**9

_ODD_VALUES = [None, True, False, 0, -1, 1, 2**63, -(2**63) - 1, 10**400, 1e308, -1e308, 0.5, "", "x" * 1000, "\u0000",
               "\ud800", [], {}, [[[[]]]], {"a": {"b": {"c": []}}}, "NaN", "Infinity", 1e-320]


def _seeds(rng: random.Random) -> tuple[list[bytes], list[bytes]]:
    site = load_site(SITE)
    obs, poses = [], []
    for n in (0, 1, 3, 10):
        world = World(site, n, seed=rng.randrange(1000))
        for cam in site.camera_ids:
            for k in range(3):
                obs.append(wire.encode(SimCamera(world, cam).observe(T0 + k * 66_666_667)[0]))
        people = tuple(
            pose_msg.PersonPose(id=i + 1, x=rng.uniform(-5, 5), y=rng.uniform(-5, 5), yaw=rng.uniform(-3, 3), vx=0.1, vy=-0.2,
                                yaw_rate=0.0, cov=np.eye(3) * 0.01, confidence=0.7, cameras=("1", "2"), stamp_ns=T0, views=2)
            for i in range(n)
        )
        poses.append(pose_msg.encode(pose_msg.PoseArray(site.name, n, T0, people, 1000, ("1", "2", "3"), "onnx:x.onnx")))
    return obs, poses


def _odd(rng: random.Random):
    """One of the odd values, as a fresh copy: a shared list or dict put into one document and
    mutated there would change every later one, and can end up holding itself."""
    return copy.deepcopy(rng.choice(_ODD_VALUES))


def _walk(doc, rng: random.Random):
    """A random (container, key) inside a JSON document, or None for the root."""
    path = []
    node = doc
    while isinstance(node, (dict, list)) and node and rng.random() < 0.8:
        key = rng.choice(list(node)) if isinstance(node, dict) else rng.randrange(len(node))
        path.append((node, key))
        node = node[key]
    return path[-1] if path else None


def _structural(payload: bytes, rng: random.Random) -> bytes:
    doc = json.loads(payload)
    for _ in range(rng.randint(1, 3)):
        where = _walk(doc, rng)
        if where is None:
            doc = _odd(rng)
            break
        parent, key = where
        op = rng.randrange(6)
        if op == 0:
            parent[key] = _odd(rng)
        elif op == 1 and isinstance(parent, dict):
            del parent[key]
        elif op == 2 and isinstance(parent, dict):
            parent[rng.choice(["extra", "Schema", "people ", "\u00e9"])] = _odd(rng)
        elif op == 3 and isinstance(parent[key], list):
            parent[key] = parent[key] * rng.randint(0, 70)
        elif op == 4 and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
            v = parent[key]
            parent[key] = rng.choice([v * 10**6, -v, v + 0.5 if abs(v) < 1e300 else v, float("nan"), float("inf")])
        else:
            parent[key] = "__DEEP__"  # nested arrays, written as text below (json.dumps would recurse)
    depth = rng.choice([1, 10, 200, 2000])
    text = json.dumps(doc, allow_nan=True).replace('"__DEEP__"', "[" * depth + "0" + "]" * depth)
    if rng.random() < 0.1:  # a duplicated key
        text = text.replace('"site":', '"site": "a", "site":', 1)
    return text.encode("utf-8", "surrogatepass")


def mutate(payload: bytes, pool: list[bytes], rng: random.Random) -> bytes:
    kind = rng.randrange(6)
    b = bytearray(payload)
    if kind == 0 and b:  # bit flips
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b)
    if kind == 1 and b:  # byte replacements
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if kind == 2:  # truncation
        return bytes(b[: rng.randrange(len(b) + 1)])
    if kind == 3:  # splice of two payloads
        other = rng.choice(pool)
        return bytes(b[: rng.randrange(len(b) + 1)] + other[rng.randrange(len(other) + 1):])
    if kind == 4:  # random bytes, sometimes huge
        return rng.randbytes(rng.choice([0, 1, 16, 1000, 300_000, 600_000]))
    return _structural(payload, rng)


def fuzz(n: int, seed: int) -> int:
    rng = random.Random(seed)
    obs_pool, pose_pool = _seeds(rng)
    outcomes: Counter[str] = Counter()
    defects: list[str] = []
    t0 = time.perf_counter()
    for i in range(n):
        is_pose = i % 2 == 1
        pool = pose_pool if is_pose else obs_pool
        payload = mutate(rng.choice(pool), pool, rng)
        codec = "pose" if is_pose else "observation"
        try:
            if is_pose:
                pose_msg.decode(payload)
            else:
                wire.decode(payload)
            outcomes[f"{codec}: decoded"] += 1
        except DecodeError as e:  # PoseDecodeError is a DecodeError
            if e.reason not in REASONS:
                defects.append(f"{codec}: undocumented reason {e.reason!r}: {e}")
            outcomes[f"{codec}: DecodeError {e.reason}"] += 1
        except Exception:  # anything else is a defect in a decoder
            defects.append(f"{codec}: {traceback.format_exc(limit=3)}\npayload[:200]={payload[:200]!r}")
            outcomes[f"{codec}: OTHER EXCEPTION"] += 1
    dt = time.perf_counter() - t0
    for k, v in sorted(outcomes.items()):
        print(f"{v:8d}  {k}")
    print(f"fuzz: {n} payloads ({n - n // 2} observations, {n // 2} pose arrays), seed {seed}, {dt:.1f} s: "
          f"{len(defects)} exceptions other than the documented DecodeError")
    for d in defects[:5]:
        print(d, file=sys.stderr)
    return 1 if defects else 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="payloads (default 100000)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    sys.exit(fuzz(a.n, a.seed))
