"""The WheresTheFellow reader: conventions measured on dev.json, validation, frame helpers."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from superbody.edge.angles import wrap_angle
from superbody.edge.body import LEFT_HIP, LEFT_SHOULDER, NOSE, NUM_KEYPOINTS, RIGHT_HIP, RIGHT_SHOULDER
from superbody.edge.colour import HIST_BINS
from superbody.edge.site import load_site
from superbody.models.data.wtf import (
    DatasetError,
    RawSample,
    from_dataset_frame,
    keypoint_bbox,
    load_wtf,
    load_wtf_raw,
    parse_wtf,
    to_dataset_frame,
    world_to_wtf,
    wtf_to_world,
)
from superbody.models.dataset_calibration import decompose_projection, normalised_dlt
from tests.conftest import DEV_JSON
from tests.conftest import WTF_SITE as SITE_TOML


def _forward(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Unit facing direction (2,) from a left/right joint pair: the right-hand normal of right->left, z up."""
    s = left[:2] - right[:2]
    f = np.array([s[1], -s[0]])
    return f / np.linalg.norm(f)


def _joint_yaw(sample: RawSample) -> float:
    """Torso yaw from the 3D joints of all views: unit votes of the shoulder line, the hip line and
    the nose's side of the shoulders, summed (single views' depth-based joints are noisy)."""
    acc = np.zeros(2)
    for v in sample.views:
        J = v.joints
        ok = ~np.isnan(J[:, 0])
        for left, right in ((LEFT_SHOULDER, RIGHT_SHOULDER), (LEFT_HIP, RIGHT_HIP)):
            if ok[left] and ok[right]:
                acc += _forward(J[left], J[right])
        if ok[NOSE] and ok[LEFT_SHOULDER] and ok[RIGHT_SHOULDER]:
            n = J[NOSE, :2] - (J[LEFT_SHOULDER, :2] + J[RIGHT_SHOULDER, :2]) / 2
            acc += n / np.linalg.norm(n)
    return math.atan2(acc[1], acc[0]) if np.any(acc) else math.nan


# The eight candidate mappings from the dataset angle to yaw: sign * angle + k * pi/2.
CANDIDATES = [(sign, k) for sign in (1, -1) for k in range(4)]


def _median_residual_deg(reference: np.ndarray, angle: np.ndarray, sign: int, k: int) -> float:
    return float(np.degrees(np.median(np.abs(wrap_angle(reference - (sign * angle + k * np.pi / 2))))))


# --- conventions measured on dev.json -----------------------------------------------------------


def test_dataset_world_is_left_handed(raw):
    # With positive focal lengths, every camera's DLT on the file's own (X, Y, Z) needs a mirror
    # (det R = -1); after wtf_to_world the same pairs give proper rotations.
    for cam in ("1", "2", "3"):
        pts = np.concatenate([v.joints[v.visible] for s in raw for v in s.views if v.camera == cam])
        pix = np.concatenate([v.keypoints[v.visible, :2] for s in raw for v in s.views if v.camera == cam])
        dataset_mm = np.stack(world_to_wtf(pts[:, 0], pts[:, 1], pts[:, 2]), axis=1)
        _, R_raw, _ = decompose_projection(normalised_dlt(dataset_mm, pix))
        _, R_rep, _ = decompose_projection(normalised_dlt(pts, pix))
        assert np.linalg.det(R_raw) == pytest.approx(-1.0, abs=1e-6), cam
        assert np.linalg.det(R_rep) == pytest.approx(1.0, abs=1e-6), cam


def test_nose_is_on_the_forward_side_of_the_shoulders(raw):
    # Anatomy alone fixes the handedness: in a right-handed z-up frame the nose is on the side of
    # the shoulder line that the right-hand normal of right->left points to. A mirrored mapping
    # would put it on the wrong side in most views.
    sides = []
    for s in raw:
        for v in s.views:
            J = v.joints
            if not np.isnan(J[[NOSE, LEFT_SHOULDER, RIGHT_SHOULDER], 0]).any():
                n = J[NOSE, :2] - (J[LEFT_SHOULDER, :2] + J[RIGHT_SHOULDER, :2]) / 2
                sides.append(np.dot(n, _forward(J[LEFT_SHOULDER], J[RIGHT_SHOULDER])) > 0)
    assert len(sides) > 150
    assert np.mean(sides) > 0.75


