"""The WheresTheFellow dataset: the paper's real recordings, read into ``Sample`` objects.

The file format is described in ``../shared/datasets/wheresthefellow/README.md``; what the
README leaves open was measured on ``dev.json`` and is written up, with the numbers, in
``docs/dataset.md``. In short:

- **World frame.** The dataset's world is in millimetres with Y up (floor at Y = 0) and X, Z on
  the floor, and it is *left-handed*: a DLT fit of every camera decomposes into positive focal
  lengths and a rotation of determinant -1 (all three cameras), and the nose lies on the side of
  the shoulder line that only a left-handed frame predicts. REP-103 (right-handed, z up) is
  reached by a reflection::

      x = X / 1000,   y = Z / 1000,   z = Y / 1000

- **Angle.** ``angle = 0`` faces +Z (REP-103 +y) and a positive angle turns towards -X, so the
  torso's facing direction on the dataset floor is ``(dX, dZ) = (-sin a, cos a)`` and::

      yaw = wrap(angle + pi / 2)

  (median 15 deg from the yaw of the 3D shoulders, hips and nose, 17 deg from the walking
  direction; the next best of the eight ``+-angle + k pi/2`` mappings is 31 deg and 72 deg; the
  file's own per-camera ``world`` estimate follows this convention to 2e-5 deg.)

- **Ground truth.** ``ground_truth = [x, y, z, angle]`` is a chest-worn tracking camera's pose in
  millimetres (as the README says) in the same world frame as the joints; its ``y`` stays near 0
  (the tracker's height relative to where it started, not above the floor) and is dropped. It
  sits about 0.21 m in front of the torso centre. The views of one sample can carry different
  ground truths (up to 99 mm and 12.6 deg apart, when their timestamps differ); a sample's truth
  and time are its first view's, as in the paper's code.

``load_wtf_raw`` parses and validates the file once and keeps the world-frame joints for tools
that need them (calibration, evaluation); ``load_wtf`` turns the raw samples into ``Sample``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from superbody.edge.angles import wrap_angle
from superbody.edge.body import INDEX, KEYPOINTS, NUM_KEYPOINTS
from superbody.edge.camera import Camera, world_to_camera
from superbody.edge.messages.observation import PersonView, empty_histogram
from superbody.edge.site import Site
from superbody.models.data.samples import Sample

__all__ = [
    "CAMERA_IDS",
    "IMAGE_WIDTH",
    "IMAGE_HEIGHT",
    "DatasetError",
    "RawView",
    "RawSample",
    "load_wtf",
    "load_wtf_raw",
    "parse_wtf",
    "to_samples",
    "person_view",
    "keypoint_bbox",
    "wtf_to_world",
    "world_to_wtf",
    "from_dataset_frame",
    "to_dataset_frame",
    "TRUTH_OFFSET_M",
    "truth_to_torso",
    "torso_to_truth",
]

# The ground truth is a chest-worn tracker, on average this far in front of the torso centre
# that the product reports (measured from the 3D shoulders and hips, docs/dataset.md).
TRUTH_OFFSET_M: Final[float] = 0.21

# The dataset's cameraId 1, 2, 3 become the site's camera ids "1", "2", "3".
CAMERA_IDS: Final[tuple[str, ...]] = ("1", "2", "3")
IMAGE_WIDTH: Final[int] = 640
IMAGE_HEIGHT: Final[int] = 480
# A box around the visible joints, grown by this fraction of its size on every side.
_BBOX_PAD: Final[float] = 0.1
# ... and by at least this many pixels, so one visible joint still gives a box with an area.
_BBOX_MIN_PAD_PX: Final[float] = 4.0


class DatasetError(ValueError):
    """An invalid dataset file; the message names the sample, the field and what is allowed."""


@dataclass(frozen=True, eq=False)
class RawView:
    """One camera's view of the person in one sample, in project units.

    Attributes:
        camera: camera id, one of ``CAMERA_IDS``.
        stamp_ms: capture time, UNIX milliseconds.
        keypoints: (17, 3) float64 (u, v, score) in pixels; NaN rows for joints not detected.
        joints: (17, 3) float64 joint positions in the REP-103 world, metres; NaN rows likewise.
        truth: (3,) float64 this view's ground truth (x, y, yaw), REP-103 metres and radians.
        estimate: (3,) float64 the original per-camera depth-based estimate (the ``world``
            field) as (x, y, yaw), or None when the file has no ``world`` field.
    """

    camera: str
    stamp_ms: int
    keypoints: NDArray[np.float64]
    joints: NDArray[np.float64]
    truth: NDArray[np.float64]
    estimate: NDArray[np.float64] | None = None

    @property
    def visible(self) -> NDArray[np.bool_]:
        """(17,) mask of the joints that were detected."""
        return ~np.isnan(self.keypoints[:, 0])


@dataclass(frozen=True, eq=False)
class RawSample:
    """All views of the person at one instant (``data_set[index]``)."""

    index: int
    views: tuple[RawView, ...]

    @property
    def truth(self) -> NDArray[np.float64]:
        """(3,) the sample's ground truth (x, y, yaw): the first view's, as in the paper's code."""
        return self.views[0].truth

    @property
    def stamp_ns(self) -> int:
        """The first (earliest) view's capture time, UNIX nanoseconds."""
        return self.views[0].stamp_ms * 1_000_000


