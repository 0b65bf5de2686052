"""The tracker's parameters (``TrackerConfig``), checked when made: a bad value names its field and range."""

from __future__ import annotations

import math
from dataclasses import dataclass

from superbody.edge.body import NUM_KEYPOINTS
from superbody.host.messages.pose import MAX_PEOPLE

__all__ = ["TrackerConfig"]


def _check(name: str, value: object, lo: float, hi: float, *, lo_open: bool = False, integer: bool = False) -> None:
    kind = int if integer else (int, float)
    ok = (isinstance(value, kind) and not isinstance(value, bool) and math.isfinite(value)
          and (lo < value if lo_open else lo <= value) and value <= hi)
    if not ok:
        what = "an integer" if integer else "a number"
        raise ValueError(f"TrackerConfig.{name} must be {what} in {'(' if lo_open else '['}{lo}, {hi}], got {value!r}")


@dataclass(frozen=True)
class TrackerConfig:
    """The tracker's parameters; defaults are the paper's values where it gives one.

    Attributes:
        confirm_after_s: a candidate becomes a person after matches spanning this long.
        remove_after_s: a track unseen this long is removed (a person) or dropped (a candidate).
        d_max: a view matches a track only if the median Bhattacharyya distance between its
            histogram and the track's last ``history_q`` histograms is below this.
        history_q: histograms kept per track (Q).
        gate_m: a view matches a track only if its ground point lies within
            ``gate_m + sigma`` of the track's predicted position.
        use_geometry: False turns the gate and the geometric cost off (the paper's tracker).
        min_joints: views with fewer visible joints are ignored.
        confirm_max_gap_s: a candidate unseen longer than this restarts its confirmation clock,
            so "2 s of matches" means 2 s of steady matches.
        accel_std_mps2: how fast a person's walking velocity may change, for the position
            prediction: continuous white acceleration of spectral density ``accel_std_mps2^2``
            (``host.filtering.kalman.continuous_accel_noise``), so the velocity wanders by this
            many m/s in one second (1-sigma), however many camera frames come in that second.
            1: over seeds 11-40 of scenes k and l (12 s) 29 and 28 seeds meet the bar with no
            identity switch; at 2, people passing within 0.2 m of each other swapped (k, l seed
            35); the old piecewise-constant noise at 2 m/s^2 and 75 frames a second allowed
            0.23 m/s in a second, and tracks trailed people who set off walking.
        max_tracks: at most this many tracks, candidates included (see the module docstring
            for the policy when full); at most ``host.messages.pose.MAX_PEOPLE`` so every PoseArray
            can be published.
        reid_window_s: a removed person is remembered this long for re-identification
            (``host.tracking.reid``; a person unseen for over ``confirm_max_gap_s`` is a
            candidate for it too; 0 turns re-identification off, both kinds).
        confirm_min_support: a candidate is confirmed only if it was matched in at least this
            share of the frames of cameras that clearly saw where it stood, less those that
            glimpsed someone who could be it (``host.tracking.evidence``: a false positive one
            camera reports where the others see nothing is not a person; 0 turns the rule off).
        min_separation_m: a candidate closer than this to a confirmed person is that person, not
            a newcomer, and two confirmed tracks that stay this close are merged
            (``host.tracking.evidence``; 0 turns the rule off).
        same_body_sigmas: a view matches a track only if it puts the person within this many
            combined 1-sigmas of the track's predicted position, and each view in a person's set S
            must put them within as many of the point the other views agree on, or the worst is
            left out (``host.tracking.evidence``; 0 turns both tests off). 3: on dev.json (one
            person) the live CV is unchanged at 3; at 2.5 real views were left out (live yaw
            7.61 -> 7.73 deg, with the rule's first, pairwise form).
        same_body_across_m: a view's ground point's 1-sigma across its camera's line of sight,
            for that test and for the tracks' position filters (``host.tracking.motion``; along
            it, the point's own sigma: a range from a body part's assumed height). The bearing
            comes from pixels: what is left is the calibration's and the detector's error.
            0.08: dev.json's real sets (3 cameras) then have a view beyond 3 sigmas in 0.3% of
            them; at 0.05, in 3.3%, and the live figures get worse.
        edge_margin: a camera clearly sees where a candidate stands (a frame of it is a chance
            to see them: ``confirm_min_support``) only if the torso's centre projects inside its
            image less this share of the image's width and height on each side
            (``evidence.clearly_sees``: a detector misses people cut in half at the edges; 0: the
            whole image). 0.1: at 0, k seed 40 (12 s) loses a person for 3 s (recall 0.989 ->
            0.949) and k meets the bar at 28 of 30 seeds.
        merge_after_s: two confirmed tracks that stand inside each other (or whose views each
            fit the other's position) this long are one person, the younger is removed
            (``host.tracking.merge``). 0.5: at 0 (at once), seed 21 of k and l gets a switch and
            an extra track and each crowd (d, e, h, j, 45 s) a switch.
        colour_margin: colours point clearly to one track (a cue that vouches for a match) or
            one lost person (re-identification) only if every other is at least this much
            further in Bhattacharyya distance (``association.clearly_best``, ``host.tracking.reid``;
            0: the nearest is enough, even by a hair).
        duplicate_spread: two skeletons of one frame whose shared joints lie, on average, within
            this share of the taller one's height of each other are one detection
            (``measure.duplicate_views``; 0: only exact copies). 0.1: people standing side by
            side are a body width apart (about a quarter of their height), a detector's double
            report or a replayed copy a few pixels.
        duplicate_min_joints: two skeletons are compared for that test only if they share at
            least this many detected joints (fewer cannot tell a copy from a neighbour; at least 1).
        unknown_colour_cost: what the colour term of a view's cost under a track is where either
            has no colours (a colour's own term is its distance over ``d_max``, below 1 where
            feasible: ``host.tracking.association``); 0: an unknown colour costs what a perfect
            match does. 0.5: a middling match.
    """

    confirm_after_s: float = 2.0
    remove_after_s: float = 2.0
    d_max: float = 0.65
    history_q: int = 10
    gate_m: float = 1.0
    use_geometry: bool = True
    min_joints: int = 3
    confirm_max_gap_s: float = 1.0
    accel_std_mps2: float = 1.0
    max_tracks: int = 64
    reid_window_s: float = 30.0
    confirm_min_support: float = 0.5
    min_separation_m: float = 0.3
    same_body_sigmas: float = 3.0
    same_body_across_m: float = 0.08
    edge_margin: float = 0.1
    merge_after_s: float = 0.5
    colour_margin: float = 0.1
    duplicate_spread: float = 0.1
    duplicate_min_joints: int = 5
    unknown_colour_cost: float = 0.5

    def __post_init__(self) -> None:
        _check("confirm_after_s", self.confirm_after_s, 0.0, 600.0)
        _check("remove_after_s", self.remove_after_s, 0.0, 600.0, lo_open=True)
        _check("d_max", self.d_max, 0.0, 1.0, lo_open=True)
        _check("history_q", self.history_q, 1, 1000, integer=True)
        _check("gate_m", self.gate_m, 0.0, 100.0, lo_open=True)
        if not isinstance(self.use_geometry, bool):
            raise ValueError(f"TrackerConfig.use_geometry must be true or false, got {self.use_geometry!r}")
        _check("min_joints", self.min_joints, 0, NUM_KEYPOINTS, integer=True)
        _check("confirm_max_gap_s", self.confirm_max_gap_s, 0.0, 600.0, lo_open=True)
        _check("accel_std_mps2", self.accel_std_mps2, 0.0, 100.0, lo_open=True)
        _check("max_tracks", self.max_tracks, 1, MAX_PEOPLE, integer=True)
        _check("reid_window_s", self.reid_window_s, 0.0, 3600.0)
        _check("confirm_min_support", self.confirm_min_support, 0.0, 1.0)
        _check("min_separation_m", self.min_separation_m, 0.0, 2.0)
        _check("same_body_sigmas", self.same_body_sigmas, 0.0, 100.0)
        _check("same_body_across_m", self.same_body_across_m, 0.0, 10.0, lo_open=True)
        _check("edge_margin", self.edge_margin, 0.0, 0.45)
        _check("merge_after_s", self.merge_after_s, 0.0, 600.0)
        _check("colour_margin", self.colour_margin, 0.0, 1.0)
        _check("duplicate_spread", self.duplicate_spread, 0.0, 1.0)
        _check("duplicate_min_joints", self.duplicate_min_joints, 1, NUM_KEYPOINTS, integer=True)
        _check("unknown_colour_cost", self.unknown_colour_cost, 0.0, 1.0)