def test_yaw_convention_matches_the_3d_joints(raw):
    yaw_joints = np.array([_joint_yaw(s) for s in raw])
    ok = ~np.isnan(yaw_joints)
    angle = np.array([to_dataset_frame(*s.truth)[2] for s in raw])
    residual = {c: _median_residual_deg(yaw_joints[ok], angle[ok], *c) for c in CANDIDATES}
    chosen = (1, 1)  # yaw = angle + pi/2, as from_dataset_frame does
    assert ok.sum() > 200
    assert residual[chosen] < 20.0, residual
    assert all(residual[chosen] + 10.0 < r for c, r in residual.items() if c != chosen), residual
    # from_dataset_frame really is that mapping.
    assert np.allclose(wrap_angle(from_dataset_frame(0.0, 0.0, angle)[2] - (angle + np.pi / 2)), 0.0)


def test_yaw_convention_matches_the_walking_direction(raw):
    # While walking (> 0.3 m/s) people face where they go: an independent check of the angle.
    truth = np.array([s.truth for s in raw])
    t = np.array([s.stamp_ns for s in raw]) / 1e9
    velocity = np.gradient(truth[:, :2], t, axis=0)
    walking = np.linalg.norm(velocity, axis=1) > 0.3
    heading = np.arctan2(velocity[walking, 1], velocity[walking, 0])
    angle = np.array([to_dataset_frame(*s.truth)[2] for s in raw])[walking]
    residual = {c: _median_residual_deg(heading, angle, *c) for c in CANDIDATES}
    assert walking.sum() > 80
    assert residual[(1, 1)] < 25.0, residual
    assert all(residual[(1, 1)] + 30.0 < r for c, r in residual.items() if c != (1, 1)), residual


def test_original_estimate_uses_the_same_convention(raw):
    # The file's per-camera ``world`` estimate was computed from the shoulder line: read with our
    # mapping, its angle is exactly the right-hand normal of right->left shoulder.
    diffs = []
    for s in raw:
        for v in s.views:
            J = v.joints
            if v.estimate is not None and not np.isnan(J[[LEFT_SHOULDER, RIGHT_SHOULDER], 0]).any():
                f = _forward(J[LEFT_SHOULDER], J[RIGHT_SHOULDER])
                diffs.append(wrap_angle(math.atan2(f[1], f[0]) - v.estimate[2]))
    assert len(diffs) > 400
    assert np.degrees(np.abs(diffs)).max() < 1e-3


def test_ground_truth_is_millimetres_in_the_joints_frame_ahead_of_the_torso(raw):
    # Read as millimetres, the chest camera sits a hand's width ahead of the torso centre; read as
    # metres it would be kilometres away from the joints.
    forward, sideways = [], []
    for s in raw:
        torso = np.concatenate([v.joints[[LEFT_SHOULDER, RIGHT_SHOULDER, LEFT_HIP, RIGHT_HIP], :2] for v in s.views])
        torso = torso[~np.isnan(torso[:, 0])]
        if len(torso) == 0:
            continue
        x, y, yaw = s.truth
        d = np.array([x, y]) - torso.mean(axis=0)
        forward.append(d @ [math.cos(yaw), math.sin(yaw)])
        sideways.append(d @ [-math.sin(yaw), math.cos(yaw)])
    assert len(forward) > 200
    assert 0.1 < np.mean(forward) < 0.35
    assert abs(np.mean(sideways)) < 0.05
    assert np.median(np.hypot(forward, sideways)) < 0.5


# --- the reader on dev.json ---------------------------------------------------------------------


def test_load_wtf_dev(raw):
    samples = load_wtf(DEV_JSON)
    assert len(samples) == 225
    counts = np.bincount([len(s.views) for s in samples], minlength=4)
    assert counts.tolist() == [0, 53, 69, 103]  # the README's counts
    stamps = [s.stamp_ns for s in samples]
    assert stamps == sorted(stamps) and stamps[0] == 1584100872192 * 1_000_000
    for s in samples:
        assert set(s.views) <= {"1", "2", "3"}
        assert s.truth.shape == (3,) and -np.pi < s.truth[2] <= np.pi
        for pv in s.views.values():
            assert pv.keypoints.shape == (NUM_KEYPOINTS, 3) and pv.keypoints.dtype == np.float32
            assert pv.histogram.shape == HIST_BINS and not pv.histogram.any()
            assert pv.points3d is None
            uv = pv.keypoints[pv.visible, :2]
            assert np.all(uv >= pv.bbox[:2]) and np.all(uv <= pv.bbox[2:])
    # The first sample's truth: ground_truth [-3.07, 0.04, 7.42, 0.00028] mm, mm, mm, rad.
    assert samples[0].truth == pytest.approx([-0.00307488, 0.00741777, 0.00028351751 + np.pi / 2], abs=1e-7)