# --- frames -------------------------------------------------------------------------------------


def wtf_to_world(X: ArrayLike, Y: ArrayLike, Z: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """Dataset world (mm, Y up, left-handed) to REP-103 (metres, z up, right-handed).

    Args:
        X, Y, Z: dataset coordinates in millimetres, any broadcastable shapes.

    Returns:
        ``(x, y, z)`` in metres, arrays of the broadcast shape.
    """
    X, Y, Z = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (X, Y, Z)))
    # A reflection (det -1): the dataset frame is left-handed, REP-103 is right-handed.
    return X / 1000.0, Z / 1000.0, Y / 1000.0


def world_to_wtf(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """REP-103 metres to dataset millimetres: the inverse of ``wtf_to_world``, as ``(X, Y, Z)``."""
    x, y, z = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, z)))
    return x * 1000.0, z * 1000.0, y * 1000.0


def from_dataset_frame(x_mm: ArrayLike, z_mm: ArrayLike, angle: ArrayLike) -> tuple[NDArray[np.float64] | float, ...]:
    """A dataset floor pose (X mm, Z mm, angle rad) to REP-103 ``(x, y, yaw)``.

    Returns:
        Metres and radians in (-pi, pi], arrays of the broadcast shape.
    """
    x_mm, z_mm, angle = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x_mm, z_mm, angle)))
    # angle 0 faces dataset +Z = REP-103 +y (yaw pi/2); both turn the same way on the REP-103 floor.
    return x_mm / 1000.0, z_mm / 1000.0, wrap_angle(angle + np.pi / 2)


def to_dataset_frame(x: ArrayLike, y: ArrayLike, yaw: ArrayLike) -> tuple[NDArray[np.float64] | float, ...]:
    """A REP-103 floor pose to the dataset's ``(x_mm, z_mm, angle)``, angle in (-pi, pi]."""
    x, y, yaw = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, yaw)))
    return x * 1000.0, y * 1000.0, wrap_angle(yaw - np.pi / 2)


# --- validation ---------------------------------------------------------------------------------


