"""Tests of the Observation wire codec (edge/messages/wire.py): a table of bad payloads, round trips,
sizes, and property tests that throw arbitrary and mutated payloads at the decoder."""

from __future__ import annotations

import json
import pickle
import re
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from superbody.edge.body import NUM_KEYPOINTS
from superbody.edge.colour import HIST_BINS
from superbody.edge.messages.observation import Observation, PersonView, empty_histogram, empty_keypoints
from superbody.edge.messages.wire import (
    ENCODING,
    MAX_PAYLOAD_BYTES,
    MAX_PEOPLE,
    REASONS,
    SCHEMA,
    VERSION,
    DecodeError,
    decode,
    encode,
    zenoh_encoding,
)
from tests.conftest import ROOT

DOCS = ROOT / "docs" / "observation-schema.md"
W, H = 640, 480


# --- fixtures: valid observations ----------------------------------------------------------


def make_person(rng: np.random.Generator, *, missing: int = 0, with_3d: bool = True, dense: bool = True) -> PersonView:
    """A plausible person; ``missing`` joints are dropped at random."""
    kp = np.stack([rng.uniform(0, W, NUM_KEYPOINTS), rng.uniform(0, H, NUM_KEYPOINTS), rng.uniform(0.3, 1.0, NUM_KEYPOINTS)], axis=1)
    gone = rng.choice(NUM_KEYPOINTS, size=missing, replace=False)
    kp[gone] = np.nan
    hist = rng.random(HIST_BINS) if dense else np.where(rng.random(HIST_BINS) < 0.1, rng.random(HIST_BINS), 0.0)
    hist = hist / hist.sum() if hist.sum() > 0 else hist
    p3 = None
    if with_3d:
        p3 = rng.uniform(-5.0, 5.0, (NUM_KEYPOINTS, 3))
        p3[gone] = np.nan
    x0, x1 = sorted(rng.uniform(0, W, 2))
    y0, y1 = sorted(rng.uniform(0, H, 2))
    return PersonView(
        keypoints=kp.astype(np.float32),
        bbox=np.array([x0, y0, x1, y1], dtype=np.float32),
        histogram=hist.astype(np.float32),
        points3d=None if p3 is None else p3.astype(np.float32),
    )


def make_obs(n: int = 1, seed: int = 0, **person_kw: Any) -> Observation:
    rng = np.random.default_rng(seed)
    people = tuple(make_person(rng, **person_kw) for _ in range(n))
    return Observation("lab", "cam-1", 42, 1_718_000_000_123_456_789, W, H, people)


def valid_doc() -> dict:
    """A valid message as a JSON document, for the bad-input table to break."""
    return json.loads(encode(make_obs(2, seed=1, missing=3)))


def dumps(doc: Any) -> bytes:
    return json.dumps(doc, allow_nan=True).encode()


def assert_close(a: Observation, b: Observation) -> None:
    """Equal up to the documented rounding (and the decoder's histogram renormalisation)."""
    assert (a.site, a.camera, a.seq, a.stamp_ns, a.width, a.height) == (b.site, b.camera, b.seq, b.stamp_ns, b.width, b.height)
    assert len(a.people) == len(b.people)
    for p, q in zip(a.people, b.people):
        for arr in (q.keypoints, q.bbox, q.histogram) + (() if q.points3d is None else (q.points3d,)):
            assert arr.dtype == np.float32
        assert q.keypoints.shape == (NUM_KEYPOINTS, 3) and q.histogram.shape == HIST_BINS
        np.testing.assert_array_equal(np.isnan(p.keypoints), np.isnan(q.keypoints))
        # 0.005 px rounding + float32 resolution (0.002 px at 32768 px).
        np.testing.assert_allclose(q.keypoints[:, :2], p.keypoints[:, :2], rtol=0, atol=0.01)
        np.testing.assert_allclose(q.keypoints[:, 2], p.keypoints[:, 2], rtol=0, atol=1e-5 + 1e-7)
        np.testing.assert_allclose(q.bbox, p.bbox, rtol=0, atol=0.01)
        # 5e-6 rounding per value; renormalising the rounded sum moves a value by <= 6.4e-4 of itself.
        np.testing.assert_allclose(q.histogram, p.histogram, rtol=1e-3, atol=1e-5)
        assert (p.points3d is None) == (q.points3d is None)
        if p.points3d is not None:
            np.testing.assert_array_equal(np.isnan(p.points3d), np.isnan(q.points3d))
            np.testing.assert_allclose(q.points3d, p.points3d, rtol=0, atol=1e-4)


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


