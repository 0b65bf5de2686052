"""The Observation wire codec: versioned, compact JSON on ``superbody/<site>/cameras/<camera>/observations``.

The schema, for subscribers in any language, is in ``docs/observation-schema.md``. In short::

    {"schema": "superbody.observation", "version": 1, "site": "lab", "camera": "1",
     "seq": 42, "stamp_ns": 1718000000000000000, "image": [640, 480],
     "people": [{"keypoints": [[u, v, score] | null] x 17,      # COCO-17, pixels, (0, 1]
                 "bbox": [x0, y0, x1, y1],                      # pixels
                 "histogram": {"bins": [16, 8], "values": [128 numbers]},
                 "points3d": [[x, y, z] | null] x 17}]}         # optional, camera frame, metres

``encode`` rounds pixels to 0.01 px, scores and histogram values to 1e-5 and 3D points to
0.1 mm, so a full person is about 2 KB. ``decode`` checks every field and raises ``DecodeError``
naming the field (``people[2].keypoints[5][1]``), a ``reason`` from ``REASONS`` for reject
counters, and the allowed range. Numeric arrays are checked with numpy; the error still names
the first offending element. The checks every superbody codec shares, and ``DecodeError``
itself, are in ``edge/messages/payload.py``.

How: the message is defined as typed structs (``ObservationMsg``, ``PersonMsg``,
``HistogramMsg``: msgspec), which carry every rule a JSON Schema can state (types, lengths,
ranges, name patterns) and from which ``docs/schemas/observation.schema.json`` is generated. A
payload the reference encoder could have written (ASCII, no escapes) is decoded by msgspec in
one pass; the rules a type cannot state (pixels within the image, box order, histogram sum,
scores that stay positive in float32, no repeated key) are then checked on the typed values,
all people at once with numpy. A payload that fails any of that, or that the typed decoder does
not take, goes to the rule-by-rule validator (``_observation``), which finds the first
violation and names it: errors are the documented ones, and only invalid traffic pays for them.
``encode`` checks the in-memory values the same way (vectorised, on the rounded values it
sends) and writes the structs with msgspec; on a failed check, the validator names the field.
"""

from __future__ import annotations

import math
from itertools import chain
from typing import TYPE_CHECKING, Any, Final, cast

import msgspec
import numpy as np
from msgspec import UNSET
from numpy.typing import NDArray

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.colour import HIST_BINS
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.messages.observation_rules import (
    _HIST_FIELDS,
    _HIST_SIZE,
    _HIST_SUM_TOL,
    _IMAGE_MAX,
    _IMAGE_MIN,
    _LABEL,
    _MAX_COORD_M,
    _MIN_SCORE,
    _PERSON_FIELDS,
    _PERSON_OPTIONAL,
    _SCORE_OPEN,
    _TOP_FIELDS,
    ENCODING,
    MAX_PAYLOAD_BYTES,
    MAX_PEOPLE,
    SCHEMA,
    VERSION,
    HistogramMsg,
    ObservationMsg,
    PersonMsg,
)
from superbody.edge.messages.payload import (
    MAX_INT63,
    REASONS,
    DecodeError,
    Reason,
    as_int,
    brief,
    check_array,
    check_array_max,
    check_int,
    check_int_pair,
    check_message,
    check_name,
    check_numbers,
    check_object,
    check_range,
    checked_json,
    fail,
    int_within,
    message_encoding,
    parse_json,
    typed_input,
)
from superbody.edge.site import NAME_RE

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "SCHEMA",
    "VERSION",
    "ENCODING",
    "MAX_PAYLOAD_BYTES",
    "MAX_PEOPLE",
    "REASONS",
    "Reason",
    "DecodeError",
    "HistogramMsg",
    "PersonMsg",
    "ObservationMsg",
    "encode",
    "decode",
    "zenoh_encoding",
]