class _Checker:
    """Validates the parsed JSON; every error names the file, the field and what is allowed."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, msg: str) -> DatasetError:
        prefix = f"{self.source}: " if self.source else ""
        return DatasetError(f"{prefix}{where}: {msg}")

    def number(self, value: Any, where: str, lo: float = -math.inf, hi: float = math.inf) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(where, f"must be a finite number, got {value!r}")
        if not lo <= value <= hi:
            raise self.fail(where, f"must be in [{lo}, {hi}], got {value!r}")
        return float(value)

    def numbers(self, value: Any, where: str, n: int) -> list[float]:
        if not isinstance(value, list) or len(value) != n:
            raise self.fail(where, f"must be a list of {n} numbers, got {_short(value)}")
        return [self.number(v, f"{where}[{i}]") for i, v in enumerate(value)]

    def field(self, obj: dict, key: str, where: str) -> Any:
        if key not in obj:
            raise self.fail(f"{where}.{key}", "is missing")
        return obj[key]


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


_CAMERA_BY_NUMBER: Final[dict[int, str]] = {int(c): c for c in CAMERA_IDS}


def _view(ck: _Checker, v: Any, where: str) -> RawView:
    if not isinstance(v, dict):
        raise ck.fail(where, f"must be an object (one camera's view), got {_short(v)}")
    cam = ck.field(v, "cameraId", where)
    if isinstance(cam, bool) or not isinstance(cam, int) or cam not in _CAMERA_BY_NUMBER:
        raise ck.fail(f"{where}.cameraId", f"must be one of {', '.join(CAMERA_IDS)}, got {cam!r}")
    stamp = ck.number(ck.field(v, "timestamp", where), f"{where}.timestamp", 0, 1e15)
    if stamp != int(stamp):
        raise ck.fail(f"{where}.timestamp", f"must be whole milliseconds, got {stamp!r}")
    gx, _, gz, ga = ck.numbers(ck.field(v, "ground_truth", where), f"{where}.ground_truth", 4)
    estimate = None
    if "world" in v:
        wx, _, wz, wa = ck.numbers(v["world"], f"{where}.world", 4)
        estimate = np.array(from_dataset_frame(wx, wz, wa))

    joints_obj = ck.field(v, "joints", where)
    if not isinstance(joints_obj, dict) or not joints_obj:
        raise ck.fail(f"{where}.joints", f"must be a non-empty object of COCO-17 joints, got {_short(joints_obj)}")
    keypoints = np.full((NUM_KEYPOINTS, 3), np.nan)
    joints_mm = np.full((NUM_KEYPOINTS, 3), np.nan)
    for name, values in joints_obj.items():
        jw = f"{where}.joints.{name}"
        if name not in INDEX:
            raise ck.fail(jw, f"unknown joint; valid: {', '.join(KEYPOINTS)}")
        if not isinstance(values, list) or len(values) != 6:
            raise ck.fail(jw, f"must be [X, Y, Z, u, v, score] (6 numbers), got {_short(values)}")
        X, Y, Z, u, v_px = (ck.number(x, f"{jw}[{i}]") for i, x in enumerate(values[:5]))
        score = ck.number(values[5], f"{jw}[5]", 0.0, 1.0)
        joints_mm[INDEX[name]] = (X, Y, Z)
        keypoints[INDEX[name]] = (u, v_px, score)
    joints = np.stack(wtf_to_world(joints_mm[:, 0], joints_mm[:, 1], joints_mm[:, 2]), axis=1)  # (17, 3)
    truth = np.array(from_dataset_frame(gx, gz, ga))
    return RawView(_CAMERA_BY_NUMBER[cam], int(stamp), keypoints, joints, truth, estimate)


def parse_wtf(doc: Any, *, source: str = "") -> list[RawSample]:
    """Validate a parsed dataset document and convert it to project units.

    Args:
        doc: the JSON document, ``{"data_set": [...]}``.
        source: file name used to prefix error messages.

    Raises:
        DatasetError: a key is missing, a value has the wrong type or is not finite, a camera id
            is unknown or repeated within a sample, or the data set is empty.
    """
    ck = _Checker(source)
    if not isinstance(doc, dict):
        raise ck.fail("top level", f'must be an object {{"data_set": [...]}}, got {_short(doc)}')
    if "data_set" not in doc:
        raise ck.fail("data_set", "is missing")
    data = doc["data_set"]
    if not isinstance(data, list) or not data:
        raise ck.fail("data_set", f"must be a non-empty list of samples, got {_short(data)}")
    samples = []
    for i, s in enumerate(data):
        where = f"data_set[{i}]"
        if not isinstance(s, dict):
            raise ck.fail(where, f'must be an object {{"superbody": [...]}}, got {_short(s)}')
        views_in = ck.field(s, "superbody", where)
        if not isinstance(views_in, list) or not 1 <= len(views_in) <= len(CAMERA_IDS):
            raise ck.fail(f"{where}.superbody", f"must be a list of 1 to {len(CAMERA_IDS)} views, got {_short(views_in)}")
        views = tuple(_view(ck, v, f"{where}.superbody[{j}]") for j, v in enumerate(views_in))
        seen: set[str] = set()
        for j, view in enumerate(views):
            if view.camera in seen:
                raise ck.fail(f"{where}.superbody[{j}].cameraId", f"camera {view.camera} appears twice in this sample")
            seen.add(view.camera)
        samples.append(RawSample(i, views))
    return samples


def load_wtf_raw(path: str | Path) -> list[RawSample]:
    """Read and validate a WheresTheFellow JSON file, keeping the world-frame joints.

    Raises:
        DatasetError: the file cannot be read, is not JSON, or any field is invalid.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise DatasetError(f"{path}: cannot read dataset file ({e.strerror or e})") from None
    except UnicodeDecodeError as e:
        raise DatasetError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise DatasetError(f"{path}: not valid JSON (line {e.lineno} column {e.colno}: {e.msg})") from None
    return parse_wtf(doc, source=str(path))