def kp0(doc: dict) -> list:
    """The first present keypoint row of the first person."""
    return next(r for r in doc["people"][0]["keypoints"] if r is not None)


def kp0_index(doc: dict) -> int:
    return next(j for j, r in enumerate(doc["people"][0]["keypoints"]) if r is not None)


def with_text(fn: Callable[[dict], Any], old: bytes, new: bytes) -> Callable[[], bytes]:
    """A payload made by ``fn`` and then a textual replacement (for what json.dumps cannot write)."""
    return lambda: edit(fn)().replace(old, new, 1)


KP = f"people[0].keypoints[{kp0_index(valid_doc())}]"  # the first present joint of person 0

BAD_CASES = [
    # whole payload
    pytest.param(raw(b" " * (MAX_PAYLOAD_BYTES + 1)), {}, "$", "oversize", id="oversize"),
    pytest.param(raw(b'{"schema": "\xff\xfe"}'), {}, "$", "not_utf8", id="not-utf8"),
    pytest.param(raw('{"schema":"superbody.observation"}'.encode("utf-16")), {}, "$", "not_utf8", id="utf16-not-utf8"),
    pytest.param(raw(b'{"schema": "superbody.observation", "version": '), {}, "$", "not_json", id="truncated"),
    pytest.param(raw(b""), {}, "$", "not_json", id="empty-payload"),
    pytest.param(raw(b"[" * 100_000), {}, "$", "not_json", id="nested-too-deep"),
    pytest.param(raw(b"1" * 5000), {}, "$", "not_json", id="int-beyond-python-digit-limit"),
    pytest.param(raw(b"[1, 2]"), {}, "$", "type", id="json-array-at-top"),
    pytest.param(raw(b'"observation"'), {}, "$", "type", id="json-string-at-top"),
    pytest.param(raw(b'{"schema": "superbody.observation", "schema": "x"}'), {}, "schema", "duplicate_key", id="duplicate-top-key"),
    # non-finite numbers
    pytest.param(edit(lambda d: kp0(d).__setitem__(0, float("nan"))), {}, "$", "non_finite", id="nan-literal"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(1, float("-inf"))), {}, "$", "non_finite", id="infinity-literal"),
    pytest.param(with_text(lambda d: d["people"][0]["bbox"].__setitem__(1, 12345.678), b"12345.678", b"1e400"), {}, "people[0].bbox[1]", "non_finite", id="1e400-overflows"),
    pytest.param(edit(lambda d: d["people"][0]["bbox"].__setitem__(0, 10**400)), {}, "people[0].bbox[0]", "non_finite", id="int-beyond-float64"),
    # schema and version
    pytest.param(edit(lambda d: d.__setitem__("schema", "superbody.pose")), {}, "schema", "schema", id="wrong-schema"),
    pytest.param(edit(lambda d: d.pop("schema")), {}, "schema", "missing", id="no-schema"),
    pytest.param(edit(lambda d: d.update(version=2, novelty=1)), {}, "version", "version", id="version-2-before-unknown-fields"),
    pytest.param(edit(lambda d: d.__setitem__("version", "1")), {}, "version", "type", id="version-string"),
    pytest.param(edit(lambda d: d.__setitem__("version", True)), {}, "version", "type", id="version-bool"),
    # top-level fields
    pytest.param(edit(lambda d: d.pop("camera")), {}, "camera", "missing", id="missing-camera"),
    pytest.param(edit(lambda d: d.__setitem__("extra", 1)), {}, "extra", "unknown_field", id="unknown-top-field"),
    pytest.param(edit(lambda d: d.__setitem__("site", "lab 2")), {}, "site", "format", id="site-with-space"),
    pytest.param(edit(lambda d: d.__setitem__("site", "lab\n")), {}, "site", "format", id="site-trailing-newline"),
    pytest.param(edit(lambda d: d.__setitem__("camera", "")), {}, "camera", "format", id="camera-empty"),
    pytest.param(edit(lambda d: d.__setitem__("camera", 1)), {}, "camera", "type", id="camera-number"),
    pytest.param(edit(lambda d: None), {"expected_site": "kitchen"}, "site", "site", id="site-mismatch"),
    pytest.param(edit(lambda d: d.__setitem__("seq", -1)), {}, "seq", "range", id="seq-negative"),
    pytest.param(edit(lambda d: d.__setitem__("seq", 2**63)), {}, "seq", "range", id="seq-2^63"),
    pytest.param(edit(lambda d: d.__setitem__("seq", 1.0)), {}, "seq", "type", id="seq-float"),
    pytest.param(edit(lambda d: d.__setitem__("seq", False)), {}, "seq", "type", id="seq-bool"),
    pytest.param(edit(lambda d: d.__setitem__("stamp_ns", "1718000000")), {}, "stamp_ns", "type", id="stamp-string"),
    pytest.param(edit(lambda d: d.__setitem__("image", [8, 480])), {}, "image[0]", "range", id="image-too-narrow"),
    pytest.param(edit(lambda d: d.__setitem__("image", [640, 16385])), {}, "image[1]", "range", id="image-too-tall"),
    pytest.param(edit(lambda d: d.__setitem__("image", [640])), {}, "image", "length", id="image-one-entry"),
    pytest.param(edit(lambda d: d.__setitem__("people", {})), {}, "people", "type", id="people-object"),
    pytest.param(edit(lambda d: d.__setitem__("people", d["people"][:1] * (MAX_PEOPLE + 1))), {}, "people", "length", id="too-many-people"),
    pytest.param(edit(lambda d: d["people"].__setitem__(1, [])), {}, "people[1]", "type", id="person-array"),
    # person fields
    pytest.param(edit(lambda d: d["people"][1].__setitem__("mood", "happy")), {}, "people[1].mood", "unknown_field", id="unknown-person-field"),
    pytest.param(edit(lambda d: d["people"][0].pop("bbox")), {}, "people[0].bbox", "missing", id="missing-bbox"),
    pytest.param(edit(lambda d: d["people"][0]["keypoints"].pop()), {}, "people[0].keypoints", "length", id="16-keypoints"),
    pytest.param(edit(lambda d: d["people"][0]["keypoints"].append(None)), {}, "people[0].keypoints", "length", id="18-keypoints"),
    pytest.param(edit(lambda d: kp0(d).pop()), {}, KP, "length", id="keypoint-2-numbers"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(2, True)), {}, KP + "[2]", "type", id="bool-as-score"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(0, "12.5")), {}, KP + "[0]", "type", id="string-as-number"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(2, 0)), {}, KP + "[2]", "range", id="score-0"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(2, 1.5)), {}, KP + "[2]", "range", id="score-1.5"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(2, 1e-300)), {}, KP + "[2]", "range", id="score-underflows-float32"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(0, 2 * W + 0.01)), {}, KP + "[0]", "range", id="u-beyond-2-widths"),
    pytest.param(edit(lambda d: kp0(d).__setitem__(1, -H - 1)), {}, KP + "[1]", "range", id="v-beyond-minus-height"),
    pytest.param(edit(lambda d: d["people"][0]["bbox"].__setitem__(2, -1)), {}, "people[0].bbox[2]", "range", id="bbox-x1-below-x0"),
    pytest.param(edit(lambda d: d["people"][0]["bbox"].__setitem__(3, 3 * H)), {}, "people[0].bbox[3]", "range", id="bbox-y1-out-of-range"),
    pytest.param(edit(lambda d: d["people"][0].__setitem__("bbox", [1, 2, 3])), {}, "people[0].bbox", "length", id="bbox-3-numbers"),
    # histogram
    pytest.param(edit(lambda d: d["people"][0]["histogram"].__setitem__("bins", [8, 8])), {}, "people[0].histogram.bins", "range", id="histogram-bins-8x8"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"].__setitem__("bins", "16x8")), {}, "people[0].histogram.bins", "type", id="histogram-bins-string"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"]["values"].pop()), {}, "people[0].histogram.values", "length", id="histogram-127-values"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"].__setitem__("values", [0.5 / 128] * 128)), {}, "people[0].histogram.values", "range", id="histogram-sum-0.5"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"]["values"].__setitem__(5, -0.001)), {}, "people[0].histogram.values[5]", "range", id="histogram-negative-value"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"]["values"].__setitem__(7, None)), {}, "people[0].histogram.values[7]", "type", id="histogram-null-value"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"].pop("bins")), {}, "people[0].histogram.bins", "missing", id="histogram-no-bins"),
    pytest.param(edit(lambda d: d["people"][0]["histogram"].__setitem__("norm", "l1")), {}, "people[0].histogram.norm", "unknown_field", id="histogram-unknown-field"),
    # points3d
    pytest.param(edit(lambda d: d["people"][0]["points3d"][kp0_index(d)].__setitem__(2, 100.5)), {}, KP.replace("keypoints", "points3d") + "[2]", "range", id="points3d-beyond-100m"),
    pytest.param(edit(lambda d: d["people"][0].__setitem__("points3d", "none")), {}, "people[0].points3d", "type", id="points3d-string"),
    pytest.param(edit(lambda d: d["people"][0].__setitem__("points3d", [None] * 16)), {}, "people[0].points3d", "length", id="points3d-16-entries"),
]