def test_load_wtf_with_site_gives_camera_frame_points(raw):
    site = load_site(SITE_TOML)
    samples = load_wtf(DEV_JSON, site=site)
    for s in samples[::10]:
        for cid, pv in s.views.items():
            cam = site.camera(cid)
            p = pv.points3d[pv.visible].astype(np.float64)  # (M, 3) camera frame, metres
            assert np.all(p[:, 2] > 0.1)  # in front (a few joints have bad depth: 0.12 m)
            # The depth camera's points project onto the keypoints through K alone.
            uv = p[:, :2] / p[:, 2:] * [cam.fx, cam.fy] + [cam.cx, cam.cy]
            assert np.abs(uv - pv.keypoints[pv.visible, :2]).max() < 1e-3
            assert np.isnan(pv.points3d[~pv.visible]).all()


def test_load_wtf_rejects_a_site_without_the_cameras(raw):
    site = load_site(SITE_TOML)
    partial = type(site)(name=site.name, cameras=site.cameras[:2], floor=site.floor)
    with pytest.raises(DatasetError, match="lacks camera"):
        load_wtf(DEV_JSON, site=partial)


# --- validation ---------------------------------------------------------------------------------


def _joints(dx: float = 0.0) -> dict:
    return {
        "nose": [10.0 + dx, 1600.0, 20.0, 300, 100, 0.9],
        "left_shoulder": [-150.0 + dx, 1450.0, 0.0, 280, 160, 0.8],
        "right_shoulder": [150.0 + dx, 1450.0, 0.0, 330, 160, 0.7],
    }


def _valid_doc() -> dict:
    def view(cam: int, t: int) -> dict:
        return {"cameraId": cam, "timestamp": t, "ground_truth": [1.0, 0.0, 2.0, 0.5], "world": [0.0, 0, 0.0, 0.1], "joints": _joints()}

    return {"data_set": [{"superbody": [view(1, 1000), view(2, 1010)]}, {"superbody": [view(3, 1100), view(1, 1105)]}]}


def _set(path: tuple, value) -> Callable[[Any], Any]:
    def mutate(doc):
        obj = doc
        for key in path[:-1]:
            obj = obj[key]
        obj[path[-1]] = value
        return doc

    return mutate


def _delete(path: tuple) -> Callable[[Any], Any]:
    def mutate(doc):
        obj = doc
        for key in path[:-1]:
            obj = obj[key]
        del obj[path[-1]]
        return doc

    return mutate


V = ("data_set", 1, "superbody", 1)  # the second view of the second sample

