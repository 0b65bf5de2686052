"""The camera's message, the Observation: its in-memory types (observation.py), its rule table
(observation_rules.py), its wire codec (wire.py) and the checks every superbody codec shares
(payload.py)."""

from superbody.edge.messages.observation import Observation, PersonView
from superbody.edge.messages.payload import DecodeError

__all__ = ["Observation", "PersonView", "DecodeError"]