@pytest.mark.parametrize("make_payload, kwargs, field, reason", BAD_CASES)
def test_bad_payload_names_field_and_reason(make_payload: Callable[[], bytes], kwargs: dict, field: str, reason: str) -> None:
    with pytest.raises(DecodeError) as info:
        decode(make_payload(), **kwargs)
    assert (info.value.field, info.value.reason) == (field, reason), str(info.value)
    assert info.value.reason in REASONS
    assert str(info.value).startswith(f"{field}: ")


def test_error_message_gives_allowed_range() -> None:
    doc = valid_doc()
    kp0(doc)[0] = 5000
    with pytest.raises(DecodeError, match=r"must be in \[-640, 1280\] \(u, pixels\), got 5000"):
        decode(dumps(doc))


def test_payload_of_wrong_python_type_is_a_decode_error() -> None:
    with pytest.raises(DecodeError) as info:
        decode("{}")  # type: ignore[arg-type]
    assert (info.value.field, info.value.reason) == ("$", "type")


def test_decode_error_pickles_with_field_and_reason() -> None:
    e = pickle.loads(pickle.dumps(DecodeError("people[0].bbox[2]", "range", "must be >= 3")))
    assert (e.field, e.reason, str(e)) == ("people[0].bbox[2]", "range", "people[0].bbox[2]: must be >= 3")


