"""Simulator of people walking in a site, and of what each camera's 2D detector reports.

Library code shared by the simulated camera nodes, the tests, the demo and training; this
package exports its face. Two parts:

- ``World``: people with varied body sizes and clothing move through the site's floor,
  avoiding obstacles: they walk between waypoints with gait and arm swing, turn in place,
  stand still and sometimes side-step. A person's plan is periodic and is a pure function of
  absolute time, so any process that builds a ``World`` from the same site and seed sees the
  same people at the same instant (the shared world clock of the simulated camera nodes).
- ``render_views``: for one camera, what a detector such as OpenPifPaf would output: joints
  projected through the camera model, dropped outside the image, behind obstacles or other
  people, with a noise model (latent per-joint confidence thresholded at 0.5 as the
  WheresTheFellow data was, pixel noise, left/right swaps, occasional spurious people) and a
  hue-saturation histogram computed by ``edge.colour.hs_histogram`` from a synthetic patch of
  the person's clothing under the camera's lighting.

Ground truth is each person's torso pose (x, y, yaw) in REP-103.
"""

from superbody.edge.sim.appearance import Appearance, Lighting
from superbody.edge.sim.cameras import SimCamera, render_views
from superbody.edge.sim.noise import FACING_VISIBILITY, NoiseModel, facing_factor
from superbody.edge.sim.skeleton import skeleton
from superbody.edge.sim.world import PersonState, SimPerson, World

__all__ = [
    "NoiseModel",
    "Appearance",
    "SimPerson",
    "PersonState",
    "World",
    "Lighting",
    "skeleton",
    "render_views",
    "SimCamera",
    "FACING_VISIBILITY",
    "facing_factor",
]
