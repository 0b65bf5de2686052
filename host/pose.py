"""The host's output message, the PoseArray, and its wire codec on ``superbody/<site>/people``.

The schema, for subscribers in any language, is in ``docs/pose-schema.md``. In short::

    {"schema": "superbody.people", "version": 1, "site": "lab", "seq": 42,
     "stamp_ns": 1718000000000000000, "latency_ns": 2100000, "estimator": "analytic",
     "cameras_alive": ["cam-1", "cam-2"],
     "people": [{"id": 3, "x": 1.234, "y": -0.5, "yaw": 1.5708,          # m, m, rad (REP-103)
                 "vx": 0.41, "vy": 0.0, "yaw_rate": 0.0123,              # m/s, m/s, rad/s
                 "cov": [xx, xy, xyaw, yy, yyaw, yawyaw],                # upper triangle
                 "confidence": 0.93, "views": 2, "cameras": ["cam-1", "cam-2"],
                 "stamp_ns": 1717999999990000000}]}

``encode`` rounds positions to 1 mm, velocities to 1 mm/s, angles and angular rates to 1e-4,
confidence to 1e-4 and covariances to 6 significant digits, so a person is about 250 bytes.
``decode`` checks every field and raises ``PoseDecodeError`` naming the field
(``people[2].cov[3]``), a ``reason`` from ``REASONS`` for reject counters, and the allowed range;
the checks shared with the Observation codec are in ``edge/payload.py``.
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import NDArray

from superbody.edge.payload import (
    MAX_INT63,
    REASONS,
    DecodeError,
    as_int,
    brief,
    check_array_max,
    check_int,
    check_message,
    check_name,
    check_object,
    fail,
    parse_json,
)

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "SCHEMA",
    "VERSION",
    "ENCODING",
    "MAX_PAYLOAD_BYTES",
    "MAX_PEOPLE",
    "MAX_CAMERAS",
    "REASONS",
    "PersonPose",
    "PoseArray",
    "PoseDecodeError",
    "encode",
    "decode",
    "zenoh_encoding",
]

SCHEMA: Final[str] = "superbody.people"
VERSION: Final[int] = 2  # what the encoder writes
READ_VERSIONS: Final[tuple[int, ...]] = (1, 2)  # what the decoder reads (1: no per-person estimator)
# Zenoh 1.x renders an Encoding as "<mime>;<schema>": this string equals str(zenoh_encoding()).
ENCODING: Final[str] = f"application/json;{SCHEMA}/{VERSION}"
MAX_PEOPLE: Final[int] = 64
MAX_CAMERAS: Final[int] = 64  # a site file holds at most 64 cameras
# 64 people each seen by 64 cameras with 64-character names is about 300 KB: valid input always fits.
MAX_PAYLOAD_BYTES: Final[int] = 512 * 1024

_TOP_FIELDS: Final[tuple[str, ...]] = (
    "schema", "version", "site", "seq", "stamp_ns", "latency_ns", "estimator", "cameras_alive", "people",
)
_PERSON_FIELDS_V1: Final[tuple[str, ...]] = (
    "id", "x", "y", "yaw", "vx", "vy", "yaw_rate", "cov", "confidence", "views", "cameras", "stamp_ns",
)
_PERSON_FIELDS: Final[tuple[str, ...]] = (*_PERSON_FIELDS_V1, "estimator")  # version 2
_MAX_ID: Final[int] = 2**53 - 1  # exact in a double (JavaScript's Number.MAX_SAFE_INTEGER)
_MAX_VIEWS: Final[int] = 255
_MAX_COORD_M: Final[float] = 1000.0
_MAX_SPEED: Final[float] = 100.0  # m/s and rad/s: far beyond people, only stops garbage
_MAX_COV: Final[float] = 1e6
_COV_DIAG: Final[tuple[int, ...]] = (0, 3, 5)  # xx, yy, yawyaw in the upper triangle
_COV_NAMES: Final[tuple[str, ...]] = ("xx", "xy", "xyaw", "yy", "yyaw", "yawyaw")
_TRIU: Final = np.triu_indices(3)  # row-major upper triangle: (0,0) (0,1) (0,2) (1,1) (1,2) (2,2)
_YAW_WIRE_MAX: Final[float] = 3.1415  # the largest 1e-4 multiple inside (-pi, pi]
_ESTIMATOR_MAX: Final[int] = 128
_NUMBER: Final[frozenset[type]] = frozenset({int, float})


# --- in-memory types -----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PersonPose:
    """One person's estimated torso pose at one tick.

    Attributes:
        id: stable track id, >= 0, never reused by a host run.
        x, y: floor position, metres, world frame (REP-103, z up).
        yaw: torso heading, radians counter-clockwise from +x, in (-pi, pi].
        vx, vy: floor velocity, m/s.
        yaw_rate: rad/s.
        cov: (3, 3) float64 covariance of (x, y, yaw): symmetric, non-negative diagonal;
            units m^2, m*rad, rad^2.
        confidence: in [0, 1].
        cameras: ids of the cameras whose views were used.
        stamp_ns: capture time of the newest view used, UNIX nanoseconds.
        views: number of views used (at least ``len(cameras)``; 0 when the pose is predicted).
        estimator: which estimator produced this person's pose: ``"hybrid"``, ``"onnx"``,
            ``"analytic"`` (version 2; a version 1 message gives its top-level ``estimator``).
    """

    id: int
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    cov: NDArray[np.float64]
    confidence: float
    cameras: tuple[str, ...]
    stamp_ns: int
    views: int
    estimator: str = "unknown"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PersonPose):
            return NotImplemented
        scalars = ("id", "x", "y", "yaw", "vx", "vy", "yaw_rate", "confidence", "cameras", "stamp_ns", "views", "estimator")
        return all(getattr(self, a) == getattr(other, a) for a in scalars) and np.array_equal(self.cov, other.cov)

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class PoseArray:
    """Everything the host publishes for one tick.

    Attributes:
        site: site name.
        seq: tick sequence number, counting up from 0 for each host run.
        stamp_ns: the tick's world time, UNIX nanoseconds.
        people: the people tracked at this tick (possibly none).
        latency_ns: host processing latency, from the arrival of the newest observation used
            to publication.
        cameras_alive: cameras whose liveliness tokens are present.
        estimator: what produced the poses, e.g. ``"onnx:wtf-apartment.int8.onnx"`` or ``"analytic"``.
    """

    site: str
    seq: int
    stamp_ns: int
    people: tuple[PersonPose, ...] = ()
    latency_ns: int = 0
    cameras_alive: tuple[str, ...] = ()
    estimator: str = "unknown"


# --- errors --------------------------------------------------------------------------------


class PoseDecodeError(DecodeError):
    """A payload that is not a valid PoseArray.

    Attributes:
        field: dotted path of the offending value, e.g. ``people[2].cov[3]``; ``$`` for the
            payload as a whole.
        reason: one of ``REASONS`` (the vocabulary of ``edge.payload``), for counting rejects.
        detail: what was wrong and what is allowed.
    """


# --- validation ----------------------------------------------------------------------------


def _number(value: Any, path: str, lo: float, hi: float, interval: str) -> float:
    """A finite JSON number in [lo, hi]; ``interval`` describes the range (and unit) in errors."""
    if type(value) not in _NUMBER:
        fail(path, "type", f"must be a number in {interval}, got {brief(value)}")
    try:
        f = float(value)
    except OverflowError:  # an integer beyond float64
        fail(path, "non_finite", f"must be a finite number, got an integer of {value.bit_length()} bits")
    if not math.isfinite(f):  # 1e400 parses as inf
        fail(path, "non_finite", f"must be a finite number, got {brief(value)}")
    if not lo <= f <= hi:
        fail(path, "range", f"must be in {interval}, got {f:g}")
    return f


def _names(value: Any, path: str) -> tuple[str, ...]:
    """An array of at most MAX_CAMERAS distinct camera ids."""
    check_array_max(value, path, MAX_CAMERAS, "camera ids")
    names = tuple(check_name(v, f"{path}[{i}]") for i, v in enumerate(value))
    if len(set(names)) != len(names):
        i = next(i for i, n in enumerate(names) if n in names[:i])
        fail(f"{path}[{i}]", "range", f"repeats camera id {names[i]!r}; ids must be distinct")
    return names


def _estimator(value: Any, path: str) -> str:
    if not isinstance(value, str):
        fail(path, "type", f"must be a string, got {brief(value)}")
    if not 1 <= len(value) <= _ESTIMATOR_MAX or not value.isascii() or not value.isprintable():
        fail(path, "format", f"must be 1-{_ESTIMATOR_MAX} printable ASCII characters, got {brief(value)}")
    return value


def _cov(value: Any, path: str) -> NDArray[np.float64]:
    """Six numbers, the upper triangle of a 3x3 covariance, to the full symmetric matrix."""
    if not isinstance(value, list):
        fail(path, "type", f"must be an array of 6 numbers [xx, xy, xyaw, yy, yyaw, yawyaw], got {brief(value)}")
    if len(value) != 6:
        fail(path, "length", f"must have 6 entries [xx, xy, xyaw, yy, yyaw, yawyaw], has {len(value)}")
    upper = [
        _number(v, f"{path}[{k}]", 0.0 if k in _COV_DIAG else -_MAX_COV, _MAX_COV,
                f"[{0 if k in _COV_DIAG else -_MAX_COV:g}, {_MAX_COV:g}] ({_COV_NAMES[k]})")
        for k, v in enumerate(value)
    ]
    cov = np.empty((3, 3))
    cov[_TRIU] = upper
    cov.T[_TRIU] = upper
    return cov


def _person(p: Any, path: str, version: int, estimator: str) -> PersonPose:
    check_object(p, path, _PERSON_FIELDS if version >= 2 else _PERSON_FIELDS_V1, label=f"{SCHEMA} version {version}")
    coord = f"[{-_MAX_COORD_M:g}, {_MAX_COORD_M:g}] (metres)"
    speed = f"[{-_MAX_SPEED:g}, {_MAX_SPEED:g}]"
    pid = check_int(p["id"], f"{path}.id", 0, _MAX_ID)
    x = _number(p["x"], f"{path}.x", -_MAX_COORD_M, _MAX_COORD_M, coord)
    y = _number(p["y"], f"{path}.y", -_MAX_COORD_M, _MAX_COORD_M, coord)
    yaw = _number(p["yaw"], f"{path}.yaw", -math.pi, math.pi, "[-pi, pi] (radians)")
    vx = _number(p["vx"], f"{path}.vx", -_MAX_SPEED, _MAX_SPEED, speed + " (m/s)")
    vy = _number(p["vy"], f"{path}.vy", -_MAX_SPEED, _MAX_SPEED, speed + " (m/s)")
    yaw_rate = _number(p["yaw_rate"], f"{path}.yaw_rate", -_MAX_SPEED, _MAX_SPEED, speed + " (rad/s)")
    cov = _cov(p["cov"], f"{path}.cov")
    confidence = _number(p["confidence"], f"{path}.confidence", 0.0, 1.0, "[0, 1]")
    views = check_int(p["views"], f"{path}.views", 0, _MAX_VIEWS)
    cameras = _names(p["cameras"], f"{path}.cameras")
    if views < len(cameras) or (views > 0 and not cameras):
        fail(f"{path}.views", "range", f"must be >= the {len(cameras)} cameras listed, and 0 only when none is, got {views}")
    stamp_ns = check_int(p["stamp_ns"], f"{path}.stamp_ns", 0, MAX_INT63)
    if version >= 2:
        estimator = _estimator(p["estimator"], f"{path}.estimator")
    return PersonPose(
        id=pid, x=x, y=y,
        yaw=math.pi if yaw == -math.pi else yaw,  # the same heading; keep the documented (-pi, pi]
        vx=vx, vy=vy, yaw_rate=yaw_rate, cov=cov, confidence=confidence, cameras=cameras,
        stamp_ns=stamp_ns, views=views, estimator=estimator,
    )


def _pose_array(doc: Any, expected_site: str | None) -> PoseArray:
    check_message(doc, SCHEMA, READ_VERSIONS, _TOP_FIELDS)
    version = doc["version"]

    site = check_name(doc["site"], "site")
    if expected_site is not None and site != expected_site:
        fail("site", "site", f"must be {expected_site!r} (this subscriber's site), got {site!r}")
    seq = check_int(doc["seq"], "seq", 0, MAX_INT63)
    stamp_ns = check_int(doc["stamp_ns"], "stamp_ns", 0, MAX_INT63)
    latency_ns = check_int(doc["latency_ns"], "latency_ns", 0, MAX_INT63)
    estimator = _estimator(doc["estimator"], "estimator")
    cameras_alive = _names(doc["cameras_alive"], "cameras_alive")

    people = check_array_max(doc["people"], "people", MAX_PEOPLE, "people")
    seen: dict[int, int] = {}
    out = []
    for i, p in enumerate(people):
        person = _person(p, f"people[{i}]", version, estimator)
        if person.id in seen:
            fail(f"people[{i}].id", "range", f"repeats the id of people[{seen[person.id]}] ({person.id}); ids must be distinct")
        seen[person.id] = i
        out.append(person)
    return PoseArray(
        site=site, seq=seq, stamp_ns=stamp_ns, people=tuple(out), latency_ns=latency_ns,
        cameras_alive=cameras_alive, estimator=estimator,
    )


# --- public API ----------------------------------------------------------------------------


def decode(payload: bytes | bytearray | memoryview, *, expected_site: str | None = None) -> PoseArray:
    """Parse and validate one PoseArray payload.

    Args:
        payload: the message bytes (a ``zenoh.ZBytes`` is accepted too).
        expected_site: if given, a message from another site is rejected (reason ``"site"``).

    Returns:
        The PoseArray; each ``cov`` is a (3, 3) float64 symmetric matrix, each ``yaw`` in (-pi, pi].

    Raises:
        PoseDecodeError: for any invalid payload; ``field`` names the value, ``reason`` is in ``REASONS``.
    """
    try:
        return _pose_array(parse_json(payload, MAX_PAYLOAD_BYTES), expected_site)
    except DecodeError as e:  # the checks raise the shared base class; name this codec in the type
        raise PoseDecodeError(e.field, e.reason, e.detail) from None


def _rounded(value: Any, digits: int) -> Any:
    """``value`` rounded to ``digits`` decimals; a non-number is left for validation to reject."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        try:
            f = float(value)
        except OverflowError:  # a huge integer
            return value
        return round(f, digits) if math.isfinite(f) else f
    return value