# --- valid payloads ------------------------------------------------------------------------


def test_empty_people_list_is_valid() -> None:
    obs = Observation("lab", "cam-1", 0, 0, W, H, ())
    assert decode(encode(obs)) == obs


VALID_EDITS = [
    pytest.param(lambda d: None, id="as-encoded"),
    pytest.param(lambda d: d["people"][0].pop("points3d"), id="points3d-absent"),
    pytest.param(lambda d: d["people"][0].__setitem__("points3d", None), id="points3d-null"),
    pytest.param(lambda d: d["people"][0].__setitem__("keypoints", [None] * 17), id="no-joint-seen"),
    pytest.param(lambda d: kp0(d).__setitem__(0, 100), id="integer-pixel"),
    pytest.param(lambda d: kp0(d).__setitem__(slice(0, 2), [-W, 2 * H]), id="pixels-on-bounds"),
    pytest.param(lambda d: kp0(d).__setitem__(2, 1), id="score-1"),
    pytest.param(lambda d: d["people"][0].__setitem__("bbox", [5, 5, 5, 5]), id="zero-area-bbox"),
    pytest.param(lambda d: d["people"][0]["histogram"].__setitem__("values", [0] * 128), id="empty-histogram"),
    pytest.param(lambda d: d["people"][0]["histogram"].__setitem__("values", [1.009 / 128] * 128), id="histogram-sum-1.009"),
    pytest.param(lambda d: d.__setitem__("seq", 2**63 - 1), id="seq-max"),
    pytest.param(lambda d: d.update(image=[16, 16384], people=[]), id="image-size-limits"),  # nobody: their pixels would not fit
]


@pytest.mark.parametrize("fn", VALID_EDITS)
def test_valid_edits_decode(fn: Callable[[dict], Any]) -> None:
    doc = valid_doc()
    fn(doc)
    obs = decode(dumps(doc))
    for p in obs.people:
        total = float(p.histogram.sum())
        assert total == 0.0 or abs(total - 1.0) < 1e-6  # renormalised
    assert_close(obs, decode(encode(obs)))


@pytest.mark.parametrize("wrap", [bytes, bytearray, memoryview], ids=["bytes", "bytearray", "memoryview"])
def test_decode_accepts_bytes_like(wrap: type) -> None:
    obs = make_obs(2)
    assert_close(obs, decode(wrap(encode(obs)), expected_site="lab"))