_DECODER: Final = msgspec.json.Decoder(ObservationMsg)  # strict: no bool for a number, no float for an integer
_ENCODER: Final = msgspec.json.Encoder()
_NAN3: Final = (math.nan, math.nan, math.nan)
_chain: Final = chain.from_iterable
# The JSON strings of a valid message: 8 keys and 3 values at the top, 5 keys a person (+1 with a points3d key).
_TOP_STRINGS, _PERSON_STRINGS = 11, 5


def _typed_decode(data: bytes, expected_site: str | None) -> Observation | None:
    """The Observation if ``data`` passes every rule, else None (the validator then names the violation)."""
    try:
        msg = _DECODER.decode(data)
    except (msgspec.ValidationError, msgspec.DecodeError):
        return None
    people = msg.people
    n = len(people)
    keys_3d = sum(p.points3d is not UNSET for p in people)  # "points3d": null counts too
    if data.count(b'"') != 2 * (_TOP_STRINGS + _PERSON_STRINGS * n + keys_3d):
        return None  # a repeated key (typed_input ruled out escapes)
    if expected_site is not None and msg.site != expected_site:
        fail("site", "site", f"must be {expected_site!r} (this subscriber's site), got {msg.site!r}")
    width, height = msg.image
    if not n:
        return Observation(msg.site, msg.camera, msg.seq, msg.stamp_ns, width, height, ())

    # numpy reads a flat iterator of floats faster than nested sequences.
    rows = [r or _NAN3 for p in people for r in p.keypoints]
    kp = np.fromiter(_chain(rows), np.float64, 3 * len(rows)).reshape(-1, 3)  # (17n, 3), NaN rows: missing
    bbox = np.array([p.bbox for p in people])  # (n, 4)
    hist = np.fromiter(_chain(p.histogram.values for p in people), np.float64, _HIST_SIZE * n).reshape(n, _HIST_SIZE)
    # Missing joints are NaN rows: every comparison with them is False.
    u, v = kp[:, 0], kp[:, 1]
    bx, by = bbox[:, 0::2], bbox[:, 1::2]
    if ((u < -width) | (u > 2 * width) | (v < -height) | (v > 2 * height)).any() \
            or ((bx < -width) | (bx > 2 * width) | (by < -height) | (by > 2 * height)).any() \
            or (bbox[:, 2] < bbox[:, 0]).any() or (bbox[:, 3] < bbox[:, 1]).any():
        return None
    if any(p.histogram.bins != HIST_BINS for p in people):
        return None
    total = hist.sum(axis=1)
    if ((total != 0.0) & (np.abs(total - 1.0) > _HIST_SUM_TOL)).any():
        return None
    hist /= np.where(total > 0.0, total, 1.0)[:, None]  # hand consumers the documented invariant: sums to 1
    kp32: NDArray[np.float32] = kp.astype(np.float32)
    if (kp32[:, 2] <= 0.0).any():  # a positive score below float32's range (NaN rows compare False)
        return None

    kp32 = kp32.reshape(n, NUM_KEYPOINTS, 3)
    bbox32 = bbox.astype(np.float32)
    hist32 = hist.astype(np.float32).reshape(n, *HIST_BINS)
    with_3d = [p.points3d for p in people if p.points3d]
    rows3 = [r or _NAN3 for points3d in with_3d for r in points3d]
    xyz = iter(np.fromiter(_chain(rows3), np.float64, 3 * len(rows3)).astype(np.float32).reshape(-1, NUM_KEYPOINTS, 3))
    return Observation(
        site=msg.site, camera=msg.camera, seq=msg.seq, stamp_ns=msg.stamp_ns, width=width, height=height,
        people=tuple(
            PersonView(keypoints=kp32[i], bbox=bbox32[i], histogram=hist32[i], points3d=next(xyz) if p.points3d else None)
            for i, p in enumerate(people)
        ),
    )


# --- the rule-by-rule validator: names the first violation ---------------------------------


