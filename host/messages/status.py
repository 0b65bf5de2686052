"""The host's status message on ``superbody/<site>/host/status``: a typed struct and its codec.

The schema, for dashboards and alarms in any language, is in ``docs/status-schema.md``. In short::

    {"cameras_alive": ["1", "2"], "cameras_total": 3, "people": 2, "obs_per_s": 44.9,
     "latency_ms": {"p50": 120.4, "p99": 180.2}, "rejected": {"late": 2}, "queue_dropped": 0,
     "published": 431, "health": {"state": "degraded", "reasons": ["camera 3: too_late: ..."]},
     "cameras": [{"id": "1", "alive": true, "state": "ok", "fps": 15.0, "delay_ms": {"p50": 95.1, "p95": 130.0},
                  "frames": 4300, "fused": 3900, "dropped": {}, "problems": []}, ...]}

``latency_ms`` is capture-to-publish: from the instant a PoseArray describes (the host's
watermark, ``host.timeline``) to its publication; ``p50`` and ``p99`` are ``null`` until the host
has published one. The status is version 1 of ``superbody.host_status`` (its Zenoh encoding says so,
``ENCODING``, as every superbody message's does); it may gain fields without a new version, and
``decode`` ignores fields it does not know. ``encode`` checks every value (a few comparisons: the host builds the status
from its own counters) and writes compact JSON with msgspec, which never writes ``NaN``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Final

import msgspec
from msgspec import Meta, Struct

from superbody.edge.messages.payload import NAME_PATTERN, DecodeError, Reason, check_object, fail, join_path, message_encoding, parse_json
from superbody.edge.site import NAME_RE

if TYPE_CHECKING:
    import zenoh

__all__ = ["SCHEMA", "VERSION", "ENCODING", "MAX_PAYLOAD_BYTES", "MAX_CAMERAS", "HEALTH_STATES", "CAMERA_STATES", "Latency", "Delay",
           "Health", "Calibration", "CameraStatus", "HostStatus", "latency", "delay", "encode", "decode", "zenoh_encoding"]

SCHEMA: Final[str] = "superbody.host_status"
VERSION: Final[int] = 1
# Zenoh 1.x renders an Encoding as "<mime>;<schema>": this string equals str(zenoh_encoding()).
ENCODING: Final[str] = f"application/json;{SCHEMA}/{VERSION}"

MAX_CAMERAS: Final[int] = 64  # a site file holds at most 64 cameras
MAX_PEOPLE: Final[int] = 64
# 64 camera ids and every reject reason with its count fit in a few KB; this only stops abuse.
MAX_PAYLOAD_BYTES: Final[int] = 64 * 1024

_NonNegative = Annotated[int, Meta(ge=0)]
_Milliseconds = Annotated[float, Meta(ge=0.0)]

HEALTH_STATES: Final[tuple[str, ...]] = ("ok", "degraded")
# A camera's state: its first problem's word (host.timeline.Timeline.problems), or "gone" (its
# liveliness token dropped), or "ok".
CAMERA_STATES: Final[tuple[str, ...]] = ("ok", "gone", "silent", "too_late", "slow", "over_rate", "two_publishers", "moved", "suspect")
MAX_REASONS: Final[int] = 256
_Reason = Annotated[str, Meta(max_length=512)]


class Latency(Struct, kw_only=True):
    """Median and 99th percentile of the host's latency, milliseconds: capture-to-publish, from
    the instant a PoseArray describes (the watermark) to its publication; null before the first."""

    p50: _Milliseconds | None
    p99: _Milliseconds | None


class Delay(Struct, kw_only=True):
    """A camera's delivery delay, milliseconds: its frames' arrival at the host minus their
    capture, median and 95th percentile over its last frames; null before its first frame."""

    p50: _Milliseconds | None
    p95: _Milliseconds | None


class Health(Struct, kw_only=True):
    """What a monitoring app alarms on: ``ok``, or ``degraded`` with one sentence per reason."""

    state: Annotated[str, Meta(pattern="^(ok|degraded)$", description="ok, or degraded (see reasons)")]
    reasons: Annotated[list[_Reason], Meta(max_length=MAX_REASONS, description="why degraded: one sentence each, "
                                                                               "'camera <id>: <state>: ...' for a camera's")]


class Calibration(Struct, kw_only=True):
    """How well a camera's views of people agree with the other cameras' (host.calibration.health)."""

    state: Annotated[str, Meta(pattern="^(unknown|ok|suspect|moved)$",
                               description="unknown (too few people seen with others), ok, suspect (off, but not found to have moved), moved")]
    residual_deg: Annotated[float, Meta(ge=0.0)] | None = None
    residual_px: Annotated[float, Meta(ge=0.0)] | None = None
    samples: Annotated[int, Meta(ge=0, description="joint residuals in the window (30 s)")]


class CameraStatus(Struct, kw_only=True):
    """One camera of the site, as the host sees it."""

    id: Annotated[str, Meta(pattern=NAME_PATTERN)]
    alive: Annotated[bool, Meta(description="its liveliness token is present")]
    state: Annotated[str, Meta(pattern="^(" + "|".join(CAMERA_STATES) + ")$", description="ok, or its first problem")]
    fps: Annotated[float, Meta(ge=0.0)] | None = None
    delay_ms: Delay
    frames: Annotated[int, Meta(ge=0, description="frames admitted")]
    fused: Annotated[int, Meta(ge=0, description="its views used in published poses")]
    dropped: Annotated[dict[str, _NonNegative], Meta(description="frames dropped, by reason: too_late, late, duplicate, "
                                                                 "seq_backwards, stale, over_rate, queue_full")]
    problems: Annotated[list[_Reason], Meta(max_length=16, description="what is wrong with it, one sentence each")]
    calibration: Calibration | None = None


class HostStatus(Struct, kw_only=True):
    """The host's periodic status (docs/status-schema.md), version 1; consumers ignore fields they do not know."""

    cameras_alive: Annotated[list[Annotated[str, Meta(pattern=NAME_PATTERN)]],
                             Meta(max_length=MAX_CAMERAS, extra_json_schema={"uniqueItems": True},
                                  description="ids of the site's cameras whose liveliness token is present, sorted")]
    cameras_total: Annotated[int, Meta(ge=1, le=MAX_CAMERAS, description="cameras in the site file")]
    people: Annotated[int, Meta(ge=0, le=MAX_PEOPLE, description="people in the PoseArray published just before")]
    obs_per_s: Annotated[float, Meta(ge=0.0, description="observation payloads taken from the queue per second since the previous status")]
    latency_ms: Latency
    rejected: Annotated[dict[str, _NonNegative], Meta(description="observations (and poses) dropped, by reason")]
    queue_dropped: Annotated[int, Meta(ge=0, description="observations dropped unread: the host's queue was full")]
    published: Annotated[int, Meta(ge=0, description="PoseArrays published")]
    # Since issue 37 (still version 1: fields are only ever added); absent from older hosts.
    health: Health | None = None
    cameras: Annotated[list[CameraStatus], Meta(max_length=MAX_CAMERAS)] | None = None


