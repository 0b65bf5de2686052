"""Simulated people seen by one camera of a site, as a frame source (edge/sim/).

Frames are captured on a grid of the world clock: frame k at k / fps plus a per-camera phase
(cameras are not synchronised, so their instants spread over the frame period). Simulated
nodes started with the same site and seed therefore see the same people at the same instants,
whichever process computes them. A node that falls behind skips to the next instant in the
future rather than publishing old ones late.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from superbody.edge.clock import WorldClock
from superbody.edge.site import Site
from superbody.edge.sources.source import Frame

__all__ = ["SimSource"]


class SimSource:
    """A ``FrameSource`` whose frames carry the simulator's detections (no image).

    Args:
        site: the site.
        camera_id: the camera whose view is simulated.
        seed: world seed; nodes with the same seed see the same people.
        people: number of simulated people.
        depth: simulate a depth camera (3D joints in the detections).
        clock: the world clock that paces the frames. Its anchor is also the scene's start
            (``World.epoch_s``): a run whose processes share an anchor (``superbody demo``)
            shows the same scene every time.
        fps: capture rate, frames per second (default: the site camera's ``fps``).
    """

    def __init__(self, site: Site, camera_id: str, seed: int = 0, people: int = 3, depth: bool = False,
                 clock: WorldClock = WorldClock(), fps: float | None = None):
        from superbody.edge.sim import SimCamera, World

        self._cam = SimCamera(World(site, people, seed, epoch_s=clock.anchor_ns * 1e-9), camera_id, depth=depth, fps=fps)
        self.clock = clock
        self.period_ns = 1e9 / self._cam.camera.fps
        self.phase_ns = self.period_ns * site.camera_index(camera_id) / max(len(site.cameras), 1)
        self.skipped = 0
        self._closed = False

    def frames(self) -> Iterator[Frame]:
        k = math.ceil((self.clock.now_ns() - self.phase_ns) / self.period_ns)
        while not self._closed:
            t_ns = int(k * self.period_ns + self.phase_ns)
            self.clock.sleep_until(t_ns)
            obs = self._cam.observe(t_ns)[0]
            yield Frame(t_ns, obs.width, obs.height, None, obs.people)
            # If we fell behind (slow machine), skip to the next frame in the future.
            k_now = math.floor((self.clock.now_ns() - self.phase_ns) / self.period_ns)
            if k_now > k + 1:
                self.skipped += k_now - k - 1
                k = k_now
            k += 1

    def close(self) -> None:
        self._closed = True
