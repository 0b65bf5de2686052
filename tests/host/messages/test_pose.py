"""Tests of the PoseArray codec (host/messages/pose.py): a table of bad payloads, round trips, sizes,
and property tests that throw arbitrary and mutated payloads at the decoder."""

from __future__ import annotations

import json
import math
import pickle
import re
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from superbody.host.messages.pose import (
    ENCODING,
    MAX_CAMERAS,
    MAX_PAYLOAD_BYTES,
    MAX_PEOPLE,
    REASONS,
    SCHEMA,
    VERSION,
    PersonPose,
    PoseArray,
    PoseDecodeError,
    decode,
    encode,
    zenoh_encoding,
)
from tests.conftest import ROOT

DOCS = ROOT / "docs" / "pose-schema.md"
STAMP = 1_718_000_000_123_456_789


# --- fixtures: valid poses -----------------------------------------------------------------


def make_cov(rng: np.random.Generator) -> np.ndarray:
    a = rng.normal(0.0, 0.2, (3, 3))
    return a @ a.T + np.diag([1e-4, 1e-4, 1e-3])


def make_person(rng: np.random.Generator, pid: int, cameras: tuple[str, ...] = ("cam-1", "cam-2")) -> PersonPose:
    return PersonPose(
        id=pid,
        x=float(rng.uniform(-10, 10)), y=float(rng.uniform(-10, 10)), yaw=float(rng.uniform(-math.pi, math.pi)),
        vx=float(rng.normal(0, 1)), vy=float(rng.normal(0, 1)), yaw_rate=float(rng.normal(0, 0.5)),
        cov=make_cov(rng), confidence=float(rng.uniform(0, 1)), cameras=cameras,
        stamp_ns=STAMP - int(rng.integers(0, 50_000_000)), views=len(cameras),
        estimator=("hybrid", "onnx", "analytic")[pid % 3],
    )


def make_poses(n: int = 2, seed: int = 0) -> PoseArray:
    rng = np.random.default_rng(seed)
    people = tuple(make_person(rng, 10 + i) for i in range(n))
    return PoseArray("lab", 42, STAMP, people, 2_100_000, ("cam-1", "cam-2", "cam-3"), "onnx:wtf-apartment.int8.onnx")


def with_person(**change: Any) -> PoseArray:
    """One person from ``make_poses`` with some attributes changed."""
    p = make_poses(1).people[0]
    return PoseArray("lab", 1, STAMP, (PersonPose(**{**p.__dict__, **change}),))


def valid_doc() -> dict:
    """A valid message as a JSON document, for the bad-input table to break."""
    return json.loads(encode(make_poses(2, seed=1)))


def dumps(doc: Any) -> bytes:
    return json.dumps(doc, allow_nan=True).encode()