BAD_INPUTS = [
    # (mutation, text the error must contain)
    (lambda d: [d], "top level: must be an object"),  # a list at the top
    (_delete(("data_set",)), "data_set: is missing"),
    (_set(("data_set",), []), "data_set: must be a non-empty list"),  # empty data set
    (_set(("data_set",), {"a": 1}), "data_set: must be a non-empty list"),
    (_set(("data_set", 1), [1, 2]), "data_set[1]: must be an object"),
    (_delete(("data_set", 1, "superbody")), "data_set[1].superbody: is missing"),
    (_set(("data_set", 1, "superbody"), []), "data_set[1].superbody: must be a list of 1 to 3 views"),
    (_set(("data_set", 1, "superbody", 1), "view"), "data_set[1].superbody[1]: must be an object"),
    (_delete(V + ("cameraId",)), "data_set[1].superbody[1].cameraId: is missing"),
    (_set(V + ("cameraId",), 4), "data_set[1].superbody[1].cameraId: must be one of 1, 2, 3, got 4"),  # unknown camera
    (_set(V + ("cameraId",), "2"), "data_set[1].superbody[1].cameraId: must be one of"),  # a string
    (_set(V + ("cameraId",), True), "data_set[1].superbody[1].cameraId: must be one of"),  # JSON true is not 1
    (_set(V + ("cameraId",), 3), "data_set[1].superbody[1].cameraId: camera 3 appears twice"),
    (_delete(V + ("timestamp",)), "data_set[1].superbody[1].timestamp: is missing"),
    (_set(V + ("timestamp",), "noon"), "data_set[1].superbody[1].timestamp: must be a finite number, got 'noon'"),
    (_set(V + ("timestamp",), -5), "data_set[1].superbody[1].timestamp: must be in"),
    (_set(V + ("timestamp",), 1000.5), "data_set[1].superbody[1].timestamp: must be whole milliseconds"),
    (_delete(V + ("ground_truth",)), "data_set[1].superbody[1].ground_truth: is missing"),
    (_set(V + ("ground_truth",), [1.0, 2.0, 3.0]), "data_set[1].superbody[1].ground_truth: must be a list of 4 numbers"),
    (_set(V + ("ground_truth", 1), float("nan")), "data_set[1].superbody[1].ground_truth[1]: must be a finite number, got nan"),
    (_set(V + ("ground_truth", 3), float("inf")), "data_set[1].superbody[1].ground_truth[3]: must be a finite number, got inf"),
    (_set(V + ("world", 3), None), "data_set[1].superbody[1].world[3]: must be a finite number, got None"),
    (_delete(V + ("joints",)), "data_set[1].superbody[1].joints: is missing"),
    (_set(V + ("joints",), {}), "data_set[1].superbody[1].joints: must be a non-empty object"),  # no joint at all
    (_set(V + ("joints",), [[1, 2, 3, 4, 5, 0.5]]), "data_set[1].superbody[1].joints: must be a non-empty object"),
    (_set(V + ("joints", "neck"), [0, 0, 0, 1, 1, 0.5]), "data_set[1].superbody[1].joints.neck: unknown joint; valid: nose"),
    (_set(V + ("joints", "nose"), [0, 0, 0, 1, 1]), "data_set[1].superbody[1].joints.nose: must be [X, Y, Z, u, v, score]"),
    (_set(V + ("joints", "nose", 4), "x"), "data_set[1].superbody[1].joints.nose[4]: must be a finite number, got 'x'"),
    (_set(V + ("joints", "nose", 0), float("-inf")), "data_set[1].superbody[1].joints.nose[0]: must be a finite number"),
    (_set(V + ("joints", "nose", 5), 1.5), "data_set[1].superbody[1].joints.nose[5]: must be in [0.0, 1.0], got 1.5"),
    (_set(V + ("joints", "nose", 2), False), "data_set[1].superbody[1].joints.nose[2]: must be a finite number, got False"),
]


@pytest.mark.parametrize(("mutate", "expected"), BAD_INPUTS)
def test_load_wtf_raw_names_the_bad_field(tmp_path, mutate, expected):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(mutate(copy.deepcopy(_valid_doc()))))
    with pytest.raises(DatasetError) as err:
        load_wtf_raw(path)
    assert str(err.value).startswith(f"{path}: ")
    assert expected in str(err.value)
    assert isinstance(err.value, ValueError)


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (None, "cannot read dataset file"),  # missing file
        (b'{"data_set": [', "not valid JSON (line 1"),  # truncated
        (b"", "not valid JSON"),  # empty file
        (b"\xff\xfe\x00garbage", "not UTF-8 text"),
    ],
)
def test_load_wtf_raw_file_errors(tmp_path, content, expected):
    path = tmp_path / "data.json"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(DatasetError, match=expected.replace("(", r"\(")):
        load_wtf_raw(path)


def test_valid_doc_parses_and_ignores_unknown_keys():
    doc = _valid_doc()
    doc["data_set"][0]["superbody"][0]["extra"] = "ignored"
    del doc["data_set"][0]["superbody"][1]["world"]  # optional: only the baseline estimate
    raw = parse_wtf(doc)
    assert [len(s.views) for s in raw] == [2, 2]
    v = raw[1].views[0]
    assert v.camera == "3" and v.stamp_ms == 1100
    assert v.truth == pytest.approx([0.001, 0.002, 0.5 + np.pi / 2])
    assert v.joints[NOSE] == pytest.approx([0.010, 0.020, 1.6])  # x = X, y = Z, z = Y, metres
    assert v.keypoints[NOSE] == pytest.approx([300, 100, 0.9])
    assert np.isnan(v.keypoints[LEFT_HIP]).all() and np.isnan(v.joints[LEFT_HIP]).all()
    assert raw[0].views[1].estimate is None and raw[0].views[0].estimate == pytest.approx([0, 0, 0.1 + np.pi / 2])