def test_decode_accepts_zenoh_zbytes() -> None:
    zenoh = pytest.importorskip("zenoh")
    obs = make_obs(1)
    assert_close(obs, decode(zenoh.ZBytes(encode(obs))))


# --- round trip, size, encoder checks ------------------------------------------------------


@pytest.mark.parametrize(
    "n, kw",
    [
        (0, {}),                                            # nobody in view
        (1, {}),                                            # one full person with 3D
        (3, {"missing": 5, "with_3d": False}),              # partial views, RGB only
        (2, {"missing": 17}),                               # detections with no joint kept
        (4, {"dense": False}),                              # sparse histograms
    ],
)
def test_round_trip(n: int, kw: dict) -> None:
    obs = make_obs(n, seed=n, **kw)
    back = decode(encode(obs))
    assert_close(obs, back)
    assert decode(encode(back)) == back  # already-rounded values survive unchanged


def test_one_full_person_is_well_under_4_kb() -> None:
    one = encode(make_obs(1, missing=0, with_3d=True, dense=True))
    none = encode(make_obs(0))
    person_bytes = len(one) - len(none)
    assert person_bytes < 3000, person_bytes
    assert len(one) < 4096


def test_max_people_fit_in_max_payload() -> None:
    assert len(encode(make_obs(MAX_PEOPLE))) < MAX_PAYLOAD_BYTES


def test_encoding_is_compact_and_canonical() -> None:
    text = encode(make_obs(1)).decode()
    assert ", " not in text and ": " not in text
    doc = json.loads(text)
    assert list(doc) == ["schema", "version", "site", "camera", "seq", "stamp_ns", "image", "people"]
    assert (doc["schema"], doc["version"]) == (SCHEMA, VERSION)
    assert all(len(str(v)) <= 7 for v in doc["people"][0]["histogram"]["values"])  # 1e-5 rounding


@pytest.mark.parametrize(
    "change, field",
    [
        ({"site": "lab/1"}, "site"),                                  # would break the Zenoh key
        ({"width": 8}, "image[0]"),                                   # image too small
        ({"seq": -1}, "seq"),                                         # negative sequence
        ({"seq": 1.5}, "seq"),                                        # not an integer
    ],
)
def test_encode_refuses_invalid_observation(change: dict, field: str) -> None:
    fields = {**make_obs(0).__dict__, **change}
    with pytest.raises(ValueError, match=re.escape(field)) as info:
        encode(Observation(**fields))
    assert not isinstance(info.value, DecodeError)


@pytest.mark.parametrize(
    "break_person, field",
    [
        (lambda kp, h: kp.__setitem__((0, 2), 1.5), "people[0].keypoints[0][2]"),  # score above 1
        (lambda kp, h: kp.__setitem__((3, 2), np.nan), "people[0].keypoints[3][2]"),  # NaN score, joint present
        (lambda kp, h: h.__setitem__((0, 0), 0.5), "people[0].histogram.values"),  # not normalised
    ],
)
def test_encode_refuses_invalid_person(break_person: Callable, field: str) -> None:
    p = make_obs(1).people[0]
    kp, hist = p.keypoints.copy(), p.histogram.copy()
    break_person(kp, hist)
    obs = Observation("lab", "cam-1", 0, 0, W, H, (PersonView(kp, p.bbox, hist, p.points3d),))
    with pytest.raises(ValueError, match=re.escape(field)):
        encode(obs)


def test_encode_refuses_wrong_shapes() -> None:
    obs = Observation("lab", "cam-1", 0, 0, W, H, (PersonView(empty_keypoints()[:16], np.zeros(4, np.float32), empty_histogram()),))
    with pytest.raises(ValueError, match=r"people\[0\]\.keypoints must have shape \(17, 3\)"):
        encode(obs)


def test_encode_accepts_numpy_integers_and_tiny_scores() -> None:
    p = make_obs(1).people[0]
    kp = p.keypoints.copy()
    kp[0, 2] = 1e-7  # rounds to 0 at 1e-5 resolution: sent as 1e-5, still a detection
    obs = Observation("lab", "cam-1", np.int64(7), np.uint64(10**18), np.int32(W), H, (PersonView(kp, p.bbox, p.histogram),))
    back = decode(encode(obs))
    assert (back.seq, back.stamp_ns, back.width) == (7, 10**18, W)
    assert back.people[0].keypoints[0, 2] == np.float32(1e-5)