def _as_list(value: Any) -> Any:
    # A string is a sequence too: "cam-1" must not become five camera ids.
    return list(value) if isinstance(value, (list, tuple)) else value


def _wire_yaw(value: Any) -> Any:
    """Yaw to 1e-4 rad, kept inside (-pi, pi]: values near +-pi would round to +-3.1416, past pi."""
    y = _rounded(value, 4)
    if isinstance(y, float) and -math.pi <= float(value) <= math.pi and abs(y) > _YAW_WIRE_MAX:
        return _YAW_WIRE_MAX  # -3.1416 and 3.1416 are both heading pi
    return y  # in range, or out of range / NaN / not a number for validation to name


def _wire_cov(cov: Any, path: str) -> list:
    c = np.asarray(cov, dtype=np.float64)
    if c.shape != (3, 3):
        raise ValueError(f"cannot encode poses: {path} must have shape (3, 3), has {c.shape}")
    if np.isfinite(c).all():
        # Filters leave float noise of ~1e-16 of the largest entry; a real asymmetry is a bug.
        if not np.allclose(c, c.T, rtol=0, atol=1e-9 * float(np.abs(c).max()) + 1e-15):
            raise ValueError(f"cannot encode poses: {path} must be symmetric, got {c.tolist()}")
        c = (c + c.T) / 2
    # 6 significant digits; NaN and inf pass through for validation to name.
    return [float(f"{v:.6g}") for v in c[_TRIU].tolist()]