_ENCODER: Final = msgspec.json.Encoder()


def latency(p50: float, p99: float) -> Latency:
    """The status latency from two percentiles in ms; NaN (no sample yet) becomes null."""
    return Latency(p50=None if math.isnan(p50) else float(p50), p99=None if math.isnan(p99) else float(p99))


def delay(p50_s: float, p95_s: float) -> Delay:
    """A camera's delay from two percentiles in seconds; NaN (no frame yet) becomes null."""
    return Delay(p50=None if math.isnan(p50_s) else float(p50_s) * 1e3, p95=None if math.isnan(p95_s) else float(p95_s) * 1e3)


def _check(status: HostStatus) -> None:
    def bad(field: str, detail: str) -> None:
        raise ValueError(f"cannot encode host status: {field} {detail}")

    alive = status.cameras_alive
    if type(alive) is not list or len(alive) > MAX_CAMERAS or len(set(alive)) != len(alive) \
            or not all(type(c) is str and NAME_RE.fullmatch(c) for c in alive):
        bad("cameras_alive", f"must be a list of at most {MAX_CAMERAS} distinct camera ids, got {alive!r}")
    for field, lo, hi in (("cameras_total", 1, MAX_CAMERAS), ("people", 0, MAX_PEOPLE), ("queue_dropped", 0, None), ("published", 0, None)):
        v = getattr(status, field)
        if type(v) is not int or v < lo or (hi is not None and v > hi):
            bad(field, f"must be an integer in [{lo}, {hi if hi is not None else 'inf'}), got {v!r}")
    rate = status.obs_per_s
    if type(rate) not in (int, float) or not 0.0 <= rate < math.inf:
        bad("obs_per_s", f"must be a finite number >= 0, got {rate!r}")
    for field in ("p50", "p99"):
        v = getattr(status.latency_ms, field)
        if v is not None and (type(v) not in (int, float) or not 0.0 <= v < math.inf):
            bad(f"latency_ms.{field}", f"must be null or a finite number >= 0, got {v!r}")
    if type(status.rejected) is not dict or not all(type(k) is str and type(n) is int and n >= 0 for k, n in status.rejected.items()):
        bad("rejected", f"must map reason names to counts >= 0, got {status.rejected!r}")
    if status.health is not None:
        h = status.health
        if h.state not in HEALTH_STATES or len(h.reasons) > MAX_REASONS or not all(type(r) is str and len(r) <= 512 for r in h.reasons):
            bad("health", f"must be ok or degraded with at most {MAX_REASONS} reasons of up to 512 characters, got {h!r}")
    for cam in status.cameras or ():
        if not NAME_RE.fullmatch(cam.id) or cam.state not in CAMERA_STATES or (cam.fps is not None and not 0.0 <= cam.fps < math.inf):
            bad("cameras", f"camera {cam.id!r}: id, state (one of {', '.join(CAMERA_STATES)}) or fps out of range")
        for v in (cam.delay_ms.p50, cam.delay_ms.p95):
            if v is not None and not 0.0 <= v < math.inf:
                bad("cameras", f"camera {cam.id}: delay_ms must be null or finite >= 0, got {cam.delay_ms!r}")
        if min(cam.frames, cam.fused, *cam.dropped.values(), 0) < 0 or len(cam.problems) > 16:
            bad("cameras", f"camera {cam.id}: counters must be >= 0 and problems at most 16")
        cal = cam.calibration
        if cal is not None and (cal.state not in ("unknown", "ok", "suspect", "moved") or cal.samples < 0
                                or any(v is not None and not 0.0 <= v < math.inf for v in (cal.residual_deg, cal.residual_px))):
            bad("cameras", f"camera {cam.id}: calibration state must be unknown, ok, suspect or moved, residuals null or finite >= 0")