def test_zenoh_encoding_matches_constant() -> None:
    pytest.importorskip("zenoh")
    assert str(zenoh_encoding()) == ENCODING == "application/json;superbody.observation/1"


def test_docs_example_payload_decodes() -> None:
    """The example in docs/observation-schema.md is a valid message."""
    block = re.search(r"```json\n(.*?)\n```", DOCS.read_text(encoding="utf-8"), re.S)
    assert block, "docs/observation-schema.md has no ```json example"
    obs = decode(block.group(1).encode(), expected_site="lab")
    assert obs.camera and len(obs.people) >= 1


# --- property tests ------------------------------------------------------------------------

_BASE_PAYLOADS: tuple[bytes, ...] = (
    encode(make_obs(0)),
    encode(make_obs(1, seed=3)),
    encode(make_obs(2, seed=4, missing=6, with_3d=False, dense=False)),
)


def _decodes_or_rejects(payload: bytes) -> Observation | None:
    """Decode must return an Observation or raise DecodeError with a known reason, nothing else."""
    try:
        return decode(payload)
    except DecodeError as e:
        assert e.reason in REASONS and e.field
        return None


@settings(max_examples=10_000, deadline=None, database=None)
@given(
    st.one_of(
        st.binary(max_size=300),                                       # noise
        st.text(max_size=200).map(str.encode),                         # any UTF-8 text
        st.tuples(st.sampled_from(_BASE_PAYLOADS), st.integers(0, 10**6), st.integers(0, 255)).map(
            lambda t: t[0][: t[1] % (len(t[0]) + 1)] + bytes([t[2]]) + t[0][t[1] % (len(t[0]) + 1) + 1 :]
        ),                                                             # one byte of a valid message replaced
    )
)
def test_arbitrary_bytes_decode_or_reject(payload: bytes) -> None:
    obs = _decodes_or_rejects(payload)
    if obs is not None:
        assert_close(obs, decode(encode(obs)))


def _f32(lo: float, hi: float, **kw: Any) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, width=32, allow_nan=False, **kw)


@st.composite
def person_views(draw: st.DrawFn, width: int, height: int) -> PersonView:
    present = np.array(draw(st.lists(st.booleans(), min_size=NUM_KEYPOINTS, max_size=NUM_KEYPOINTS)))
    kp = np.empty((NUM_KEYPOINTS, 3), dtype=np.float32)
    kp[:, 0] = draw(hnp.arrays(np.float32, NUM_KEYPOINTS, elements=_f32(-width, 2 * width)))
    kp[:, 1] = draw(hnp.arrays(np.float32, NUM_KEYPOINTS, elements=_f32(-height, 2 * height)))
    kp[:, 2] = draw(hnp.arrays(np.float32, NUM_KEYPOINTS, elements=_f32(0, 1, exclude_min=True)))
    kp[~present] = np.nan
    xs = sorted(draw(st.lists(_f32(-width, 2 * width), min_size=2, max_size=2)))
    ys = sorted(draw(st.lists(_f32(-height, 2 * height), min_size=2, max_size=2)))
    raw_hist = draw(hnp.arrays(np.float32, HIST_BINS, elements=_f32(0, 1))).astype(np.float64)
    hist = raw_hist / raw_hist.sum() if raw_hist.sum() > 0 else raw_hist
    p3 = None
    if draw(st.booleans()):
        p3 = draw(hnp.arrays(np.float32, (NUM_KEYPOINTS, 3), elements=_f32(-100, 100)))
        p3[~np.array(draw(st.lists(st.booleans(), min_size=NUM_KEYPOINTS, max_size=NUM_KEYPOINTS)))] = np.nan
    return PersonView(kp, np.array([xs[0], ys[0], xs[1], ys[1]], np.float32), hist.astype(np.float32), p3)


@st.composite
def observations(draw: st.DrawFn) -> Observation:
    name = st.from_regex(r"[A-Za-z0-9_-]{1,64}", fullmatch=True)
    width, height = draw(st.integers(16, 16384)), draw(st.integers(16, 16384))
    people = draw(st.lists(person_views(width, height), max_size=3))
    return Observation(
        site=draw(name), camera=draw(name), seq=draw(st.integers(0, 2**63 - 1)), stamp_ns=draw(st.integers(0, 2**63 - 1)),
        width=width, height=height, people=tuple(people),
    )