# --- frames -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("dataset", "rep103"),
    [
        # (x_mm, z_mm, angle) -> (x, y, yaw)
        ((0.0, 0.0, 0.0), (0.0, 0.0, np.pi / 2)),  # angle 0 faces dataset +Z = REP-103 +y
        ((1000.0, -2000.0, np.pi / 2), (1.0, -2.0, np.pi)),  # +90 deg faces dataset -X
        ((-500.0, 250.0, np.pi), (-0.5, 0.25, -np.pi / 2)),  # faces dataset -Z
        ((0.0, 0.0, -np.pi / 2), (0.0, 0.0, 0.0)),  # faces dataset +X = REP-103 +x
        ((0.0, 0.0, 3 * np.pi / 2), (0.0, 0.0, 0.0)),  # angles outside (-pi, pi] wrap
    ],
)
def test_dataset_frame_table(dataset, rep103):
    got = from_dataset_frame(*dataset)
    assert np.allclose(got[:2], rep103[:2])
    assert abs(wrap_angle(got[2] - rep103[2])) < 1e-12 and -np.pi < got[2] <= np.pi
    back = to_dataset_frame(*rep103)
    assert np.allclose(back[:2], dataset[:2]) and abs(wrap_angle(back[2] - dataset[2])) < 1e-12


def test_yaw_pi_stays_pi():
    assert from_dataset_frame(0.0, 0.0, np.pi / 2)[2] == pytest.approx(np.pi)
    assert to_dataset_frame(0.0, 0.0, -np.pi / 2)[2] == pytest.approx(np.pi)


finite = st.floats(-1e4, 1e4, allow_nan=False)


@given(x=finite, y=finite, yaw=st.floats(-10, 10, allow_nan=False))
def test_dataset_frame_round_trip(x, y, yaw):
    x2, y2, yaw2 = from_dataset_frame(*to_dataset_frame(x, y, yaw))
    assert x2 == pytest.approx(x, abs=1e-9) and y2 == pytest.approx(y, abs=1e-9)
    assert abs(wrap_angle(yaw2 - yaw)) < 1e-9 and -np.pi < yaw2 <= np.pi


def test_frame_helpers_are_vectorised_inverses():
    rng = np.random.default_rng(0)
    X, Y, Z = rng.uniform(-3000, 3000, (3, 5, 4))
    x, y, z = wtf_to_world(X, Y, Z)
    assert x.shape == (5, 4)
    assert np.allclose(np.stack(world_to_wtf(x, y, z)), np.stack([X, Y, Z]))
    assert np.allclose(z, Y / 1000)  # dataset Y (up) is REP-103 z
    # The mapping is a reflection: it turns the left-handed dataset frame right-handed.
    M = np.stack(wtf_to_world(*np.eye(3)), axis=1)
    assert np.linalg.det(M * 1000) == pytest.approx(-1.0)
    xs, ys, yaws = from_dataset_frame(np.zeros(7), np.zeros(7), np.linspace(-4, 4, 7))
    assert yaws.shape == (7,) and np.all((yaws > -np.pi) & (yaws <= np.pi))


# --- boxes --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("uv", "expected"),
    [
        # visible (u, v) -> (x0, y0, x1, y1)
        ([(100, 100), (200, 300)], (90, 80, 210, 320)),  # 10% of 100 x 200
        ([(100, 100)], (96, 96, 104, 104)),  # one joint: at least 4 px
        ([(2, 470), (50, 478)], (0, 466, 54.8, 480)),  # clipped to the 640x480 image
    ],
)
def test_keypoint_bbox(uv, expected):
    kp = np.full((NUM_KEYPOINTS, 3), np.nan)
    kp[: len(uv), :2] = uv
    kp[: len(uv), 2] = 0.9
    box = keypoint_bbox(kp)
    assert box.dtype == np.float32
    assert box == pytest.approx(expected, abs=1e-4)


def test_truth_offset_round_trip():
    from superbody.models.data.wtf import TRUTH_OFFSET_M, torso_to_truth, truth_to_torso
    pose = np.array([[1.0, 2.0, 0.0], [0.0, 0.0, np.pi / 2]])
    chest = torso_to_truth(pose)
    np.testing.assert_allclose(chest[:, :2] - pose[:, :2], [[TRUTH_OFFSET_M, 0.0], [0.0, TRUTH_OFFSET_M]], atol=1e-12)
    np.testing.assert_allclose(truth_to_torso(chest), pose, atol=1e-12)