# --- samples ------------------------------------------------------------------------------------


def keypoint_bbox(keypoints: NDArray, width: int = IMAGE_WIDTH, height: int = IMAGE_HEIGHT) -> NDArray[np.float32]:
    """Box around the visible keypoints, grown by 10% of its size (at least 4 px) on each side.

    Args:
        keypoints: (17, 3) (u, v, score) with NaN rows for missing joints; at least one visible.
        width, height: image size; the box is clipped to it.

    Returns:
        (4,) float32 (x0, y0, x1, y1) in pixels.
    """
    uv = keypoints[~np.isnan(keypoints[:, 0]), :2]  # (M, 2)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    pad = np.maximum(_BBOX_PAD * (hi - lo), _BBOX_MIN_PAD_PX)
    lo = np.clip(lo - pad, 0, [width, height])
    hi = np.clip(hi + pad, 0, [width, height])
    return np.concatenate([lo, hi]).astype(np.float32)


def person_view(view: RawView, camera: Camera | None = None) -> PersonView:
    """The ``PersonView`` a camera node would have sent for this view.

    Args:
        view: one raw view.
        camera: the calibrated camera that took it; when given, ``points3d`` holds the joints in
            its frame (metres), as a depth camera would report them.
    """
    points3d = None
    if camera is not None:
        # p_cam = R^T (p_world - t); NaN rows stay NaN.
        points3d = world_to_camera(view.joints, camera).astype(np.float32)
    return PersonView(
        keypoints=view.keypoints.astype(np.float32),
        bbox=keypoint_bbox(view.keypoints),
        histogram=empty_histogram(),  # the dataset has no colour
        points3d=points3d,
    )


def to_samples(raw: Sequence[RawSample], site: Site | None = None) -> list[Sample]:
    """Raw samples to ``Sample`` objects; with a ``site``, views carry camera-frame 3D joints.

    Raises:
        DatasetError: ``site`` lacks one of the dataset's cameras.
    """
    cameras: dict[str, Camera] = {}
    if site is not None:
        needed = sorted({v.camera for s in raw for v in s.views})
        missing = [c for c in needed if c not in site.camera_ids]
        if missing:
            raise DatasetError(
                f"site {site.name!r} lacks camera(s) {', '.join(missing)} used by the dataset; "
                f"site cameras: {', '.join(site.camera_ids)}"
            )
        cameras = {c: site.camera(c) for c in needed}
    return [
        Sample(
            views={v.camera: person_view(v, cameras.get(v.camera)) for v in s.views},
            truth=s.truth.copy(),
            stamp_ns=s.stamp_ns,
        )
        for s in raw
    ]


def load_wtf(path: str | Path, site: Site | None = None) -> list[Sample]:
    """Read a WheresTheFellow JSON file as samples.

    Args:
        path: the dataset file.
        site: the calibrated site (``deploy/sites/wtf-apartment.toml``); when given, every view's
            ``points3d`` holds the joints in that camera's frame, otherwise it is None.

    Returns:
        One ``Sample`` per ``data_set`` entry, in file (time) order.

    Raises:
        DatasetError: the file is unreadable or invalid, or ``site`` lacks a camera.
    """
    return to_samples(load_wtf_raw(path), site)


def truth_to_torso(truth: ArrayLike, offset_m: float = TRUTH_OFFSET_M) -> NDArray[np.float64]:
    """(N, 3) dataset ground truth (x, y, yaw), a chest point, to the torso centre behind it."""
    t = np.array(truth, dtype=np.float64).reshape(-1, 3)
    t[:, 0] -= offset_m * np.cos(t[:, 2])
    t[:, 1] -= offset_m * np.sin(t[:, 2])
    return t


def torso_to_truth(pose: ArrayLike, offset_m: float = TRUTH_OFFSET_M) -> NDArray[np.float64]:
    """(N, 3) torso poses (x, y, yaw) to the point the dataset's chest tracker measures."""
    return truth_to_torso(pose, -offset_m)