# --- validation: numeric arrays ------------------------------------------------------------


def _vector(value: Any, path: str, n: int, what: str) -> NDArray[np.float64]:
    return check_numbers(check_array(value, path, n, what), lambda k: f"{path}[{k}]")


def _joints(value: Any, path: str, what: str) -> tuple[list[int], NDArray[np.float64]]:
    """17 entries, each null or 3 numbers: (indices of the present joints, (P, 3) values)."""
    if not isinstance(value, list):
        fail(path, "type", f"must be an array of {NUM_KEYPOINTS} entries, each {what} or null, got {brief(value)}")
    if len(value) != NUM_KEYPOINTS:
        fail(path, "length", f"must have {NUM_KEYPOINTS} entries (COCO-17), has {len(value)}")
    present: list[int] = []
    flat: list = []
    for j, row in enumerate(value):
        if row is None:
            continue
        if not isinstance(row, list):
            fail(f"{path}[{j}]", "type", f"must be {what} or null, got {brief(row)}")
        if len(row) != 3:
            fail(f"{path}[{j}]", "length", f"must have 3 entries ({what}), has {len(row)}")
        present.append(j)
        flat += row
    a = check_numbers(flat, lambda k: f"{path}[{present[k // 3]}][{k % 3}]")
    return present, a.reshape(-1, 3)


def _scatter(present: list[int], values: NDArray[np.float32]) -> NDArray[np.float32]:
    out = np.full((NUM_KEYPOINTS, 3), np.nan, dtype=np.float32)
    out[present] = values
    return out


def _person(p: Any, path: str, width: int, height: int) -> PersonView:
    check_object(p, path, _PERSON_FIELDS, _PERSON_OPTIONAL, label=_LABEL)
    # Detectors extrapolate joints a little outside the image.
    u_lo, u_hi, v_lo, v_hi = -width, 2 * width, -height, 2 * height

    kp_path = f"{path}.keypoints"
    present, kp = _joints(p["keypoints"], kp_path, "[u, v, score]")
    kp_where = lambda k: f"{kp_path}[{present[k // 3]}][{k % 3}]"  # noqa: E731
    kp_interval = lambda k: (f"[{u_lo}, {u_hi}] (u, pixels)", f"[{v_lo}, {v_hi}] (v, pixels)", "(0, 1] (score)")[k % 3]  # noqa: E731
    check_range(kp, np.array([u_lo, v_lo, 0.0]), np.array([u_hi, v_hi, 1.0]), kp_where, kp_interval, open_lo=_SCORE_OPEN)
    kp32 = kp.astype(np.float32)
    if (kp32[:, 2] <= 0).any():  # a positive score below float32's range
        k = int(np.argmax(kp32[:, 2] <= 0)) * 3 + 2
        fail(kp_where(k), "range", f"must be in (0, 1] and representable as float32, got {kp[k // 3, 2]:g}")

    bb_path = f"{path}.bbox"
    bbox = _vector(p["bbox"], bb_path, 4, "numbers [x0, y0, x1, y1]")
    bb_where = lambda k: f"{bb_path}[{k}]"  # noqa: E731
    check_range(bbox, np.array([u_lo, v_lo, u_lo, v_lo]), np.array([u_hi, v_hi, u_hi, v_hi]), bb_where,
                 lambda k: f"[{u_lo}, {u_hi}] (pixels)" if k % 2 == 0 else f"[{v_lo}, {v_hi}] (pixels)")
    for k in (2, 3):
        if bbox[k] < bbox[k - 2]:
            fail(bb_where(k), "range", f"must be >= {bb_path}[{k - 2}] = {bbox[k - 2]:g}, got {bbox[k]:g}")

    h_path = f"{path}.histogram"
    hist = check_object(p["histogram"], h_path, _HIST_FIELDS, label=_LABEL)
    bins = check_int_pair(hist["bins"], f"{h_path}.bins", 1, 1024)
    if bins != HIST_BINS:
        fail(f"{h_path}.bins", "range", f"must be {list(HIST_BINS)} (hue x saturation), got {list(bins)}")
    v_path = f"{h_path}.values"
    values = _vector(hist["values"], v_path, _HIST_SIZE, "numbers in [0, 1]")
    check_range(values, np.array(0.0), np.array(1.0), lambda k: f"{v_path}[{k}]", lambda k: "[0, 1]")
    total = float(values.sum())
    if total != 0.0 and abs(total - 1.0) > _HIST_SUM_TOL:
        fail(v_path, "range", f"must sum to 0 or to 1 +- {_HIST_SUM_TOL:g}, sums to {total:g}")
    if total > 0.0:
        values /= total  # hand consumers the documented invariant: sums to 1

    points3d = None
    p3 = p.get("points3d")
    if p3 is not None:
        p3_path = f"{path}.points3d"
        present3, xyz = _joints(p3, p3_path, "[x, y, z]")
        check_range(xyz, np.array(-_MAX_COORD_M), np.array(_MAX_COORD_M), lambda k: f"{p3_path}[{present3[k // 3]}][{k % 3}]",
                     lambda k: f"[{-_MAX_COORD_M:g}, {_MAX_COORD_M:g}] (metres)")
        points3d = _scatter(present3, xyz.astype(np.float32))

    return PersonView(
        keypoints=_scatter(present, kp32),
        bbox=bbox.astype(np.float32),
        histogram=values.astype(np.float32).reshape(HIST_BINS),
        points3d=points3d,
    )


