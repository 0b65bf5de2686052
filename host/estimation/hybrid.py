"""The hybrid estimator: the network and geometry, each trusted as far as it has earned.

Per person, the network (``host.estimation.estimator.OnnxEstimator``) gives a pose and its own 1-sigma
(``pose_std``, scaled by the calibration in the model's metadata), and the analytic estimator
(``host.estimation.analytic``) gives a pose whose 1-sigma depends on how many cameras saw the person and on
whether a shoulder or hip pair was seen (measured on real data, stored in the model's metadata
as ``hybrid.calibration``, with the geometry's typical yaw error per camera count, which is
subtracted from its yaw first). Then:

1. **Support gate.** Where the network has never been trained (its position, or the
   geometry's, more than ``floor_margin_m`` outside the site's floor polygon), the pose is the
   analytic one: label ``"analytic"``.
2. **Fusion.** Otherwise each of x, y and yaw is the weighted mean of the two (each less its
   typical error on held-out real data per camera count, ``net_bias`` and ``analytic_bias``; yaw as a
   weighted mean of unit vectors) with weights t/s_net^2 and 1/s_geo^2, where the trust t per
   camera count and per axis was fitted on held-out real data (a network
   whose real errors are biased deserves less weight than its sigma says; 0 leaves it to
   geometry), and sigma is that of this mean of two independent estimates ((1/s_net^2 +
   1/s_geo^2)^-1/2 at t = 1): label ``"hybrid"``. Where the geometry found nothing, the network's pose:
   label ``"onnx"``.
3. **A yaw from nothing.** Where the geometry's yaw came from no cue at all (``analytic.NO_CUE``:
   one side of a body, cut off at an image edge), the pose's yaw sigma is ``YAW_STD_NO_CUE`` and
   the filter keeps the person's yaw. The geometry's yaw is then 0 by convention: taken at the
   calibration's no-pair sigma (1.6 rad for the apartment), it turned a person standing still by
   141 deg in 1.5 s (``test_views_that_show_no_yaw_keep_the_persons_last_yaw``); and the
   apartment's network alone, tried there once instead, put them 150-180 deg off.

The fused sigma is what the host's filter uses as the measurement noise.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal, cast

import numpy as np
from numpy.typing import NDArray

from superbody.edge.angles import wrap_angle
from superbody.edge.floor import point_in_polygon
from superbody.edge.messages.observation import PersonView
from superbody.edge.site import Site
from superbody.host.estimation.analytic import NO_CUE, PAIR, YAW_STD_NO_CUE, AnalyticEstimator
from superbody.host.estimation.estimator import Estimates, ModelMismatchError, OnnxEstimator

__all__ = ["HybridCalibration", "HybridEstimator", "calibration_of", "fuse", "combine", "META_HYBRID", "SOURCES"]

META_HYBRID: Final[str] = "hybrid.calibration"
SOURCES: Final[tuple[str, ...]] = ("hybrid", "onnx", "analytic")


@dataclass(frozen=True)
class HybridCalibration:
    """How far the geometry is trusted, by camera count.

    Attributes:
        analytic_std: per camera count 1, 2, 3 (3 = three or more), the analytic pose's 1-sigma
            (x m, y m, yaw rad) when a shoulder or hip pair was seen.
        analytic_yaw_std_no_pair: the analytic yaw's 1-sigma without a shoulder or hip pair
            (from the head, or no yaw at all).
        net_trust: per camera count 1, 2, 3+, how much the network's weight is trusted per axis
            (x, y, yaw): its precision 1/sigma^2 is multiplied by this. 1 is plain inverse-variance
            fusion; 0 leaves the axis to geometry (a network whose errors on real data are biased
            is less useful than its sigma says: fitted on held-out real data).
        floor_margin_m: support gate: how far outside the floor polygon a pose may be.
        analytic_bias: per camera count 1, 2, 3+, the analytic pose's typical error (x m, y m,
            yaw rad; the median, measured on real data), subtracted from it before it is used:
            e.g. a yaw convention of the site's ground truth that differs from the shoulder line.
        net_bias: per camera count 1, 2, 3+, the network pose's typical error (x m, y m, yaw
            rad; the median of its errors on held-out real data), subtracted from it before the
            fusion (``models.hybrid_fit.NET_DEBIAS`` says which axes are measured: since December
            2026 none, as dev.json's offsets did not carry over to another recording).
        source: how the numbers were measured (free text, for the model card).
    """

    analytic_std: tuple[tuple[float, float, float], ...]
    analytic_yaw_std_no_pair: float = 3.0
    net_trust: tuple[tuple[float, float, float], ...] = ((1.0, 1.0, 1.0),) * 3
    floor_margin_m: float = 0.5
    analytic_bias: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.0),) * 3
    net_bias: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.0),) * 3
    source: str = ""

    def __post_init__(self) -> None:
        if len(self.analytic_std) != 3 or any(len(s) != 3 or not all(0 < v < 100 for v in s) for s in self.analytic_std):
            raise ValueError(f"analytic_std must be 3 rows (1, 2, 3+ cameras) of 3 positive sigmas, got {self.analytic_std!r}")
        if len(self.net_trust) != 3 or any(len(s) != 3 or not all(0 <= v <= 100 for v in s) for s in self.net_trust):
            raise ValueError(f"net_trust must be 3 rows (1, 2, 3+ cameras) of 3 factors in [0, 100], got {self.net_trust!r}")
        if not 0 < self.analytic_yaw_std_no_pair < 100:
            raise ValueError(f"analytic_yaw_std_no_pair must be in (0, 100) radians, got {self.analytic_yaw_std_no_pair!r}")
        if not 0 <= self.floor_margin_m <= 10:
            raise ValueError(f"floor_margin_m must be in [0, 10] metres, got {self.floor_margin_m!r}")
        for name in ("analytic_bias", "net_bias"):
            b = getattr(self, name)
            if len(b) != 3 or any(len(r) != 3 or not all(abs(v) <= 10 for v in r) for r in b):
                raise ValueError(f"{name} must be 3 rows (1, 2, 3+ cameras) of 3 values in [-10, 10], got {b!r}")

    def to_json(self) -> str:
        return json.dumps({"analytic_std": [list(s) for s in self.analytic_std], "analytic_yaw_std_no_pair": self.analytic_yaw_std_no_pair,
                           "net_trust": [list(s) for s in self.net_trust], "floor_margin_m": self.floor_margin_m,
                           "analytic_bias": [list(b) for b in self.analytic_bias], "net_bias": [list(b) for b in self.net_bias],
                           "source": self.source})

    @classmethod
    def from_json(cls, text: str) -> HybridCalibration:
        d = json.loads(text)
        return cls(analytic_std=_float_rows(d["analytic_std"]),
                   analytic_yaw_std_no_pair=float(d.get("analytic_yaw_std_no_pair", 3.0)),
                   net_trust=_float_rows(d.get("net_trust", ((1.0, 1.0, 1.0),) * 3)),
                   floor_margin_m=float(d.get("floor_margin_m", 0.5)),
                   analytic_bias=_float_rows(d.get("analytic_bias", ((0.0, 0.0, 0.0),) * 3)),
                   net_bias=_float_rows(d.get("net_bias", ((0.0, 0.0, 0.0),) * 3)), source=str(d.get("source", "")))

    def trust(self, cameras: NDArray) -> NDArray[np.float64]:
        """(B, 3) the trust factors (x, y, yaw) for camera counts (B,)."""
        return np.asarray(self.net_trust, dtype=np.float64)[np.clip(np.asarray(cameras, int), 1, 3) - 1]

    def debias(self, pose: NDArray, cameras: NDArray, bias: Literal["analytic_bias", "net_bias"] = "analytic_bias") -> NDArray[np.float64]:
        """(B, 3) analytic poses (or with ``bias="net_bias"``, network poses) less their calibrated
        bias (yaw wrapped to (-pi, pi])."""
        out = np.asarray(pose, np.float64) - np.asarray(getattr(self, bias), np.float64)[np.clip(np.asarray(cameras, int), 1, 3) - 1]
        out[:, 2] = wrap_angle(out[:, 2])
        return out

    def analytic_sigmas(self, cameras: NDArray, pair: NDArray) -> NDArray[np.float64]:
        """(B, 3) analytic 1-sigma for camera counts (B,) and shoulder-or-hip-pair flags (B,)."""
        table = np.asarray(self.analytic_std, dtype=np.float64)  # (3, 3)
        s = table[np.clip(np.asarray(cameras, int), 1, 3) - 1].copy()
        s[~np.asarray(pair, bool), 2] = self.analytic_yaw_std_no_pair
        return s


def _float_rows(rows: Any) -> tuple[tuple[float, float, float], ...]:
    """Parsed JSON rows as tuples of floats; ``HybridCalibration`` checks that they are 3 rows of 3."""
    return cast("tuple[tuple[float, float, float], ...]", tuple(tuple(float(v) for v in r) for r in rows))


def fuse(net: NDArray, net_std: NDArray, geo: NDArray, geo_std: NDArray, trust: NDArray | float = 1.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inverse-variance fusion of two pose estimates.

    Args:
        net, geo: (B, 3) poses (x, y, yaw).
        net_std, geo_std: (B, 3) their 1-sigmas.
        trust: (B, 3) or scalar factor on the network's weight (its precision 1/sigma^2 times
            this; 0 leaves an axis to the geometry). It moves the weights, not what each input
            is worth: the returned sigma is that of the weighted mean of two independent
            estimates with the given sigmas, so a trust above 1 does not make the result
            surer than the network.

    Returns:
        ``(pose, std)``, (B, 3) each; yaw in (-pi, pi].
    """
    trust = np.broadcast_to(np.asarray(trust, np.float64), np.shape(net_std))
    with np.errstate(divide="ignore", invalid="ignore"):
        w_n = np.where(trust > 0, trust / np.square(net_std), 0.0)  # (B, 3)
        w_g = 1.0 / np.square(geo_std)
        w = w_n + w_g
        xy = (w_n[:, :2] * net[:, :2] + w_g[:, :2] * geo[:, :2]) / w[:, :2]  # (B, 2)
        # yaw: the weighted mean direction of the two unit vectors
        s = w_n[:, 2] * np.sin(net[:, 2]) + w_g[:, 2] * np.sin(geo[:, 2])
        c = w_n[:, 2] * np.cos(net[:, 2]) + w_g[:, 2] * np.cos(geo[:, 2])
        yaw = np.arctan2(s, c)
        yaw = np.where(yaw <= -np.pi, np.pi, yaw)
        # var(sum w_i x_i / sum w_i) for independent x_i; at trust 1 it is 1 / (w_n + w_g)
        var = (np.where(w_n > 0, np.square(w_n * net_std), 0.0) + np.square(w_g * geo_std)) / np.square(w)
    return np.column_stack([xy, yaw]), np.sqrt(var)


def calibration_of(net: OnnxEstimator) -> HybridCalibration:
    """The hybrid calibration a model carries in its metadata.

    Raises:
        ModelMismatchError: the model has none, or an invalid one.
    """
    text = net.metadata.get(META_HYBRID)
    if not text:
        raise ModelMismatchError(f"{net.path}: no {META_HYBRID} metadata (run superbody calibrate hybrid on it)")
    try:
        return HybridCalibration.from_json(text)
    except (ValueError, KeyError, TypeError) as e:
        raise ModelMismatchError(f"{net.path}: metadata {META_HYBRID} is invalid: {e}") from None


class HybridEstimator:
    """The network fused with geometry (module docstring); implements ``Estimator``.

    Args:
        net: the ONNX estimator; its model must carry ``hybrid.calibration`` metadata and a
            ``pose_std`` output.
        site: the site.

    Raises:
        ModelMismatchError: the model has no uncertainty output or no hybrid calibration.
    """

    def __init__(self, net: OnnxEstimator, site: Site):
        if not net.has_std:
            raise ModelMismatchError(f"{net.path}: the hybrid estimator needs a model with a pose_std output (retrain it)")
        self.calibration = calibration_of(net)
        self.net = net
        self.site = site
        self.analytic = AnalyticEstimator(site)

    def estimate(self, view_sets: Sequence[Mapping[str, PersonView]]) -> NDArray[np.float64]:
        return self.estimate_detailed(view_sets).pose

    def estimate_detailed(self, view_sets: Sequence[Mapping[str, PersonView]]) -> Estimates:
        """Poses, 1-sigmas and, per person, which estimator produced the pose."""
        if len(view_sets) == 0:
            return Estimates(np.zeros((0, 3)), np.zeros((0, 3)), ())
        net, net_std = self.net.estimate_with_std(view_sets)
        geo, cue = self.analytic.estimate_with_cues(view_sets)
        pose, std, source = combine(net, net_std, geo, cue == PAIR, np.array([len(v) for v in view_sets]), self.calibration, self.site,
                                    no_yaw=cue == NO_CUE)
        return Estimates(pose, std, tuple(str(s) for s in source))


def combine(
    net: NDArray, net_std: NDArray, geo: NDArray, pair: NDArray, cameras: NDArray, calibration: HybridCalibration, site: Site,
    no_yaw: NDArray | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.str_]]:
    """The hybrid's decision on arrays: the support gate, then the fusion (module docstring).

    Args:
        net, net_std: (B, 3) the network's poses and calibrated 1-sigmas.
        geo, pair: (B, 3) the analytic poses, (B,) whether each yaw came from a shoulder/hip pair.
        cameras: (B,) how many cameras saw each person.
        no_yaw: (B,) analytic yaws from nothing (``analytic.NO_CUE``): the pose's yaw sigma is
            ``YAW_STD_NO_CUE`` there, so the filter keeps the person's yaw. None: none (the
            calibration's fits, which take the no-pair sigma for them).

    Returns:
        (B, 3) poses, (B, 3) 1-sigmas and (B,) sources ("hybrid", "onnx", "analytic").
    """
    net = calibration.debias(net, cameras, "net_bias")
    geo = calibration.debias(geo, cameras)
    geo_std = calibration.analytic_sigmas(cameras, pair)
    pose, std = fuse(net, net_std, geo, geo_std, calibration.trust(cameras))
    has_geo = np.isfinite(geo[:, :2]).all(1)
    m = calibration.floor_margin_m
    outside = ~(_near_floor(net[:, :2], site, m) & np.where(has_geo, _near_floor(np.nan_to_num(geo[:, :2]), site, m), True))
    source = np.where(~has_geo, "onnx", np.where(outside, "analytic", "hybrid"))
    pick = lambda a, b, fused: np.where((source == "onnx")[:, None], a, np.where((source == "analytic")[:, None], b, fused))  # noqa: E731
    out_std = pick(net_std, geo_std, std)
    if no_yaw is not None:  # neither yaw is to be trusted there (module docstring); the network's alone stands
        out_std[np.asarray(no_yaw, bool) & (source != "onnx"), 2] = YAW_STD_NO_CUE
    return pick(net, geo, pose), out_std, source


def _near_floor(xy: NDArray, site: Site, margin: float) -> NDArray[np.bool_]:
    """(B,) points inside the floor polygon, or within ``margin`` of it."""
    inside = point_in_polygon(xy, site.floor)
    if margin <= 0 or inside.all():
        return inside
    p = np.asarray(site.floor, dtype=np.float64)
    a, b = p, np.roll(p, -1, axis=0)  # (V, 2) edges a -> b
    ab = b - a
    t = np.clip(np.einsum("bvk,vk->bv", xy[:, None] - a[None], ab) / np.maximum((ab**2).sum(1), 1e-12), 0, 1)  # (B, V)
    d = np.linalg.norm(xy[:, None] - (a[None] + t[..., None] * ab[None]), axis=2).min(1)  # (B,)
    return inside | (d <= margin)
