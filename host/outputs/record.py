"""``superbody record``: a site's traffic into an MCAP file.

Subscribes to ``superbody/<site>/**`` (every site: ``superbody/**``) and writes each
Observation, PoseArray and host status as it arrived: the payload bytes unchanged (JSON), one
MCAP channel per Zenoh key (the key is the topic), each with its message's JSON Schema
(``docs/schemas/{observation,people,status}.schema.json``, package ``superbody.schemas``).
Log time is the arrival time, publish time the message's own ``stamp_ns`` (capture time) when
it has one. Payloads that are not JSON objects are still recorded, and counted.

    superbody record --duration 60 --out site.mcap [--site NAME] [--connect tcp/10.0.0.2:7447]

Read it back with the ``mcap`` library (``mcap.reader.make_reader``) or open it in Foxglove.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import Counter, deque
from pathlib import Path
from typing import BinaryIO

from superbody.edge.messages import wire
from superbody.edge.resources import json_schema, package_version
from superbody.host.messages import pose as pose_msg
from superbody.host.messages import status as host_status

__all__ = ["Recorder", "message_kind", "record"]

log = logging.getLogger("superbody.record")

# Message kind -> the schema name written into the MCAP file (the payload's own "schema" field).
SCHEMA_NAMES = {"observation": wire.SCHEMA, "people": pose_msg.SCHEMA, "status": host_status.SCHEMA}


def message_kind(key: str) -> str | None:
    """``"observation"``, ``"people"``, ``"status"`` for a superbody key, None for any other key."""
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != "superbody":
        return None
    if len(parts) == 5 and parts[2] == "cameras" and parts[4] == "observations":
        return "observation"
    if len(parts) == 3 and parts[2] == "people":
        return "people"
    if len(parts) == 4 and parts[2:] == ["host", "status"]:
        return "status"
    return None


class Recorder:
    """Writes messages into an MCAP stream: a channel per key, a JSON Schema per message kind.

    Not thread-safe: one thread calls ``add`` (``record`` queues from Zenoh's threads).

    Args:
        stream: a binary file open for writing.
    """

    def __init__(self, stream: BinaryIO):
        from mcap.writer import Writer

        self._writer = Writer(stream)
        self._writer.start(profile="", library=f"superbody {package_version()}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: Counter[str] = Counter()
        self.counts: Counter[str] = Counter()  # by kind, plus "not_json"

    def _channel(self, key: str, kind: str) -> int:
        if kind not in self._schemas:
            self._schemas[kind] = self._writer.register_schema(name=SCHEMA_NAMES[kind], encoding="jsonschema", data=json_schema(kind))
        if key not in self._channels:
            self._channels[key] = self._writer.register_channel(topic=key, message_encoding="json", schema_id=self._schemas[kind])
        return self._channels[key]

    def add(self, key: str, payload: bytes, log_time_ns: int) -> bool:
        """Record one message; False (and nothing written) for a key that is not a superbody message."""
        kind = message_kind(key)
        if kind is None:
            return False
        publish_ns = log_time_ns
        try:
            doc = json.loads(payload)
            stamp = doc.get("stamp_ns") if isinstance(doc, dict) else None
            if isinstance(stamp, int) and 0 <= stamp < 2**63:
                publish_ns = stamp
        except (ValueError, UnicodeDecodeError):
            self.counts["not_json"] += 1
        channel = self._channel(key, kind)
        self._writer.add_message(channel_id=channel, log_time=log_time_ns, publish_time=publish_ns, data=bytes(payload),
                                 sequence=self._seq[key])
        self._seq[key] += 1
        self.counts[kind] += 1
        return True

    def close(self) -> None:
        self._writer.finish()


def record(conf, out: Path, duration_s: float | None, site: str | None = None, stop: threading.Event | None = None) -> dict:
    """Record until ``duration_s`` wall seconds pass or ``stop`` is set; returns the counts by kind."""
    import zenoh

    stop = stop or threading.Event()
    pending: deque[tuple[str, bytes, int]] = deque(maxlen=100_000)
    wake = threading.Condition()

    def on_sample(sample) -> None:
        pending.append((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))
        with wake:
            wake.notify()

    key = f"superbody/{site}/**" if site else "superbody/**"
    end = None if duration_s is None else time.monotonic() + duration_s
    with open(out, "wb") as f, zenoh.open(conf) as session:
        rec = Recorder(f)
        sub = session.declare_subscriber(key, on_sample)
        log.info("recording %s into %s", key, out)
        try:
            while not stop.is_set() and (end is None or time.monotonic() < end):
                with wake:
                    if not pending:
                        wake.wait(timeout=0.1)
                while pending:
                    rec.add(*pending.popleft())
        finally:
            sub.undeclare()
            while pending:
                rec.add(*pending.popleft())
            rec.close()
    return dict(rec.counts)