def _observation(doc: Any, expected_site: str | None) -> Observation:
    check_message(doc, SCHEMA, VERSION, _TOP_FIELDS)

    site = check_name(doc["site"], "site")
    if expected_site is not None and site != expected_site:
        fail("site", "site", f"must be {expected_site!r} (this subscriber's site), got {site!r}")
    camera = check_name(doc["camera"], "camera")
    seq = check_int(doc["seq"], "seq", 0, MAX_INT63)
    stamp_ns = check_int(doc["stamp_ns"], "stamp_ns", 0, MAX_INT63)
    width, height = check_int_pair(doc["image"], "image", _IMAGE_MIN, _IMAGE_MAX)
    people = check_array_max(doc["people"], "people", MAX_PEOPLE, "people")
    return Observation(
        site=site, camera=camera, seq=seq, stamp_ns=stamp_ns, width=width, height=height,
        people=tuple(_person(p, f"people[{i}]", width, height) for i, p in enumerate(people)),
    )


# --- public API ----------------------------------------------------------------------------


def decode(payload: bytes | bytearray | memoryview, *, expected_site: str | None = None) -> Observation:
    """Parse and validate one Observation payload.

    Args:
        payload: the message bytes (a ``zenoh.ZBytes`` is accepted too).
        expected_site: if given, a message from another site is rejected (reason ``"site"``).

    Returns:
        The Observation. Keypoints and 3D points are (17, 3) float32 with NaN rows for missing
        joints; the histogram is ``HIST_BINS`` float32, renormalised to sum to 1 (or all zeros).

    Raises:
        DecodeError: for any invalid payload; ``field`` names the value, ``reason`` is in ``REASONS``.
    """
    data = typed_input(payload, MAX_PAYLOAD_BYTES)
    if data is not None:
        obs = _typed_decode(data, expected_site)
        if obs is not None:
            return obs
    return _observation(parse_json(payload, MAX_PAYLOAD_BYTES), expected_site)


def _array(value: Any, shape: tuple[int, ...], field: str) -> NDArray[np.float64]:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"cannot encode observation: {field} must have shape {shape}, has {a.shape}")
    return a


