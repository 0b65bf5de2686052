"""Frame sources of a camera node: the seam (``Frame``, ``FrameSource``, ``SourceError`` in
source.py) and its implementations, each opened by ``edge.node.open_source`` from ``--source``:

- sim_source.py: simulated people (no image);
- video.py: video files, webcams and RTSP streams through OpenCV (images for a detector);
- replay.py: a camera's Observations from a ``superbody record`` MCAP file;
- oak.py, oak_convert.py: a Luxonis OAK with the pose network on the device (the ``oak`` extra).
"""

from superbody.edge.sources.source import Frame, FrameSource, SourceError

__all__ = ["Frame", "FrameSource", "SourceError"]
