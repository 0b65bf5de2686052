"""The host's output message, the PoseArray, and its wire codec on ``superbody/<site>/people``.

The schema, for subscribers in any language, is in ``docs/pose-schema.md``. In short::

    {"schema": "superbody.people", "version": 2, "site": "lab", "seq": 42,
     "stamp_ns": 1718000000000000000, "latency_ns": 2100000, "estimator": "analytic",
     "cameras_alive": ["cam-1", "cam-2"],
     "people": [{"id": 3, "x": 1.234, "y": -0.5, "yaw": 1.5708,          # m, m, rad (REP-103)
                 "vx": 0.41, "vy": 0.0, "yaw_rate": 0.0123,              # m/s, m/s, rad/s
                 "cov": [xx, xy, xyaw, yy, yyaw, yawyaw],                # upper triangle
                 "confidence": 0.93, "views": 2, "cameras": ["cam-1", "cam-2"],
                 "stamp_ns": 1717999999990000000, "estimator": "hybrid"}]}

``encode`` rounds positions to 1 mm, velocities to 1 mm/s, angles and angular rates to 1e-4,
confidence to 1e-4 and covariances to 6 significant digits, so a person is about 250 bytes.
``decode`` checks every field and raises ``PoseDecodeError`` naming the field
(``people[2].cov[3]``), a ``reason`` from ``REASONS`` for reject counters, and the allowed range;
the checks shared with the Observation codec are in ``edge/messages/payload.py``.

How (as in ``edge/messages/wire.py``): the message is defined as msgspec structs (``PoseArrayMsg``,
``PersonPoseMsg``, and their version 1 forms), which carry every rule a JSON Schema can state and
from which ``docs/schemas/people.schema.json`` is generated. A payload the reference encoder
could have written (ASCII, no escapes) is decoded by msgspec in one pass, then checked for what a
type cannot state (distinct ids and camera ids, views against cameras, no repeated key). What
fails goes to the rule-by-rule validator (``_pose_array``), which names the first violation.
``encode`` checks the in-memory values vectorised, on the rounded values it sends, and writes the
structs; on a failed check the validator names the field.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Final

import msgspec
import numpy as np

from superbody.edge.messages.payload import (
    MAX_INT63,
    REASONS,
    DecodeError,
    as_int,
    checked_json,
    fail,
    int_within,
    message_encoding,
    parse_json,
    typed_input,
)
from superbody.edge.site import NAME_RE
from superbody.host.messages.pose_check import PoseDecodeError, _pose_array
from superbody.host.messages.pose_rules import (
    _COV_DIAG,
    _ESTIMATOR_MAX,
    _MAX_COORD_M,
    _MAX_COV,
    _MAX_ID,
    _MAX_SPEED,
    _MAX_VIEWS,
    _TRIU,
    _YAW_WIRE_MAX,
    ENCODING,
    MAX_CAMERAS,
    MAX_PAYLOAD_BYTES,
    MAX_PEOPLE,
    SCHEMA,
    VERSION,
    PersonPoseMsg,
    PersonPoseMsgV1,
    PoseArrayMsg,
    PoseArrayMsgV1,
)
from superbody.host.messages.pose_types import PersonPose, PoseArray

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
    "PersonPoseMsg",
    "PersonPoseMsgV1",
    "PoseArrayMsg",
    "PoseArrayMsgV1",
    "encode",
    "decode",
    "zenoh_encoding",
]




# Every rule a JSON Schema can state lives here; the rest is in _typed_decode.


_DECODERS: Final = (msgspec.json.Decoder(PoseArrayMsg), msgspec.json.Decoder(PoseArrayMsgV1))  # the newest first
_ENCODER: Final = msgspec.json.Encoder()
# The JSON strings of a valid message: 9 keys, schema, site and estimator at the top; 12 keys a
# person (13 and its estimator in version 2); and every camera id.
_TOP_STRINGS: Final[int] = 12
_PERSON_STRINGS: Final[dict[int, int]] = {1: 12, 2: 14}
# (N, 6) upper triangles to (N, 9) row-major full matrices.
_FULL_FROM_UPPER: Final = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])


def _typed_decode(data: bytes, expected_site: str | None) -> PoseArray | None:
    """The PoseArray if ``data`` passes every rule, else None (the validator then names the violation)."""
    for decoder in _DECODERS:
        try:
            msg = decoder.decode(data)
            break
        except (msgspec.ValidationError, msgspec.DecodeError):
            continue
    else:
        return None
    people = msg.people
    strings = _TOP_STRINGS + len(msg.cameras_alive) + _PERSON_STRINGS[msg.version] * len(people)
    strings += sum(len(p.cameras) for p in people)
    if data.count(b'"') != 2 * strings:
        return None  # a repeated key (typed_input ruled out escapes)
    if expected_site is not None and msg.site != expected_site:
        fail("site", "site", f"must be {expected_site!r} (this subscriber's site), got {msg.site!r}")
    if len(set(msg.cameras_alive)) != len(msg.cameras_alive) or len({p.id for p in people}) != len(people):
        return None
    for p in people:
        if len(set(p.cameras)) != len(p.cameras) or p.views < len(p.cameras) or (p.views and not p.cameras):
            return None
    cov = np.array([p.cov for p in people], dtype=np.float64).reshape(-1, 6)[:, _FULL_FROM_UPPER].reshape(-1, 3, 3)
    top = msg.estimator
    return PoseArray(
        site=msg.site, seq=msg.seq, stamp_ns=msg.stamp_ns, latency_ns=msg.latency_ns, estimator=top,
        cameras_alive=tuple(msg.cameras_alive),
        people=tuple(
            PersonPose(
                id=p.id, x=p.x, y=p.y, yaw=math.pi if p.yaw == -math.pi else p.yaw,  # the same heading; keep (-pi, pi]
                vx=p.vx, vy=p.vy, yaw_rate=p.yaw_rate, cov=cov[i], confidence=p.confidence, cameras=tuple(p.cameras),
                stamp_ns=p.stamp_ns, views=p.views, estimator=p.estimator if isinstance(p, PersonPoseMsg) else top,  # version 2 people carry their own
            )
            for i, p in enumerate(people)
        ),
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
        data = typed_input(payload, MAX_PAYLOAD_BYTES)
        if data is not None:
            poses = _typed_decode(data, expected_site)
            if poses is not None:
                return poses
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
    finite = np.isfinite(c)
    if finite.all():
        # Filters leave float noise of ~1e-16 of the largest entry; a real asymmetry is a bug.
        if not np.allclose(c, c.T, rtol=0, atol=1e-9 * float(np.abs(c).max()) + 1e-15):
            raise ValueError(f"cannot encode poses: {path} must be symmetric, got {c.tolist()}")
        c = (c + c.T) / 2
    elif (finite != finite.T).any():  # a NaN below the diagonal only is an asymmetry too, not one to drop
        raise ValueError(f"cannot encode poses: {path} must be symmetric, got {c.tolist()}")
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


def _ints_in(values: list, lo: int, hi: int) -> list[int] | None:
    """Every value an integer in [lo, hi] (as ``_int_in``), as Python ints; None if one is not."""
    if not all(type(v) is int for v in values):
        values = [int_within(v, lo, hi) for v in values]
        return None if None in values else values
    return values if not values or (lo <= min(values) and max(values) <= hi) else None


def _names_ok(names: Sequence[str]) -> bool:
    """Every entry a camera id: one regex call for all of them, joined by NUL (which no id holds)."""
    if not names:
        return True
    text = "\x00".join(names)  # a non-string raises TypeError
    return text.count("\x00") == len(names) - 1 and bool(_NAMES_RE.fullmatch(text + "\x00"))


def _estimator_ok(value: Any) -> bool:
    return type(value) is str and 1 <= len(value) <= _ESTIMATOR_MAX and value.isascii() and value.isprintable()


# Columns of the (N, 7) scalar table and the decimals each is sent with.
_SCALARS: Final[tuple[str, ...]] = ("x", "y", "yaw", "vx", "vy", "yaw_rate", "confidence")
_SCALE: Final = 10.0 ** np.array([3, 3, 4, 3, 3, 4, 4])  # 1 mm, 1 mm/s, 1e-4 rad, rad/s and confidence
_LO: Final = np.array([-_MAX_COORD_M, -_MAX_COORD_M, -math.pi, -_MAX_SPEED, -_MAX_SPEED, -_MAX_SPEED, 0.0])
_HI: Final = np.array([_MAX_COORD_M, _MAX_COORD_M, math.pi, _MAX_SPEED, _MAX_SPEED, _MAX_SPEED, 1.0])
_COV_LO: Final = np.array([0.0 if k in _COV_DIAG else -_MAX_COV for k in range(6)])
_NUMBER_TYPES: Final[frozenset[type]] = frozenset({float, int, np.float64, np.float32})
_NAMES_RE: Final = re.compile(r"(?:[A-Za-z0-9_-]{1,64}\x00)*")  # camera ids, each followed by NUL


def _typed_encode(poses: PoseArray) -> bytes | None:
    """The payload, or None if a value breaks a rule (or is of an odd type): every check runs on
    the rounded values that are sent, for all people at once. None sends ``encode`` to the
    validator, which names the field."""
    people = poses.people
    n = len(people)
    top = _ints_in([poses.seq, poses.stamp_ns, poses.latency_ns], 0, MAX_INT63)
    alive = poses.cameras_alive
    if (top is None or n > MAX_PEOPLE or type(poses.site) is not str or not NAME_RE.fullmatch(poses.site)
            or not _estimator_ok(poses.estimator) or type(alive) not in (tuple, list) or len(alive) > MAX_CAMERAS
            or len(set(alive)) != len(alive) or not _names_ok(alive)):
        return None
    msg_people: list[PersonPoseMsg] = []
    if n:
        flat = [getattr(p, a) for p in people for a in _SCALARS]
        if not _NUMBER_TYPES.issuperset(map(type, flat)):  # bools, strings, None...
            return None
        raw = np.array(flat, dtype=np.float64).reshape(n, len(_SCALARS))  # (n, 7); an int beyond float64 raises
        # Half to even on the scaled value: the grid of round(v, d), ties aside.
        wire = np.round(raw * _SCALE) / _SCALE
        yaw = raw[:, 2]
        # Yaw to 1e-4 rad, kept inside (-pi, pi]: values near +-pi would round to +-3.1416, past pi.
        wire[:, 2] = np.where((yaw >= -math.pi) & (yaw <= math.pi) & (np.abs(wire[:, 2]) > _YAW_WIRE_MAX), _YAW_WIRE_MAX, wire[:, 2])
        cov = np.array([p.cov for p in people], dtype=np.float64)  # (n, 3, 3)
        if cov.shape != (n, 3, 3) or not ((wire >= _LO) & (wire <= _HI)).all() or not np.isfinite(cov).all():
            return None
        cov_t = cov.transpose(0, 2, 1)
        # Filters leave float noise of ~1e-16 of the largest entry; a real asymmetry is a bug.
        atol = 1e-9 * np.abs(cov).max(axis=(1, 2)) + 1e-15
        if not (np.abs(cov - cov_t) <= atol[:, None, None]).all():
            return None
        upper = ((cov + cov_t) / 2)[:, _TRIU[0], _TRIU[1]]  # (n, 6)
        # 6 significant digits: one C-level format of all of them.
        c = np.array(("%.6g " * upper.size % tuple(upper.ravel().tolist())).split(), dtype=np.float64).reshape(n, 6)
        if not ((c >= _COV_LO) & (c <= _MAX_COV)).all():
            return None
        ids = _ints_in([p.id for p in people], 0, _MAX_ID)
        views = _ints_in([p.views for p in people], 0, _MAX_VIEWS)
        stamps = _ints_in([p.stamp_ns for p in people], 0, MAX_INT63)
        cams = [p.cameras for p in people]
        if (ids is None or views is None or stamps is None or len(set(ids)) != n
                or not all(type(cs) in (tuple, list) and len(cs) <= MAX_CAMERAS and len(set(cs)) == len(cs) for cs in cams)
                or not _names_ok([c for cs in cams for c in cs])
                or not all(v >= len(cs) and (len(cs) or not v) for v, cs in zip(views, cams))
                or not all(_estimator_ok(e) for e in {p.estimator for p in people if type(p.estimator) is str})
                or not all(type(p.estimator) is str for p in people)):
            return None
        msg_people = [
            PersonPoseMsg(id=i, x=x, y=y, yaw=yw, vx=vx, vy=vy, yaw_rate=yr, cov=cv, confidence=conf, views=v,
                          cameras=list(cs), stamp_ns=st, estimator=p.estimator)
            for p, i, (x, y, yw, vx, vy, yr, conf), cv, v, cs, st in zip(people, ids, wire.tolist(), c.tolist(), views, cams, stamps)
        ]
    return _ENCODER.encode(PoseArrayMsg(
        schema=SCHEMA, version=VERSION, site=poses.site, seq=top[0], stamp_ns=top[1], latency_ns=top[2],
        estimator=poses.estimator, cameras_alive=list(alive), people=msg_people,
    ))


def encode(poses: PoseArray) -> bytes:
    """Serialise a PoseArray to compact JSON (about 250 bytes per person).

    Positions are rounded to 1 mm, velocities to 1 mm/s, yaw and yaw rate to 1e-4, confidence
    to 1e-4, covariances to 6 significant digits; only the upper triangle of each covariance is
    sent.

    Raises:
        ValueError: the poses would not decode (a value out of range, a NaN, a repeated id, an
            asymmetric covariance...); the message names the field.
    """
    try:
        payload = _typed_encode(poses)
    except (TypeError, ValueError, OverflowError):  # e.g. a value numpy cannot read as a number
        payload = None
    if payload is None:
        payload = _checked_encode(poses)
    if len(payload) > MAX_PAYLOAD_BYTES:  # cannot happen for valid input; kept as a guard
        raise ValueError(f"cannot encode poses: {len(payload)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    return payload


def _checked_encode(poses: PoseArray) -> bytes:
    """The encoder for what ``_typed_encode`` refused: a document checked by the validator, which
    names the field that breaks a rule (and encodes what only looked odd, e.g. a numpy float)."""
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
    return checked_json(doc, _pose_array, "poses")


def zenoh_encoding() -> zenoh.Encoding:
    """The ``zenoh.Encoding`` to put with each payload (``str()`` of it equals ``ENCODING``)."""
    return message_encoding(SCHEMA, VERSION)