def _person_doc(p: PersonPose, path: str) -> dict:
    return {
        "id": as_int(p.id),
        "x": _rounded(p.x, 3),  # 1 mm
        "y": _rounded(p.y, 3),
        "yaw": _wire_yaw(p.yaw),  # 1e-4 rad
        "vx": _rounded(p.vx, 3),  # 1 mm/s
        "vy": _rounded(p.vy, 3),
        "yaw_rate": _rounded(p.yaw_rate, 4),  # 1e-4 rad/s
        "cov": _wire_cov(p.cov, f"{path}.cov"),
        "confidence": _rounded(p.confidence, 4),
        "views": as_int(p.views),
        "cameras": _as_list(p.cameras),
        "stamp_ns": as_int(p.stamp_ns),
        "estimator": p.estimator,
    }


def encode(poses: PoseArray) -> bytes:
    """Serialise a PoseArray to compact JSON (about 250 bytes per person).

    Positions are rounded to 1 mm, velocities to 1 mm/s, yaw and yaw rate to 1e-4, confidence
    to 1e-4, covariances to 6 significant digits; only the upper triangle of each covariance is
    sent.

    Raises:
        ValueError: the poses would not decode (a value out of range, a NaN, a repeated id, an
            asymmetric covariance...); the message names the field.
    """
    doc = {
        "schema": SCHEMA,
        "version": VERSION,
        "site": poses.site,
        "seq": as_int(poses.seq),
        "stamp_ns": as_int(poses.stamp_ns),
        "latency_ns": as_int(poses.latency_ns),
        "estimator": poses.estimator,
        "cameras_alive": _as_list(poses.cameras_alive),
        "people": [_person_doc(p, f"people[{i}]") for i, p in enumerate(poses.people)],
    }
    # Refuse to send what every subscriber would reject: fail here, where the bug is.
    try:
        _pose_array(doc, None)
    except DecodeError as e:
        raise ValueError(f"cannot encode poses: {e}") from e
    payload = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode("utf-8")
    if len(payload) > MAX_PAYLOAD_BYTES:  # cannot happen for valid input; kept as a guard
        raise ValueError(f"cannot encode poses: {len(payload)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    return payload


def zenoh_encoding() -> zenoh.Encoding:
    """The ``zenoh.Encoding`` to put with each payload (``str()`` of it equals ``ENCODING``)."""
    import zenoh  # lazily: the codec itself does not need Zenoh

    return zenoh.Encoding.APPLICATION_JSON.with_schema(f"{SCHEMA}/{VERSION}")