def encode(status: HostStatus) -> bytes:
    """Compact JSON of one status.

    Raises:
        ValueError: a value outside its range (the message names the field).
    """
    _check(status)
    return _ENCODER.encode(status)


def decode(payload: bytes | bytearray | memoryview) -> HostStatus:
    """Parse and validate one status payload (fields this version does not know are ignored).

    Raises:
        DecodeError: for any invalid payload; ``field`` names the value (``$`` for the whole
            payload), ``reason`` is ``oversize``, ``not_utf8``, ``not_json``, ``non_finite``,
            ``duplicate_key``, ``type``, ``missing`` or ``range``.
    """
    doc = parse_json(payload, MAX_PAYLOAD_BYTES)  # size, UTF-8, JSON, NaN literals: the shared checks and errors
    _no_repeated_key(doc, "")
    try:
        status = msgspec.convert(doc, HostStatus, strict=True)
    except msgspec.ValidationError as e:
        raise _validation_error(str(e)) from None
    if len(set(status.cameras_alive)) != len(status.cameras_alive):
        fail("cameras_alive", "range", "repeats a camera id; ids must be distinct")
    return status


def _no_repeated_key(doc: Any, path: str) -> None:
    if isinstance(doc, dict):
        check_object(doc, path, (), tuple(doc), label="superbody host status")  # reports a repeated key with its path
        for k, v in doc.items():
            _no_repeated_key(v, join_path(path, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            _no_repeated_key(v, f"{path}[{i}]")


def _validation_error(text: str) -> DecodeError:
    """msgspec's "Expected `int` >= 0, got ... - at `$.people`" as a DecodeError naming the field."""
    message, _, where = text.partition(" - at `")
    field = where.rstrip("`").removeprefix("$.") if where else ""
    if message.startswith("Object missing required field `"):
        name = message.split("`")[1]
        return DecodeError(join_path(field.removeprefix("$"), name), "missing", "is required")
    reason: Reason = "range" if any(op in message for op in (">=", "<=", "length", "matching")) else "type"
    return DecodeError(field.removeprefix("$") or "$", reason, message[0].lower() + message[1:])


def zenoh_encoding() -> zenoh.Encoding:
    """The ``zenoh.Encoding`` to put with each payload (``str()`` of it equals ``ENCODING``)."""
    return message_encoding(SCHEMA, VERSION)
