"""The typed codecs agree with the rule-by-rule validators they stand in front of.

``edge.messages.wire`` and ``host.messages.pose`` decode a payload with msgspec structs and a few vectorised
checks (``_typed_decode``) and send whatever that path refuses to the validator that names the
violation (``_observation``, ``_pose_array``). These property tests hold the two to each other:
the typed path never accepts what the validator rejects, returns exactly what the validator
returns, and refuses nothing valid that it may take (ASCII, no escapes). The encoders' typed
paths (``_typed_encode``) are held to the checked encoders the same way, on in-memory values
with one value broken.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from superbody.edge.messages import wire
from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.messages.payload import DecodeError, parse_json, typed_input
from superbody.host.messages import pose as pose_msg
from superbody.host.messages.pose import PersonPose, PoseArray
from tests.edge.messages import test_wire as tw
from tests.host.messages import test_pose as tp

# --- decoders ------------------------------------------------------------------------------


def _reference(decode_doc, payload: bytes, max_bytes: int) -> Any:
    try:
        return decode_doc(parse_json(payload, max_bytes), None)
    except DecodeError:
        return None


def _agree(payload: bytes, codec) -> None:
    if codec is wire:
        ref = _reference(wire._observation, payload, wire.MAX_PAYLOAD_BYTES)
    else:
        ref = _reference(pose_msg._pose_array, payload, pose_msg.MAX_PAYLOAD_BYTES)
    data = typed_input(payload, codec.MAX_PAYLOAD_BYTES)
    if data is None:
        return  # not the typed path's: the validator decides alone
    fast = codec._typed_decode(data, None)
    if fast is None:
        assert ref is None, f"the typed path refused a valid payload: {payload[:300]!r}"
    else:
        assert ref is not None, f"the typed path accepted an invalid payload: {payload[:300]!r}"
        assert fast == ref


def _byte_replaced(bases: tuple[bytes, ...]) -> st.SearchStrategy[bytes]:
    return st.tuples(st.sampled_from(bases), st.integers(0, 10**6), st.integers(0, 255)).map(
        lambda t: t[0][: t[1] % (len(t[0]) + 1)] + bytes([t[2]]) + t[0][t[1] % (len(t[0]) + 1) + 1 :])


@st.composite
def _mutated(draw: st.DrawFn, texts: tuple[str, ...]) -> bytes:
    """A valid message with one or two random edits (test_wire's mutations), sometimes cut short."""
    b = draw(st.integers(0, len(texts) - 1))
    doc = json.loads(texts[b])
    by_depth = tw._by_depth(doc)
    for _ in range(draw(st.integers(1, 2))):
        paths = by_depth[draw(st.integers(0, len(by_depth) - 1))]
        doc = tw._mutate(doc, paths[draw(st.integers(0, len(paths) - 1))], draw)
    payload = json.dumps(doc, allow_nan=True, separators=draw(st.sampled_from([(",", ":"), (", ", ": ")]))).encode()
    if draw(st.integers(0, 9)) == 0:
        payload = payload[: draw(st.integers(0, len(payload)))]
    return payload


_POSE_BASES = tp._BASE_PAYLOADS + (
    json.dumps({**json.loads(tp._BASE_PAYLOADS[2]), "version": 1,
                "people": [{k: v for k, v in p.items() if k != "estimator"} for p in json.loads(tp._BASE_PAYLOADS[2])["people"]]}).encode(),
)


@settings(max_examples=10_000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(_byte_replaced(tw._BASE_PAYLOADS), _mutated(tw._BASE_TEXTS)))
def test_observation_typed_decoder_agrees_with_validator(payload: bytes) -> None:
    _agree(payload, wire)


@settings(max_examples=10_000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(_byte_replaced(_POSE_BASES), _mutated(tuple(p.decode() for p in _POSE_BASES))))
def test_pose_typed_decoder_agrees_with_validator(payload: bytes) -> None:
    """And PoseArray's version of test_wire's mutated-message property: a PoseArray or a PoseDecodeError."""
    _agree(payload, pose_msg)
    try:
        poses = pose_msg.decode(payload)
    except pose_msg.PoseDecodeError as e:
        assert e.reason in pose_msg.REASONS and e.field
        return
    tp.assert_close(poses, pose_msg.decode(pose_msg.encode(poses)))


@pytest.mark.parametrize("codec, payload", [
    (wire, tw._BASE_PAYLOADS[1]),                 # one person with 3D points
    (wire, tw._BASE_PAYLOADS[2]),                 # partial views, no 3D
    (pose_msg, tp._BASE_PAYLOADS[2]),             # three people, version 2
    (pose_msg, _POSE_BASES[-1]),                  # version 1
])
def test_valid_payloads_take_the_typed_path(codec, payload: bytes) -> None:
    assert codec._typed_decode(payload, None) is not None


@pytest.mark.parametrize("codec, payload, old, new", [
    (wire, tw._BASE_PAYLOADS[1], b'"camera":', b'"camera":"x","camera":'),   # same key twice
    (pose_msg, tp._BASE_PAYLOADS[1], b'"views":', b'"views":0,"views":'),    # in a person
    (pose_msg, tp._BASE_PAYLOADS[1], b'"site":', b'"site":"a\\"b","site":'),  # a discarded value with a quote
])
def test_repeated_keys_are_refused_by_both_paths(codec, payload: bytes, old: bytes, new: bytes) -> None:
    bad = payload.replace(old, new, 1)
    assert bad != payload
    data = typed_input(bad, codec.MAX_PAYLOAD_BYTES)
    assert data is None or codec._typed_decode(data, None) is None
    with pytest.raises(DecodeError) as info:
        codec.decode(bad)
    assert info.value.reason == "duplicate_key"


# --- encoders ------------------------------------------------------------------------------

_ODD = [math.nan, math.inf, -math.inf, 1e30, -1e30, 5000.0, -0.0, 1.5, 3.1416, -3.2, 1e-300, 1e-7, 2.0**64]


@st.composite
def _broken_observations(draw: st.DrawFn) -> Observation:
    """A valid observation, then one number of one person changed to an odd value."""
    obs = draw(tw.observations())
    if not obs.people:
        return obs
    i = draw(st.integers(0, len(obs.people) - 1))
    p = obs.people[i]
    arrays = {"keypoints": p.keypoints.copy(), "bbox": p.bbox.copy(), "histogram": p.histogram.copy()}
    if p.points3d is not None:
        arrays["points3d"] = p.points3d.copy()
    name = draw(st.sampled_from(sorted(arrays)))
    a = arrays[name].reshape(-1)
    a[draw(st.integers(0, a.size - 1))] = draw(st.sampled_from(_ODD))
    people = list(obs.people)
    people[i] = PersonView(**{**p.__dict__, **arrays})
    return Observation(obs.site, obs.camera, obs.seq, obs.stamp_ns, obs.width, obs.height, tuple(people))


def _checked(encode_checked, value) -> bytes | None:
    try:
        return encode_checked(value)
    except ValueError:
        return None


@settings(max_examples=1000, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(_broken_observations())
def test_observation_typed_encoder_agrees_with_checked_encoder(obs: Observation) -> None:
    fast, slow = wire._typed_encode(obs), _checked(wire._checked_encode, obs)
    assert (fast is None) == (slow is None), (fast, slow)
    if fast is not None:
        assert wire._observation(parse_json(fast, wire.MAX_PAYLOAD_BYTES), None) == wire.decode(slow)


@st.composite
def _broken_pose_arrays(draw: st.DrawFn) -> PoseArray:
    """A valid PoseArray, then one value of one person changed to an odd one (or none changed)."""
    poses = draw(tp.pose_arrays())
    if draw(st.integers(0, 4)) == 0:  # a top-level field
        field = draw(st.sampled_from(["site", "seq", "latency_ns", "cameras_alive", "estimator"]))
        value = draw(st.sampled_from({
            "site": ["lab/1", "", "lab\n", 5], "seq": [-1, 2**63, 1.5, True, np.int64(3)], "latency_ns": [-5, None, np.uint64(7)],
            "cameras_alive": [("a", "a"), ("a\x00b",), "cam", ["1"], ("y",) * 65], "estimator": ["", "x" * 129, "\t", 3],
        }[field]))
        return PoseArray(**{**poses.__dict__, field: value})
    if not poses.people or draw(st.integers(0, 4)) == 0:
        return poses
    i = draw(st.integers(0, len(poses.people) - 1))
    p = poses.people[i]
    field = draw(st.sampled_from(["x", "y", "yaw", "vx", "yaw_rate", "confidence", "cov", "views", "id", "cameras", "estimator"]))
    if field == "cov":
        cov = p.cov.copy()
        cov[draw(st.integers(0, 2)), draw(st.integers(0, 2))] = draw(st.sampled_from(_ODD))
        value: Any = cov
    elif field in ("views", "id"):
        value = draw(st.sampled_from([-1, 256, 2**53, True, 1.0, None]))
    elif field == "cameras":
        value = draw(st.sampled_from([("a", "a"), ("a b",), ("a\x00b",), ("a", ""), "cam-1", ("x",) * 65, (), ["1", "2"]]))
    elif field == "estimator":
        value = draw(st.sampled_from(["", "x" * 129, "caf\u00e9", "a\nb", None]))
    else:
        value = draw(st.sampled_from(_ODD + [True, None, "1.0"]))
    people = list(poses.people)
    people[i] = PersonPose(**{**p.__dict__, field: value})
    return PoseArray(poses.site, poses.seq, poses.stamp_ns, tuple(people), poses.latency_ns, poses.cameras_alive, poses.estimator)


@settings(max_examples=1000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(_broken_pose_arrays())
def test_pose_typed_encoder_agrees_with_checked_encoder(poses: PoseArray) -> None:
    fast, slow = pose_msg._typed_encode(poses), _checked(pose_msg._checked_encode, poses)
    assert (fast is None) == (slow is None), (fast, slow)
    if fast is not None:
        back = pose_msg._pose_array(parse_json(fast, pose_msg.MAX_PAYLOAD_BYTES), None)
        tp.assert_close(back, pose_msg.decode(slow))  # the same up to the last rounded digit (ties)


def test_pose_encode_refuses_a_nan_below_the_diagonal_only() -> None:
    """The checked encoder used to send the upper triangle and drop it; both paths now refuse it."""
    p = tp.make_poses(1).people[0]
    cov = p.cov.copy()
    cov[1, 0] = math.nan
    poses = PoseArray("lab", 1, tp.STAMP, (PersonPose(**{**p.__dict__, "cov": cov}),))
    assert pose_msg._typed_encode(poses) is None
    with pytest.raises(ValueError, match=r"people\[0\]\.cov must be symmetric"):
        pose_msg.encode(poses)
