"""People from the observations of all cameras: the tracker (tracker.py; ``Tracker.update`` is a
list of named steps), its parameters (config.py), a track (track.py), association (association.py),
each track's position filter (motion.py) and single-view ground points (ground.py)."""

from superbody.host.tracking.association import Match
from superbody.host.tracking.config import TrackerConfig
from superbody.host.tracking.track import Track
from superbody.host.tracking.tracker import Tracker

__all__ = ["Tracker", "TrackerConfig", "Track", "Match"]
