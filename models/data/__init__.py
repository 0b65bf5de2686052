"""Training and evaluation data: the WheresTheFellow recordings (wtf.py), one person's views and
truth (samples.py), simulated datasets of a site (simdata.py) and the simulator's statistics
against the real detector's (simstats.py)."""

from superbody.models.data.samples import Sample

__all__ = ["Sample"]
