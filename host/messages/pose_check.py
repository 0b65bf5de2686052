"""The PoseArray's rule-by-rule validator: what the typed decoder did not take goes here, and the
first violation is named (field path, reason, allowed range) in a ``PoseDecodeError``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from superbody.edge.messages.payload import (
    _NUMBER,
    MAX_INT63,
    DecodeError,
    brief,
    check_array_max,
    check_int,
    check_message,
    check_name,
    check_object,
    fail,
)
from superbody.host.messages.pose_rules import (
    _COV_DIAG,
    _COV_NAMES,
    _ESTIMATOR_MAX,
    _MAX_COORD_M,
    _MAX_COV,
    _MAX_ID,
    _MAX_SPEED,
    _MAX_VIEWS,
    _PERSON_FIELDS,
    _PERSON_FIELDS_V1,
    _TOP_FIELDS,
    _TRIU,
    MAX_CAMERAS,
    MAX_PEOPLE,
    READ_VERSIONS,
    SCHEMA,
)
from superbody.host.messages.pose_types import PersonPose, PoseArray

__all__ = ["PoseDecodeError"]


class PoseDecodeError(DecodeError):
    """A payload that is not a valid PoseArray.

    Attributes:
        field: dotted path of the offending value, e.g. ``people[2].cov[3]``; ``$`` for the
            payload as a whole.
        reason: one of ``REASONS`` (the vocabulary of ``edge.messages.payload``), for counting rejects.
        detail: what was wrong and what is allowed.
    """


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
