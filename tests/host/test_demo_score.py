"""The demo's scorer (host.demo._Watcher): each published pose against the simulated truth."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from superbody.edge.sim import World
from superbody.edge.site import load_site
from superbody.host.demo import DemoConfig, _Watcher
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


@pytest.mark.parametrize("lag_s", [0.0, 2.0])  # published at once; published 2 s later (a host fusing in event time)
def test_each_pose_is_scored_against_the_truth_at_its_own_capture_time(lag_s):
    watcher = _Watcher(SITE, World(SITE, 2, seed=1), T0)
    watcher.world = _Truth()
    # Both poses are exact at their own stamps. Scored at A's stamp, B would be 1.0 m from
    # its pose (0.5 s earlier) and left unmatched; scored at the publish time, 4 m.
    publish = T1 + int(lag_s * S)
    arr = pose_msg.PoseArray(SITE.name, 1, publish, (_pose(1, 0.0, 0.0, T0), _pose(2, 0.4, 0.3, T1)), 0, ("1",), "analytic")
    watcher.on_people(SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: pose_msg.encode(arr))))
    s = watcher.score
    assert s.track_of == {0: 1, 1: 2} and s.switches == 0
    assert len(s.pos_err) == 2 and max(s.pos_err) < 1e-6, s.pos_err
    assert all(math.isfinite(e) for e in s.yaw_err)


def test_the_demo_gives_each_camera_its_timing_and_the_watcher_its_rate():
    cfg = DemoConfig(delay_s=0.1, camera_delay_s={"1": 0.8}, jitter_s=0.05, camera_fps={"3": 5.0})
    cfg.check_cameras(SITE)
    assert cfg.node_args("1") == ["--delay", "0.8", "--jitter", "0.05"]
    assert cfg.node_args("3") == ["--delay", "0.1", "--jitter", "0.05", "--fps", "5.0"]
    assert cfg.camera_timing("2") == {"delay_s": 0.1, "jitter_s": 0.05, "fps": None}
    # The watcher recomputes who each view is with the camera's own frame numbering (its noise follows it).
    watcher = _Watcher(SITE, World(SITE, 2, seed=1), T0, cfg.camera_fps)
    assert watcher.cams["3"].camera.fps == 5.0 and watcher.cams["1"].camera.fps == SITE.camera("1").fps
    with pytest.raises(KeyError, match="camera '4' is not in site 'wtf-apartment'; cameras: 1, 2, 3"):
        DemoConfig(camera_fps={"4": 5.0}).check_cameras(SITE)