def _rows(a: NDArray[np.float64]) -> list:
    """(17, 3) to nested lists, with all-NaN rows (missing joints) as None."""
    rows = a.tolist()
    for j in np.flatnonzero(np.isnan(a).all(axis=1)):
        rows[j] = None
    return rows


def _person_doc(p: PersonView, path: str) -> dict:
    kp = _array(p.keypoints, (NUM_KEYPOINTS, 3), f"{path}.keypoints")
    score = kp[:, 2]
    score_r = np.round(score, 5)
    wire_kp = np.empty_like(kp)
    wire_kp[:, :2] = np.round(kp[:, :2], 2)  # 0.01 px
    # 1e-5; a positive score too small for that stays positive rather than becoming invalid.
    wire_kp[:, 2] = np.where((score > 0) & (score_r < _MIN_SCORE), _MIN_SCORE, score_r)
    doc = {
        "keypoints": _rows(wire_kp),
        "bbox": np.round(_array(p.bbox, (4,), f"{path}.bbox"), 2).tolist(),
        "histogram": {
            "bins": list(HIST_BINS),
            "values": np.round(_array(p.histogram, HIST_BINS, f"{path}.histogram").ravel(), 5).tolist(),
        },
    }
    if p.points3d is not None:
        doc["points3d"] = _rows(np.round(_array(p.points3d, (NUM_KEYPOINTS, 3), f"{path}.points3d"), 4))  # 0.1 mm
    return doc


def _null_rows(a: NDArray[np.float64], missing: NDArray[np.bool_]) -> list:
    """(P, 17, 3) to nested lists, with the ``missing`` (P, 17) rows as None."""
    rows = a.tolist()
    for i, j in zip(*(k.tolist() for k in np.nonzero(missing))):
        rows[i][j] = None
    return rows


def _typed_encode(obs: Observation) -> bytes | None:
    """The payload, or None if a value breaks a rule (or is of an odd type): every check runs on
    the rounded values that are sent, for all people at once. None sends ``encode`` to the
    validator, which names the field."""
    site, camera = obs.site, obs.camera
    if type(site) is not str or type(camera) is not str or not NAME_RE.fullmatch(site) or not NAME_RE.fullmatch(camera):
        return None
    seq, stamp_ns = int_within(obs.seq, 0, MAX_INT63), int_within(obs.stamp_ns, 0, MAX_INT63)
    w, h = int_within(obs.width, _IMAGE_MIN, _IMAGE_MAX), int_within(obs.height, _IMAGE_MIN, _IMAGE_MAX)
    people = obs.people
    n = len(people)
    if seq is None or stamp_ns is None or w is None or h is None or n > MAX_PEOPLE:
        return None
    msg_people: list[PersonMsg] = []
    if n:
        kp = np.array([p.keypoints for p in people], dtype=np.float64)  # (n, 17, 3)
        bbox = np.array([p.bbox for p in people], dtype=np.float64)  # (n, 4)
        hist = np.array([p.histogram for p in people], dtype=np.float64)  # (n, 16, 8)
        if kp.shape != (n, NUM_KEYPOINTS, 3) or bbox.shape != (n, 4) or hist.shape != (n, *HIST_BINS):
            return None
        wire_kp = np.empty_like(kp)
        wire_kp[..., :2] = np.round(kp[..., :2], 2)  # 0.01 px
        score, score_r = kp[..., 2], np.round(kp[..., 2], 5)
        # 1e-5; a positive score too small for that stays positive rather than becoming invalid.
        wire_kp[..., 2] = np.where((score > 0) & (score_r < _MIN_SCORE), _MIN_SCORE, score_r)
        missing = cast("NDArray[np.bool_]", np.isnan(wire_kp).all(axis=2))  # (n, 17)
        u, v, s = wire_kp[..., 0], wire_kp[..., 1], wire_kp[..., 2]
        # A NaN or infinity in a present joint fails these comparisons.
        kp_ok = (u >= -w) & (u <= 2 * w) & (v >= -h) & (v <= 2 * h) & (s > 0) & (s <= 1)
        wire_bbox = np.round(bbox, 2)
        bx, by = wire_bbox[:, 0::2], wire_bbox[:, 1::2]
        wire_hist = np.round(hist.reshape(n, _HIST_SIZE), 5)
        total = wire_hist.sum(axis=1)
        if not ((kp_ok | missing).all() and ((bx >= -w) & (bx <= 2 * w) & (by >= -h) & (by <= 2 * h)).all()
                and (wire_bbox[:, 2] >= wire_bbox[:, 0]).all() and (wire_bbox[:, 3] >= wire_bbox[:, 1]).all()
                and ((wire_hist >= 0) & (wire_hist <= 1)).all()
                and ((total == 0.0) | (np.abs(total - 1.0) <= _HIST_SUM_TOL)).all()):
            return None
        with_3d = [i for i, p in enumerate(people) if p.points3d is not None]
        points3d: dict[int, list] = {}
        if with_3d:
            p3 = cast("NDArray[np.float64]", np.round(np.array([people[i].points3d for i in with_3d], dtype=np.float64), 4))  # 0.1 mm; cast: numpy stubs pick float16
            if p3.shape != (len(with_3d), NUM_KEYPOINTS, 3):
                return None
            missing3 = cast("NDArray[np.bool_]", np.isnan(p3).all(axis=2))
            if not ((np.abs(p3) <= _MAX_COORD_M).all(axis=2) | missing3).all():
                return None
            points3d = dict(zip(with_3d, _null_rows(p3, missing3)))
        bins = HIST_BINS
        msg_people = [
            PersonMsg(keypoints=k, bbox=b, histogram=HistogramMsg(bins=bins, values=hv), points3d=points3d.get(i, UNSET))
            for i, (k, b, hv) in enumerate(zip(_null_rows(wire_kp, missing), wire_bbox.tolist(), wire_hist.tolist()))
        ]
    return _ENCODER.encode(ObservationMsg(
        schema=SCHEMA, version=VERSION, site=site, camera=camera, seq=seq, stamp_ns=stamp_ns, image=(w, h), people=msg_people,
    ))