def yaw_diff(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def assert_close(a: PoseArray, b: PoseArray) -> None:
    """Equal up to the documented rounding."""
    assert (a.site, a.seq, a.stamp_ns, a.latency_ns, a.cameras_alive, a.estimator) == (
        b.site, b.seq, b.stamp_ns, b.latency_ns, b.cameras_alive, b.estimator)
    assert len(a.people) == len(b.people)
    for p, q in zip(a.people, b.people):
        assert (p.id, p.cameras, p.stamp_ns, p.views) == (q.id, q.cameras, q.stamp_ns, q.views)
        for attr in ("x", "y", "vx", "vy"):
            assert abs(getattr(p, attr) - getattr(q, attr)) <= 5e-4 + 1e-12, attr  # 1 mm, 1 mm/s
        assert abs(p.yaw_rate - q.yaw_rate) <= 5e-5 + 1e-12
        assert abs(p.confidence - q.confidence) <= 5e-5 + 1e-12
        # 1e-4 rounding, and up to 1.4e-4 where a yaw next to -pi is sent as 3.1415.
        assert yaw_diff(p.yaw, q.yaw) <= 1.5e-4
        assert -math.pi < q.yaw <= math.pi
        assert q.cov.shape == (3, 3) and q.cov.dtype == np.float64
        np.testing.assert_array_equal(q.cov, q.cov.T)
        np.testing.assert_allclose(q.cov, (p.cov + p.cov.T) / 2, rtol=5e-6, atol=1e-300)  # 6 significant digits


# --- bad payloads: each case breaks one thing ----------------------------------------------


def edit(fn: Callable[[dict], Any]) -> Callable[[], bytes]:
    """A payload made by applying ``fn`` to a valid document (in place)."""
    def make() -> bytes:
        doc = valid_doc()
        fn(doc)
        return dumps(doc)
    return make


def raw(data: bytes) -> Callable[[], bytes]:
    return lambda: data


def p0(doc: dict) -> dict:
    return doc["people"][0]


BAD_CASES = [
    # whole payload
    pytest.param(raw(b" " * (MAX_PAYLOAD_BYTES + 1)), {}, "$", "oversize", id="oversize"),
    pytest.param(raw(b'{"schema": "\xff"}'), {}, "$", "not_utf8", id="not-utf8"),
    pytest.param(raw(b'{"schema": "superbody.people", "version": '), {}, "$", "not_json", id="truncated"),
    pytest.param(raw(b""), {}, "$", "not_json", id="empty-payload"),
    pytest.param(raw(b"[" * 100_000), {}, "$", "not_json", id="nested-too-deep"),
    pytest.param(raw(b"[]"), {}, "$", "type", id="json-array-at-top"),
    pytest.param(raw(b'{"schema": "superbody.people", "schema": "x"}'), {}, "schema", "duplicate_key", id="duplicate-top-key"),
    pytest.param(edit(lambda d: p0(d).__setitem__("x", float("nan"))), {}, "$", "non_finite", id="nan-literal"),
    pytest.param(lambda: edit(lambda d: p0(d).__setitem__("y", 12345.678))().replace(b"12345.678", b"-1e400"), {}, "people[0].y", "non_finite", id="1e400-overflows"),
    pytest.param(edit(lambda d: p0(d).__setitem__("vx", 10**400)), {}, "people[0].vx", "non_finite", id="int-beyond-float64"),
    # schema and version
    pytest.param(edit(lambda d: d.__setitem__("schema", "superbody.observation")), {}, "schema", "schema", id="observation-schema"),
    pytest.param(edit(lambda d: d.pop("schema")), {}, "schema", "missing", id="no-schema"),
    pytest.param(edit(lambda d: d.update(version=3, novelty=1)), {}, "version", "version", id="version-3-before-unknown-fields"),
    pytest.param(edit(lambda d: p0(d).pop("estimator")), {}, "people[0].estimator", "missing", id="v2-person-without-estimator"),
    pytest.param(edit(lambda d: p0(d).__setitem__("estimator", "")), {}, "people[0].estimator", "format", id="empty-person-estimator"),
    pytest.param(edit(lambda d: d.update(version=1)), {}, "people[0].estimator", "unknown_field", id="v1-has-no-person-estimator"),
    pytest.param(edit(lambda d: d.__setitem__("version", 1.0)), {}, "version", "type", id="version-float"),
    # top-level fields
    pytest.param(edit(lambda d: d.pop("latency_ns")), {}, "latency_ns", "missing", id="missing-latency"),
    pytest.param(edit(lambda d: d.__setitem__("frame_id", "map")), {}, "frame_id", "unknown_field", id="unknown-top-field"),
    pytest.param(edit(lambda d: d.__setitem__("site", "lab/1")), {}, "site", "format", id="site-with-slash"),
    pytest.param(edit(lambda d: None), {"expected_site": "kitchen"}, "site", "site", id="site-mismatch"),
    pytest.param(edit(lambda d: d.__setitem__("seq", -1)), {}, "seq", "range", id="seq-negative"),
    pytest.param(edit(lambda d: d.__setitem__("stamp_ns", 2**63)), {}, "stamp_ns", "range", id="stamp-2^63"),
    pytest.param(edit(lambda d: d.__setitem__("latency_ns", 2.5e6)), {}, "latency_ns", "type", id="latency-float"),
    pytest.param(edit(lambda d: d.__setitem__("estimator", "")), {}, "estimator", "format", id="estimator-empty"),
    pytest.param(edit(lambda d: d.__setitem__("estimator", "onnx:\n")), {}, "estimator", "format", id="estimator-control-char"),
    pytest.param(edit(lambda d: d.__setitem__("estimator", "x" * 129)), {}, "estimator", "format", id="estimator-too-long"),
    pytest.param(edit(lambda d: d.__setitem__("estimator", None)), {}, "estimator", "type", id="estimator-null"),
    pytest.param(edit(lambda d: d.__setitem__("cameras_alive", "cam-1")), {}, "cameras_alive", "type", id="cameras-alive-string"),
    pytest.param(edit(lambda d: d.__setitem__("cameras_alive", ["a", "b", "a"])), {}, "cameras_alive[2]", "range", id="cameras-alive-repeated"),
    pytest.param(edit(lambda d: d.__setitem__("cameras_alive", [f"c{i}" for i in range(MAX_CAMERAS + 1)])), {}, "cameras_alive", "length", id="cameras-alive-65"),
    pytest.param(edit(lambda d: d.__setitem__("people", None)), {}, "people", "type", id="people-null"),
    pytest.param(edit(lambda d: d.__setitem__("people", [{**p0(d), "id": i} for i in range(MAX_PEOPLE + 1)])), {}, "people", "length", id="too-many-people"),
    pytest.param(edit(lambda d: d["people"].__setitem__(1, [])), {}, "people[1]", "type", id="person-array"),
    # person fields
    pytest.param(edit(lambda d: d["people"][1].__setitem__("z", 0.0)), {}, "people[1].z", "unknown_field", id="unknown-person-field"),
    pytest.param(edit(lambda d: p0(d).pop("cov")), {}, "people[0].cov", "missing", id="missing-cov"),
    pytest.param(edit(lambda d: d["people"][1].__setitem__("id", p0(d)["id"])), {}, "people[1].id", "range", id="repeated-id"),
    pytest.param(edit(lambda d: p0(d).__setitem__("id", -1)), {}, "people[0].id", "range", id="id-negative"),
    pytest.param(edit(lambda d: p0(d).__setitem__("id", 2**53)), {}, "people[0].id", "range", id="id-beyond-2^53"),
    pytest.param(edit(lambda d: p0(d).__setitem__("id", "7")), {}, "people[0].id", "type", id="id-string"),
    pytest.param(edit(lambda d: p0(d).__setitem__("x", 1000.001)), {}, "people[0].x", "range", id="x-beyond-1-km"),
    pytest.param(edit(lambda d: p0(d).__setitem__("y", True)), {}, "people[0].y", "type", id="y-bool"),
    pytest.param(edit(lambda d: p0(d).__setitem__("yaw", 3.1416)), {}, "people[0].yaw", "range", id="yaw-past-pi"),
    pytest.param(edit(lambda d: p0(d).__setitem__("yaw", -4)), {}, "people[0].yaw", "range", id="yaw-below-minus-pi"),
    pytest.param(edit(lambda d: p0(d).__setitem__("vy", -100.5)), {}, "people[0].vy", "range", id="vy-beyond-100"),
    pytest.param(edit(lambda d: p0(d).__setitem__("yaw_rate", "0")), {}, "people[0].yaw_rate", "type", id="yaw-rate-string"),
    pytest.param(edit(lambda d: p0(d).__setitem__("confidence", 1.0001)), {}, "people[0].confidence", "range", id="confidence-above-1"),
    pytest.param(edit(lambda d: p0(d).__setitem__("confidence", -0.01)), {}, "people[0].confidence", "range", id="confidence-negative"),
    pytest.param(edit(lambda d: p0(d).__setitem__("cov", [1, 0, 0, 1, 0, 1, 0, 0, 1])), {}, "people[0].cov", "length", id="cov-full-matrix"),
    pytest.param(edit(lambda d: p0(d).__setitem__("cov", {"xx": 1})), {}, "people[0].cov", "type", id="cov-object"),
    pytest.param(edit(lambda d: p0(d)["cov"].__setitem__(3, -1e-9)), {}, "people[0].cov[3]", "range", id="cov-negative-yy"),
    pytest.param(edit(lambda d: p0(d)["cov"].__setitem__(5, -1)), {}, "people[0].cov[5]", "range", id="cov-negative-yawyaw"),
    pytest.param(edit(lambda d: p0(d)["cov"].__setitem__(1, 2e6)), {}, "people[0].cov[1]", "range", id="cov-xy-huge"),
    pytest.param(edit(lambda d: p0(d)["cov"].__setitem__(2, None)), {}, "people[0].cov[2]", "type", id="cov-null"),
    pytest.param(edit(lambda d: p0(d).__setitem__("views", 256)), {}, "people[0].views", "range", id="views-256"),
    pytest.param(edit(lambda d: p0(d).__setitem__("views", 1)), {}, "people[0].views", "range", id="fewer-views-than-cameras"),
    pytest.param(edit(lambda d: p0(d).update(views=1, cameras=[])), {}, "people[0].views", "range", id="views-without-cameras"),
    pytest.param(edit(lambda d: p0(d).__setitem__("cameras", ["cam 1"])), {}, "people[0].cameras[0]", "format", id="camera-with-space"),
    pytest.param(edit(lambda d: p0(d).__setitem__("cameras", ["cam-1", "cam-1"])), {}, "people[0].cameras[1]", "range", id="camera-repeated"),
    pytest.param(edit(lambda d: p0(d).__setitem__("stamp_ns", -5)), {}, "people[0].stamp_ns", "range", id="person-stamp-negative"),
]


@pytest.mark.parametrize("make_payload, kwargs, field, reason", BAD_CASES)
def test_bad_payload_names_field_and_reason(make_payload: Callable[[], bytes], kwargs: dict, field: str, reason: str) -> None:
    with pytest.raises(PoseDecodeError) as info:
        decode(make_payload(), **kwargs)
    assert (info.value.field, info.value.reason) == (field, reason), str(info.value)
    assert info.value.reason in REASONS
    assert str(info.value).startswith(f"{field}: ")


def test_error_message_gives_allowed_range() -> None:
    doc = valid_doc()
    p0(doc)["x"] = 5000
    with pytest.raises(PoseDecodeError, match=r"people\[0\]\.x: must be in \[-1000, 1000\] \(metres\), got 5000"):
        decode(dumps(doc))


def test_payload_of_wrong_python_type_is_a_decode_error() -> None:
    with pytest.raises(PoseDecodeError) as info:
        decode("{}")  # type: ignore[arg-type]
    assert (info.value.field, info.value.reason) == ("$", "type")


def test_decode_error_pickles_with_field_and_reason() -> None:
    e = pickle.loads(pickle.dumps(PoseDecodeError("people[0].cov[3]", "range", "must be >= 0")))
    assert (e.field, e.reason, str(e)) == ("people[0].cov[3]", "range", "people[0].cov[3]: must be >= 0")
    assert isinstance(e, ValueError)


# --- valid payloads ------------------------------------------------------------------------


def test_empty_people_list_is_valid() -> None:
    poses = PoseArray("lab", 0, 0, (), 0, (), "analytic")
    assert decode(encode(poses)) == poses
    assert json.loads(encode(poses))["people"] == []


VALID_EDITS = [
    pytest.param(lambda d: None, id="as-encoded"),
    pytest.param(lambda d: p0(d).update(x=-1000, y=1000), id="coordinates-on-bounds"),
    pytest.param(lambda d: p0(d).update(x=2, vx=0), id="integers-for-floats"),
    pytest.param(lambda d: p0(d).__setitem__("yaw", math.pi), id="yaw-pi"),
    pytest.param(lambda d: p0(d).__setitem__("yaw", -math.pi), id="yaw-minus-pi-read-as-pi"),
    pytest.param(lambda d: p0(d).update(views=0, cameras=[]), id="predicted-without-views"),
    pytest.param(lambda d: p0(d).update(views=5), id="more-views-than-cameras"),
    pytest.param(lambda d: p0(d).update(cov=[0] * 6, confidence=0), id="zero-covariance"),
    pytest.param(lambda d: p0(d).update(id=2**53 - 1, stamp_ns=0), id="id-max"),
    pytest.param(lambda d: d.update(cameras_alive=[], estimator="analytic v2 (fallback)"), id="no-camera-alive"),
]


@pytest.mark.parametrize("fn", VALID_EDITS)
def test_valid_edits_decode(fn: Callable[[dict], Any]) -> None:
    doc = valid_doc()
    fn(doc)
    poses = decode(dumps(doc))
    for p in poses.people:
        assert -math.pi < p.yaw <= math.pi
    assert_close(poses, decode(encode(poses)))


@pytest.mark.parametrize("wrap", [bytes, bytearray, memoryview], ids=["bytes", "bytearray", "memoryview"])
def test_decode_accepts_bytes_like(wrap: type) -> None:
    poses = make_poses(2)
    assert_close(poses, decode(wrap(encode(poses)), expected_site="lab"))


def test_decode_accepts_zenoh_zbytes() -> None:
    zenoh = pytest.importorskip("zenoh")
    poses = make_poses(1)
    assert_close(poses, decode(zenoh.ZBytes(encode(poses))))


# --- round trip, size, encoder checks ------------------------------------------------------


@pytest.mark.parametrize("n", [0, 1, 10, MAX_PEOPLE])  # nobody, one, a busy room, the limit
def test_round_trip(n: int) -> None:
    poses = make_poses(n, seed=n)
    back = decode(encode(poses))
    assert_close(poses, back)
    assert decode(encode(back)) == back  # already-rounded values survive unchanged


def test_ten_people_fit_in_3_kb() -> None:
    assert len(encode(make_poses(10))) < 3072


def test_encoding_is_compact_and_canonical() -> None:
    text = encode(make_poses(1)).decode()
    assert ", " not in text and ": " not in text
    doc = json.loads(text)
    assert list(doc) == ["schema", "version", "site", "seq", "stamp_ns", "latency_ns", "estimator", "cameras_alive", "people"]
    assert list(doc["people"][0]) == ["id", "x", "y", "yaw", "vx", "vy", "yaw_rate", "cov", "confidence", "views", "cameras", "stamp_ns", "estimator"]
    assert (doc["schema"], doc["version"]) == (SCHEMA, VERSION)
    assert all(v == float(f"{v:.6g}") for v in doc["people"][0]["cov"])  # 6 significant digits


@pytest.mark.parametrize(
    "yaw, wire",
    [
        (math.pi, 3.1415),             # +pi would round to 3.1416, past pi
        (-math.pi, 3.1415),            # -pi is the same heading, and outside (-pi, pi]
        (-3.14159, 3.1415),            # rounds to -3.1416, below -pi
        (-3.14149, -3.1415),           # rounds inside the range: kept
        (1.23456, 1.2346),             # ordinary rounding
    ],
)
def test_yaw_stays_inside_range_after_rounding(yaw: float, wire: float) -> None:
    doc = json.loads(encode(with_person(yaw=yaw)))
    assert doc["people"][0]["yaw"] == wire


@pytest.mark.parametrize(
    "poses, field",
    [
        (PoseArray("lab/1", 0, 0), "site"),                                      # would break the Zenoh key
        (PoseArray("lab", -1, 0), "seq"),                                        # negative sequence
        (PoseArray("lab", 1.5, 0), "seq"),                                       # not an integer
        (PoseArray("lab", 0, 0, estimator=""), "estimator"),                     # empty estimator name
        (PoseArray("lab", 0, 0, cameras_alive=("a", "a")), "cameras_alive[1]"),  # repeated camera
        (with_person(x=float("nan")), "people[0].x"),                            # NaN position
        (with_person(yaw=4.0), "people[0].yaw"),                                 # unwrapped yaw
        (with_person(confidence=1.5), "people[0].confidence"),                   # confidence above 1
        (with_person(cov=np.diag([1.0, -1.0, 1.0])), "people[0].cov[3]"),        # negative variance
        (with_person(cov=np.diag([1.0, np.inf, 1.0])), "people[0].cov[3]"),      # infinite variance
        (with_person(views=1), "people[0].views"),                               # 2 cameras, 1 view
        (with_person(id=None), "people[0].id"),                                  # no id
        (with_person(x=10**400), "people[0].x"),                                 # an integer beyond float64
        (with_person(cameras="cam-1"), "people[0].cameras"),                     # a string, not a tuple of ids
    ],
)
def test_encode_refuses_invalid_poses(poses: PoseArray, field: str) -> None:
    with pytest.raises(ValueError, match=re.escape(field)) as info:
        encode(poses)
    assert not isinstance(info.value, PoseDecodeError)


def test_encode_refuses_asymmetric_or_misshapen_cov() -> None:
    cov = np.eye(3)
    cov[0, 1] = 0.5
    with pytest.raises(ValueError, match=r"people\[0\]\.cov must be symmetric"):
        encode(with_person(cov=cov))
    with pytest.raises(ValueError, match=r"people\[0\]\.cov must have shape \(3, 3\)"):
        encode(with_person(cov=np.eye(2)))


def test_encode_accepts_float_noise_in_cov_and_numpy_scalars() -> None:
    cov = make_cov(np.random.default_rng(3))
    cov[0, 1] += 1e-17  # what a Kalman update leaves behind
    poses = PoseArray("lab", np.int64(7), np.uint64(10**18), (with_person(
        cov=cov, x=np.float32(1.5), id=np.int32(4), views=np.uint8(2)).people[0],), np.int64(5))
    back = decode(encode(poses))
    assert (back.seq, back.stamp_ns, back.latency_ns, back.people[0].id, back.people[0].x) == (7, 10**18, 5, 4, 1.5)


def test_zenoh_encoding_matches_constant() -> None:
    pytest.importorskip("zenoh")
    assert str(zenoh_encoding()) == ENCODING == "application/json;superbody.people/2"


def test_version_1_still_decodes_with_the_top_level_estimator() -> None:
    """Subscribers upgraded first still read a version 1 host: its people carry no estimator."""
    doc = json.loads(encode(PoseArray(site="lab", seq=1, stamp_ns=5, estimator="analytic", people=(make_person(np.random.default_rng(0), 3),))))
    doc["version"] = 1
    for p in doc["people"]:
        del p["estimator"]
    poses = decode(json.dumps(doc).encode())
    assert [p.estimator for p in poses.people] == ["analytic"]


def test_docs_example_payload_decodes() -> None:
    """The example in docs/pose-schema.md is a valid message."""
    block = re.search(r"```json\n(.*?)\n```", DOCS.read_text(encoding="utf-8"), re.S)
    assert block, "docs/pose-schema.md has no ```json example"
    poses = decode(block.group(1).encode(), expected_site="lab")
    assert len(poses.people) >= 1


# --- property tests ------------------------------------------------------------------------

_NAMES = st.one_of(st.sampled_from(["1", "cam-1", "kitchen_east", "A" * 64]), st.from_regex(r"[A-Za-z0-9_-]{1,64}", fullmatch=True))


def _f(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False)


@st.composite
def person_poses(draw: st.DrawFn, pid: int) -> PersonPose:
    cameras = tuple(draw(st.lists(_NAMES, max_size=4, unique=True)))
    diag = draw(st.lists(_f(0, 1e6), min_size=3, max_size=3))
    off = draw(st.lists(_f(-1e6, 1e6), min_size=3, max_size=3))
    cov = np.diag(diag)
    cov[0, 1] = cov[1, 0] = off[0]
    cov[0, 2] = cov[2, 0] = off[1]
    cov[1, 2] = cov[2, 1] = off[2]
    return PersonPose(
        id=pid, x=draw(_f(-1000, 1000)), y=draw(_f(-1000, 1000)), yaw=draw(_f(-math.pi, math.pi)),
        vx=draw(_f(-100, 100)), vy=draw(_f(-100, 100)), yaw_rate=draw(_f(-100, 100)), cov=cov,
        confidence=draw(_f(0, 1)), cameras=cameras, stamp_ns=draw(st.integers(0, 2**63 - 1)),
        views=draw(st.integers(len(cameras), 255)) if cameras else 0,
        estimator=draw(st.sampled_from(["hybrid", "onnx", "analytic", "x" * 128])),
    )


@st.composite
def pose_arrays(draw: st.DrawFn) -> PoseArray:
    ids = draw(st.lists(st.integers(0, 2**53 - 1), max_size=4, unique=True))
    return PoseArray(
        site=draw(_NAMES), seq=draw(st.integers(0, 2**63 - 1)), stamp_ns=draw(st.integers(0, 2**63 - 1)),
        people=tuple(draw(person_poses(i)) for i in ids), latency_ns=draw(st.integers(0, 2**63 - 1)),
        cameras_alive=tuple(draw(st.lists(_NAMES, max_size=4, unique=True))),
        estimator=draw(st.text(st.characters(min_codepoint=32, max_codepoint=126), min_size=1, max_size=128)),
    )


@settings(max_examples=300, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(pose_arrays())
def test_valid_pose_arrays_round_trip(poses: PoseArray) -> None:
    back = decode(encode(poses), expected_site=poses.site)
    assert_close(poses, back)
    assert decode(encode(back)) == back


_BASE_PAYLOADS: tuple[bytes, ...] = (encode(make_poses(0)), encode(make_poses(1, seed=3)), encode(make_poses(3, seed=4)))


@settings(max_examples=4000, deadline=None, database=None)
@given(
    st.one_of(
        st.binary(max_size=300),                                       # noise
        st.text(max_size=200).map(str.encode),                         # any UTF-8 text
        st.tuples(st.sampled_from(_BASE_PAYLOADS), st.integers(0, 10**6), st.integers(0, 255)).map(
            lambda t: t[0][: t[1] % (len(t[0]) + 1)] + bytes([t[2]]) + t[0][t[1] % (len(t[0]) + 1) + 1 :]
        ),                                                             # one byte of a valid message replaced
        st.tuples(st.sampled_from(_BASE_PAYLOADS), st.integers(0, 10**6)).map(
            lambda t: t[0][: t[1] % (len(t[0]) + 1)]
        ),                                                             # a valid message cut short
    )
)
def test_arbitrary_bytes_decode_or_reject(payload: bytes) -> None:
    """Decode returns a PoseArray or raises PoseDecodeError with a known reason, nothing else."""
    try:
        poses = decode(payload)
    except PoseDecodeError as e:
        assert e.reason in REASONS and e.field
        return
    assert_close(poses, decode(encode(poses)))
