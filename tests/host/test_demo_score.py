"""The demo's scorer (host.demo._Watcher): each published pose against the simulated truth."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from superbody.edge.sim import World
from superbody.edge.site import load_site
from superbody.host.demo import _Watcher
from superbody.host.messages import pose as pose_msg
from tests.conftest import WTF_SITE

S = 1_000_000_000
T1 = 1_800_000_000 * S
T0 = T1 - S // 2  # one array's people were seen up to the host's freshness (0.5 s) apart
SITE = load_site(WTF_SITE)


class _Truth:
    """A: standing at (0, 0). B: walking along +x at 2 m/s, at (0.4, 0.3) at T1."""

    def states(self, t_s: float) -> list[SimpleNamespace]:
        return [SimpleNamespace(x=0.0, y=0.0, yaw=0.0), SimpleNamespace(x=0.4 + 2.0 * (t_s - T1 / S), y=0.3, yaw=0.0)]


def _pose(pid: int, x: float, y: float, stamp_ns: int) -> pose_msg.PersonPose:
    return pose_msg.PersonPose(id=pid, x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, yaw_rate=0.0, cov=np.eye(3) * 0.01, confidence=1.0,
                               cameras=("1",), stamp_ns=stamp_ns, views=1, estimator="analytic")


def test_each_pose_is_scored_against_the_truth_at_its_own_capture_time():
    watcher = _Watcher(SITE, World(SITE, 2, seed=1), T0)
    watcher.world = _Truth()
    # Both poses are exact at their own stamps. Scored at A's stamp, B would be 1.0 m from
    # its pose (0.5 s earlier) and left unmatched.
    arr = pose_msg.PoseArray(SITE.name, 1, T1, (_pose(1, 0.0, 0.0, T0), _pose(2, 0.4, 0.3, T1)), 0, ("1",), "analytic")
    watcher.on_people(SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: pose_msg.encode(arr))))
    s = watcher.score
    assert s.track_of == {0: 1, 1: 2} and s.switches == 0
    assert len(s.pos_err) == 2 and max(s.pos_err) < 1e-6, s.pos_err
    assert all(math.isfinite(e) for e in s.yaw_err)
