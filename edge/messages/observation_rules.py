"""The Observation message's rule table: its name, version and limits, and the message as typed
structs (msgspec) that carry every rule a JSON Schema can state (types, lengths, ranges, name
patterns). ``edge/messages/wire.py`` decodes and encodes with them and checks the rules a type
cannot state; ``docs/schemas/observation.schema.json`` is generated from them.
"""

from __future__ import annotations

from typing import Annotated, Final, Literal

import numpy as np
from msgspec import UNSET, Meta, Struct, UnsetType

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.colour import HIST_BINS
from superbody.edge.messages.payload import (
    MAX_INT63,
    NAME_PATTERN,
)

__all__ = ["SCHEMA", "VERSION", "ENCODING", "MAX_PAYLOAD_BYTES", "MAX_PEOPLE", "HistogramMsg", "PersonMsg", "ObservationMsg"]


SCHEMA: Final = "superbody.observation"


VERSION: Final = 1


# Zenoh 1.x renders an Encoding as "<mime>;<schema>": this string equals str(zenoh_encoding()).
ENCODING: Final[str] = f"application/json;{SCHEMA}/{VERSION}"


# Checked before parsing. 64 full people encode to about 150 KB, so this only stops abuse.
MAX_PAYLOAD_BYTES: Final[int] = 256 * 1024


MAX_PEOPLE: Final[int] = 64


_TOP_FIELDS: Final[tuple[str, ...]] = ("schema", "version", "site", "camera", "seq", "stamp_ns", "image", "people")


_LABEL: Final[str] = f"{SCHEMA} version {VERSION}"  # names the schema in unknown_field errors


_PERSON_FIELDS: Final[tuple[str, ...]] = ("keypoints", "bbox", "histogram")


_PERSON_OPTIONAL: Final[tuple[str, ...]] = ("points3d",)


_HIST_FIELDS: Final[tuple[str, ...]] = ("bins", "values")


_IMAGE_MIN, _IMAGE_MAX = 16, 16384


_MAX_COORD_M: Final[float] = 100.0


_HIST_SIZE: Final[int] = HIST_BINS[0] * HIST_BINS[1]


_HIST_SUM_TOL: Final[float] = 1e-2


_MIN_SCORE: Final[float] = 1e-5  # the score resolution on the wire


_SCORE_OPEN: Final = np.array([False, False, True])  # u, v closed below; score > 0




_Name = Annotated[str, Meta(pattern=NAME_PATTERN, description="1-64 characters of A-Z a-z 0-9 _ - (a Zenoh key chunk)")]


_Count = Annotated[int, Meta(ge=0, le=MAX_INT63)]


_ImageSide = Annotated[int, Meta(ge=_IMAGE_MIN, le=_IMAGE_MAX)]


# The bounds that hold for any image; the decoder checks [-W, 2W] and [-H, 2H] of this image.
_Pixel = Annotated[float, Meta(ge=-_IMAGE_MAX, le=2 * _IMAGE_MAX)]


_Score = Annotated[float, Meta(gt=0.0, le=1.0)]


_Fraction = Annotated[float, Meta(ge=0.0, le=1.0)]


_Metre = Annotated[float, Meta(ge=-_MAX_COORD_M, le=_MAX_COORD_M)]


_BinCount = Annotated[int, Meta(ge=1, le=1024)]


_JOINTS = Meta(min_length=NUM_KEYPOINTS, max_length=NUM_KEYPOINTS,
               description="COCO-17 order; null for a joint not detected (no depth, for points3d)")


class HistogramMsg(Struct, forbid_unknown_fields=True, kw_only=True):
    """OpenCV HSV hue x saturation histogram: values[8*h + s], summing to 0 or to 1 +- 0.01 (checked by the decoder)."""

    bins: Annotated[tuple[_BinCount, _BinCount], Meta(extra_json_schema={"const": list(HIST_BINS)})]
    values: Annotated[list[_Fraction], Meta(min_length=_HIST_SIZE, max_length=_HIST_SIZE)]


class PersonMsg(Struct, forbid_unknown_fields=True, kw_only=True):
    """One person in one frame. keypoints and bbox in pixels within [-W, 2W] x [-H, 2H] of the image,
    x0 <= x1 and y0 <= y1 (checked by the decoder); points3d in metres, camera frame (optional)."""

    keypoints: Annotated[list[tuple[_Pixel, _Pixel, _Score] | None], _JOINTS]
    bbox: tuple[_Pixel, _Pixel, _Pixel, _Pixel]
    histogram: HistogramMsg
    points3d: Annotated[list[tuple[_Metre, _Metre, _Metre] | None], _JOINTS] | None | UnsetType = UNSET


class ObservationMsg(Struct, forbid_unknown_fields=True, kw_only=True):
    """One camera frame: the people a camera's 2D pose detector saw (docs/observation-schema.md)."""

    schema: Literal["superbody.observation"]
    version: Literal[1]
    site: _Name
    camera: _Name
    seq: _Count
    stamp_ns: _Count
    image: tuple[_ImageSide, _ImageSide]
    people: Annotated[list[PersonMsg], Meta(max_length=MAX_PEOPLE)]