def encode(obs: Observation) -> bytes:
    """Serialise an Observation to compact JSON (about 2 KB per person).

    Pixels are rounded to 0.01 px, scores and histogram values to 1e-5, 3D points to 0.1 mm.
    All-NaN rows of ``keypoints`` and ``points3d`` become ``null`` (missing joint).

    Raises:
        ValueError: the observation would not decode (a value out of range, a NaN inside a
            present joint, a wrong array shape...); the message names the field.
    """
    try:
        payload = _typed_encode(obs)
    except (TypeError, ValueError, OverflowError):  # e.g. an array numpy cannot read as numbers
        payload = None
    if payload is None:
        payload = _checked_encode(obs)
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"cannot encode observation: {len(payload)} bytes, more than the {MAX_PAYLOAD_BYTES} allowed")
    return payload


def _checked_encode(obs: Observation) -> bytes:
    """The encoder for what ``_typed_encode`` refused: a document checked by the validator, which
    names the field that breaks a rule (and encodes what only looked odd, e.g. a float subclass)."""
    doc = {
        "schema": SCHEMA,
        "version": VERSION,
        "site": obs.site,
        "camera": obs.camera,
        "seq": as_int(obs.seq),
        "stamp_ns": as_int(obs.stamp_ns),
        "image": [as_int(obs.width), as_int(obs.height)],
        "people": [_person_doc(p, f"people[{i}]") for i, p in enumerate(obs.people)],
    }
    return checked_json(doc, _observation, "observation")


def zenoh_encoding() -> zenoh.Encoding:
    """The ``zenoh.Encoding`` to put with each payload (``str()`` of it equals ``ENCODING``)."""
    return message_encoding(SCHEMA, VERSION)

