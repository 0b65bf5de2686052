"""The PoseArray message's rule table: its name, versions and limits, and the message as typed
structs (msgspec) that carry every rule a JSON Schema can state. ``host/messages/pose.py``
decodes and encodes with them and checks the rules a type cannot state;
``docs/schemas/people.schema.json`` is generated from them.
"""

from __future__ import annotations

import math
from typing import Annotated, Final, Literal

import numpy as np
from msgspec import Meta, Struct

from superbody.edge.messages.payload import (
    MAX_INT63,
    NAME_PATTERN,
)

__all__ = ["SCHEMA", "VERSION", "ENCODING", "MAX_PEOPLE", "MAX_SPEED", "MAX_CAMERAS", "MAX_PAYLOAD_BYTES", "PersonPoseMsgV1", "PersonPoseMsg", "PoseArrayMsgV1", "PoseArrayMsg"]


SCHEMA: Final = "superbody.people"


VERSION: Final = 2  # what the encoder writes


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


MAX_SPEED: Final[float] = 100.0  # m/s and rad/s: far beyond people, only stops garbage
_MAX_SPEED: Final[float] = MAX_SPEED


_MAX_COV: Final[float] = 1e6


_COV_DIAG: Final[tuple[int, ...]] = (0, 3, 5)  # xx, yy, yawyaw in the upper triangle


_COV_NAMES: Final[tuple[str, ...]] = ("xx", "xy", "xyaw", "yy", "yyaw", "yawyaw")


_TRIU: Final = np.triu_indices(3)  # row-major upper triangle: (0,0) (0,1) (0,2) (1,1) (1,2) (2,2)


_YAW_WIRE_MAX: Final[float] = 3.1415  # the largest 1e-4 multiple inside (-pi, pi]


_ESTIMATOR_MAX: Final[int] = 128


_Name = Annotated[str, Meta(pattern=NAME_PATTERN, description="1-64 characters of A-Z a-z 0-9 _ - (a Zenoh key chunk)")]


_Names = Annotated[list[_Name], Meta(max_length=MAX_CAMERAS, extra_json_schema={"uniqueItems": True})]


_Count = Annotated[int, Meta(ge=0, le=MAX_INT63)]


_Estimator = Annotated[str, Meta(min_length=1, max_length=_ESTIMATOR_MAX, pattern="^[ -~]+$",
                                 description="printable ASCII")]


_Coord = Annotated[float, Meta(ge=-_MAX_COORD_M, le=_MAX_COORD_M, description="metres, world frame (REP-103)")]


_Speed = Annotated[float, Meta(ge=-_MAX_SPEED, le=_MAX_SPEED)]


_Var = Annotated[float, Meta(ge=0.0, le=_MAX_COV)]


_Covar = Annotated[float, Meta(ge=-_MAX_COV, le=_MAX_COV)]


class PersonPoseMsgV1(Struct, forbid_unknown_fields=True, kw_only=True):
    """One person's torso pose, version 1 (version 2 without the per-person estimator)."""

    id: Annotated[int, Meta(ge=0, le=_MAX_ID)]
    x: _Coord
    y: _Coord
    yaw: Annotated[float, Meta(ge=-math.pi, le=math.pi, description="radians, counter-clockwise from +x; -pi reads as pi")]
    vx: Annotated[_Speed, Meta(description="m/s")]
    vy: Annotated[_Speed, Meta(description="m/s")]
    yaw_rate: Annotated[_Speed, Meta(description="rad/s")]
    cov: Annotated[tuple[_Var, _Covar, _Covar, _Var, _Covar, _Var],
                   Meta(description="upper triangle of the (x, y, yaw) covariance: xx, xy, xyaw, yy, yyaw, yawyaw")]
    confidence: Annotated[float, Meta(ge=0.0, le=1.0)]
    views: Annotated[int, Meta(ge=0, le=_MAX_VIEWS, description=">= len(cameras); 0 only with no cameras (checked by the decoder)")]
    cameras: _Names
    stamp_ns: _Count


class PersonPoseMsg(PersonPoseMsgV1, forbid_unknown_fields=True, kw_only=True):
    """One person's torso pose at one tick; ids are distinct within a message (checked by the decoder)."""

    estimator: Annotated[_Estimator, Meta(description='"hybrid", "onnx" or "analytic": what produced this pose')]


class PoseArrayMsgV1(Struct, forbid_unknown_fields=True, kw_only=True):
    """The host's PoseArray, version 1 (still read)."""

    schema: Literal["superbody.people"]
    version: Literal[1]
    site: _Name
    seq: _Count
    stamp_ns: _Count
    latency_ns: _Count
    estimator: _Estimator
    cameras_alive: _Names
    people: Annotated[list[PersonPoseMsgV1], Meta(max_length=MAX_PEOPLE)]


class PoseArrayMsg(Struct, forbid_unknown_fields=True, kw_only=True):
    """The host's PoseArray: each tracked person's floor pose (docs/pose-schema.md)."""

    schema: Literal["superbody.people"]
    version: Literal[2]
    site: _Name
    seq: _Count
    stamp_ns: _Count
    latency_ns: _Count
    estimator: _Estimator
    cameras_alive: _Names
    people: Annotated[list[PersonPoseMsg], Meta(max_length=MAX_PEOPLE)]