@settings(max_examples=200, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(observations())
def test_valid_observations_round_trip(obs: Observation) -> None:
    back = decode(encode(obs), expected_site=obs.site)
    assert_close(obs, back)
    assert_close(back, decode(encode(back)))


# Values that stress the decoder: wrong types, non-finite, huge, tiny, and boundary numbers.
_JSON_LEAVES = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=6),
    st.sampled_from([10**400, -(2**63), 2**63, 1e308, 5e-324, -0.0, 0, 1, 16, 16384, 17, 128, "", "lab"]),
)
# One level of nesting is enough to put an array or object where a scalar goes and vice versa.
_JSON_VALUES = st.one_of(
    _JSON_LEAVES, st.lists(_JSON_LEAVES, max_size=4), st.dictionaries(st.sampled_from(["u", "bins", ""]), _JSON_LEAVES, max_size=2)
)

_BASE_TEXTS = tuple(p.decode() for p in _BASE_PAYLOADS)


def _nodes(doc: Any, path: tuple = ()) -> list[tuple]:
    """Paths to every value in a document (the root is ())."""
    out = [path]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _nodes(v, path + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _nodes(v, path + (i,))
    return out


def _by_depth(doc: Any) -> tuple[tuple[tuple, ...], ...]:
    """The paths of ``doc`` grouped by depth, so that top-level fields are picked as often as
    histogram values (of which there are hundreds)."""
    paths = _nodes(doc)
    return tuple(tuple(p for p in paths if len(p) == d) for d in range(max(map(len, paths)) + 1))


_BASE_PATHS = tuple(_by_depth(json.loads(t)) for t in _BASE_TEXTS)


def _has(parent: Any, key: Any) -> bool:
    if isinstance(parent, dict):
        return key in parent
    return isinstance(parent, list) and isinstance(key, int) and key < len(parent)


def _mutate(doc: Any, path: tuple, draw: st.DrawFn) -> Any:
    """Apply one random edit at ``path``; returns the (possibly new) root."""
    op = draw(st.sampled_from(["replace", "replace", "number", "delete", "add"]))
    if not path:
        return draw(_JSON_VALUES) if op == "replace" else doc
    parent = doc
    for k in path[:-1]:
        if not _has(parent, k):
            return doc  # an earlier edit removed this path
        parent = parent[k]
    key = path[-1]
    if not _has(parent, key):
        return doc
    old = parent[key]
    if op == "replace":
        parent[key] = draw(_JSON_VALUES)
    elif op == "number":  # a plausible-looking number: near the old value, a boundary, or non-finite
        base = float(old) if type(old) is float or (type(old) is int and abs(old) < 2**1000) else 1.0
        parent[key] = draw(st.one_of(
            st.floats(), st.integers(-(2**64), 2**64),
            st.sampled_from([0, -1, 1, 1e-300, float("inf"), float("nan")]),
            st.floats(-1e3, 1e3).map(lambda d: base + d),
        ))
    elif op == "delete":
        del parent[key]
    elif isinstance(parent, dict):  # add a field beside this one
        parent[draw(st.sampled_from(["extra", "points3d", "bbox", "version", "x"]))] = draw(_JSON_VALUES)
    else:  # add an entry before this one
        parent.insert(key, draw(_JSON_VALUES))
    return doc


@st.composite
def mutated_payloads(draw: st.DrawFn) -> bytes:
    """A valid message with one or two random edits, sometimes cut short."""
    b = draw(st.integers(0, len(_BASE_TEXTS) - 1))
    doc = json.loads(_BASE_TEXTS[b])  # a fresh copy
    by_depth = _BASE_PATHS[b]
    for _ in range(draw(st.integers(1, 2))):
        paths = by_depth[draw(st.integers(0, len(by_depth) - 1))]
        doc = _mutate(doc, paths[draw(st.integers(0, len(paths) - 1))], draw)
    payload = json.dumps(doc, allow_nan=True).encode()
    if draw(st.integers(0, 9)) == 0:
        payload = payload[: draw(st.integers(0, len(payload)))]
    return payload


@settings(max_examples=10_000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_payloads())
def test_mutated_messages_decode_or_reject(payload: bytes) -> None:
    obs = _decodes_or_rejects(payload)
    if obs is not None:  # whatever passes re-validates: it encodes and round-trips
        assert_close(obs, decode(encode(obs)))

