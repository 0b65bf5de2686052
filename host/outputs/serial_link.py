"""The serial link: each tick's poses as one compact binary frame, for robot microcontrollers.

A frame (little-endian, no padding; the byte-by-byte layout and a C struct are in
``docs/pose-schema.md``)::

    sync 0xA5 0x5A | version u8 | length u16 | payload (length bytes) | crc u16
    payload = seq u32, stamp_ms u64, count u8, then count x 18-byte person records:
              id u16, x_mm i32, y_mm i32, yaw_mrad i16, vx_mm_s i16, vy_mm_s i16,
              confidence u8 (0-255), views u8
    crc = CRC-16/CCITT-FALSE over every byte before it, from the first sync byte

Why a sync word, a length and a CRC rather than COBS: every frame has a size known from its
header and its records can be read in place as a packed struct; a receiver is a five-state
loop with no unstuffing buffer. A sync pattern that happens to occur inside a payload costs one
failed CRC check and a rescan from the next byte, so receivers resynchronise by themselves.

Values are scaled, rounded and clamped to their fields (each clamp counted); ``seq`` wraps
modulo 2^32 and ``id`` modulo 2^16 (a clamped id would merge people; a wrapped one stays
distinct unless two live tracks are 65536 ids apart).
"""

from __future__ import annotations

import binascii
import logging
import math
import os
import socket
import struct
import threading
import time
from collections import Counter, deque
from typing import Any, Final, NamedTuple

import numpy as np
import serial

from superbody.host.messages.pose import PoseArray

__all__ = [
    "SYNC",
    "VERSION",
    "HEADER_BYTES",
    "PERSON_BYTES",
    "MAX_FRAME_PEOPLE",
    "MAX_FRAME_BYTES",
    "PERSON_DTYPE",
    "Frame",
    "FrameError",
    "SerialLinkError",
    "crc16_ccitt_false",
    "frame_size",
    "pack_frame",
    "unpack_frame",
    "FrameReader",
    "SerialLink",
]

log = logging.getLogger(__name__)

SYNC: Final[bytes] = b"\xa5\x5a"
VERSION: Final[int] = 1
_HEAD = struct.Struct("<2sBH")  # sync, version, payload length
_PAYLOAD_HEAD = struct.Struct("<IQB")  # seq, stamp_ms, count
_CRC = struct.Struct("<H")
HEADER_BYTES: Final[int] = _HEAD.size  # 5
# Packed little-endian person record; numpy structured dtypes have no padding unless asked.
PERSON_DTYPE: Final = np.dtype([
    ("id", "<u2"),
    ("x_mm", "<i4"),
    ("y_mm", "<i4"),
    ("yaw_mrad", "<i2"),
    ("vx_mm_s", "<i2"),
    ("vy_mm_s", "<i2"),
    ("confidence", "u1"),
    ("views", "u1"),
])
PERSON_BYTES: Final[int] = PERSON_DTYPE.itemsize  # 18
MAX_FRAME_PEOPLE: Final[int] = 64  # host.messages.pose.MAX_PEOPLE: a receiver's buffer is MAX_FRAME_BYTES
_MIN_PAYLOAD: Final[int] = _PAYLOAD_HEAD.size  # 13
_MAX_PAYLOAD: Final[int] = _MIN_PAYLOAD + MAX_FRAME_PEOPLE * PERSON_BYTES
MAX_FRAME_BYTES: Final[int] = HEADER_BYTES + _MAX_PAYLOAD + _CRC.size  # 1172

# Record field <- PoseArray attribute, scale to the integer unit.
_SCALED: Final[tuple[tuple[str, str, float], ...]] = (
    ("x_mm", "x", 1000.0),
    ("y_mm", "y", 1000.0),
    ("yaw_mrad", "yaw", 1000.0),
    ("vx_mm_s", "vx", 1000.0),
    ("vy_mm_s", "vy", 1000.0),
    ("confidence", "confidence", 255.0),
)


class Frame(NamedTuple):
    """One decoded frame: people are dicts of id, x, y (m), yaw (rad), vx, vy (m/s), confidence ([0, 1]), views."""

    seq: int
    stamp_ms: int
    people: list[dict[str, Any]]


class FrameError(ValueError):
    """Bytes that are not one valid frame.

    Attributes:
        reason: ``"sync"``, ``"version"``, ``"length"``, ``"crc"`` or ``"count"``.
    """

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail

    def __reduce__(self):
        return (type(self), (self.reason, self.detail))


class SerialLinkError(OSError):
    """The serial port could not be opened; the message names the URL."""


def crc16_ccitt_false(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor (check 0x29B1)."""
    # binascii's CRC-CCITT is exactly this polynomial and bit order, in C.
    return binascii.crc_hqx(data, crc)


def frame_size(count: int) -> int:
    """Bytes in a frame with ``count`` people: 20 + 18 * count."""
    return HEADER_BYTES + _MIN_PAYLOAD + count * PERSON_BYTES + _CRC.size


def _clamped(values: np.ndarray, lo: float, hi: float, field: str, clamps: Counter | None) -> np.ndarray:
    """Round to integers in [lo, hi]; NaN becomes 0. Each value changed by more than rounding counts one clamp."""
    bad = np.isnan(values)
    rounded = np.rint(np.where(bad, 0.0, values))
    out = np.clip(rounded, lo, hi)
    if clamps is not None:
        n = int(bad.sum() + (out != rounded).sum())
        if n:
            clamps[field] += n
    return out


def pack_frame(poses: PoseArray, *, clamps: Counter | None = None) -> bytes:
    """One frame for ``poses`` (``frame_size(len(poses.people))`` bytes, at most ``MAX_FRAME_BYTES``).

    Args:
        poses: the tick's poses. People beyond ``MAX_FRAME_PEOPLE`` are left out.
        clamps: if given, the number of values clamped to their field's range (NaN counts, as 0)
            is added per field name (``"x_mm"``, ..., ``"count"``, ``"stamp_ms"``).
    """
    people = poses.people[:MAX_FRAME_PEOPLE]
    if clamps is not None and len(poses.people) > MAX_FRAME_PEOPLE:
        clamps["count"] += len(poses.people) - MAX_FRAME_PEOPLE
    records = np.zeros(len(people), dtype=PERSON_DTYPE)
    if people:
        records["id"] = [int(p.id) % 2**16 for p in people]
        for field, attr, scale in _SCALED:
            values = np.array([getattr(p, attr) for p in people], dtype=np.float64)
            if attr == "yaw":
                values = math.pi - np.mod(math.pi - values, 2 * math.pi)  # wrap to (-pi, pi]
            info = np.iinfo(PERSON_DTYPE[field])
            records[field] = _clamped(values * scale, info.min, info.max, field, clamps)
        views = np.array([p.views for p in people], dtype=np.float64)
        records["views"] = _clamped(views, 0, 255, "views", clamps)
    stamp_ms = int(poses.stamp_ns) // 1_000_000
    if not 0 <= stamp_ms < 2**64:
        if clamps is not None:
            clamps["stamp_ms"] += 1
        stamp_ms = min(max(stamp_ms, 0), 2**64 - 1)
    payload = _PAYLOAD_HEAD.pack(int(poses.seq) % 2**32, stamp_ms, len(people)) + records.tobytes()
    frame = _HEAD.pack(SYNC, VERSION, len(payload)) + payload
    return frame + _CRC.pack(crc16_ccitt_false(frame))


def _check_header(data: bytes | bytearray | memoryview, offset: int = 0) -> int:
    """The payload length of the frame header at ``offset``; FrameError if it cannot start a frame."""
    sync, version, length = _HEAD.unpack_from(data, offset)
    if sync != SYNC:
        raise FrameError("sync", f"frame must start with {SYNC.hex(' ')}, got {bytes(sync).hex(' ')}")
    if version != VERSION:
        raise FrameError("version", f"version {version} is not supported; this decoder reads version {VERSION}")
    if not _MIN_PAYLOAD <= length <= _MAX_PAYLOAD or (length - _MIN_PAYLOAD) % PERSON_BYTES:
        raise FrameError("length", f"payload length must be 13 + 18 * count with count <= {MAX_FRAME_PEOPLE}, got {length}")
    return length


def unpack_frame(data: bytes | bytearray | memoryview) -> Frame:
    """Decode exactly one frame (the reference decoder).

    Returns:
        ``Frame(seq, stamp_ms, people)``, people as dicts in SI units: ``id``, ``x``, ``y`` (m),
        ``yaw`` (rad), ``vx``, ``vy`` (m/s), ``confidence`` ([0, 1]), ``views``.

    Raises:
        FrameError: with ``reason`` ``"sync"``, ``"version"``, ``"length"`` (header length out of
            range, or not the size of ``data``), ``"crc"`` or ``"count"`` (count disagrees with length).
    """
    data = memoryview(data).cast("B")
    if len(data) < HEADER_BYTES:
        raise FrameError("length", f"a frame has at least {frame_size(0)} bytes, got {len(data)}")
    length = _check_header(data)
    if len(data) != HEADER_BYTES + length + _CRC.size:
        raise FrameError("length", f"header says {HEADER_BYTES + length + _CRC.size} bytes, got {len(data)}")
    body_end = HEADER_BYTES + length
    (crc,) = _CRC.unpack_from(data, body_end)
    actual = crc16_ccitt_false(data[:body_end])
    if crc != actual:
        raise FrameError("crc", f"CRC is 0x{crc:04X}, the bytes give 0x{actual:04X}")
    seq, stamp_ms, count = _PAYLOAD_HEAD.unpack_from(data, HEADER_BYTES)
    if length != _MIN_PAYLOAD + count * PERSON_BYTES:
        raise FrameError("count", f"count {count} needs a payload of {_MIN_PAYLOAD + count * PERSON_BYTES} bytes, length is {length}")
    records = np.frombuffer(data, dtype=PERSON_DTYPE, count=count, offset=HEADER_BYTES + _MIN_PAYLOAD)
    people = [
        {
            "id": int(r["id"]),
            "x": int(r["x_mm"]) / 1000.0,
            "y": int(r["y_mm"]) / 1000.0,
            "yaw": int(r["yaw_mrad"]) / 1000.0,
            "vx": int(r["vx_mm_s"]) / 1000.0,
            "vy": int(r["vy_mm_s"]) / 1000.0,
            "confidence": int(r["confidence"]) / 255.0,
            "views": int(r["views"]),
        }
        for r in records
    ]
    return Frame(seq, stamp_ms, people)


class FrameReader:
    """Finds frames in a byte stream: feed it whatever the port returns, get whole frames back.

    Garbage, truncated frames and corrupted frames are skipped: after any bad candidate the
    search restarts one byte after its sync word, so a real frame hidden behind a false sync is
    still found. At most ``MAX_FRAME_BYTES - 1`` bytes are kept between calls.

    Attributes:
        stats: ``frames`` decoded, ``bad_header`` (sync followed by an impossible version or
            length), ``bad_crc`` (CRC or count mismatch), ``skipped_bytes`` (bytes not in a frame).
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats: dict[str, int] = {"frames": 0, "bad_header": 0, "bad_crc": 0, "skipped_bytes": 0}

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame (always < MAX_FRAME_BYTES)."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Append ``data`` and return the frames completed by it, oldest first."""
        buf = self._buf
        buf += data
        frames: list[Frame] = []
        start = 0  # consume by index and trim once: no quadratic deletes on a long garbage run
        while True:
            i = buf.find(SYNC, start)
            if i < 0:
                # Keep a trailing first sync byte: the second may come in the next read.
                keep = max(start, len(buf) - 1) if buf[-1:] == SYNC[:1] else len(buf)
                self.stats["skipped_bytes"] += keep - start
                start = keep
                break
            self.stats["skipped_bytes"] += i - start
            start = i
            if len(buf) - start < HEADER_BYTES:
                break
            try:
                length = _check_header(buf, start)
            except FrameError:
                self.stats["bad_header"] += 1
                self.stats["skipped_bytes"] += 1
                start += 1
                continue
            end = start + HEADER_BYTES + length + _CRC.size
            if len(buf) < end:
                break  # wait for the rest (at most MAX_FRAME_BYTES in all)
            try:
                frames.append(unpack_frame(bytes(buf[start:end])))  # a copy: buf is resized below
            except FrameError:
                self.stats["bad_crc"] += 1
                self.stats["skipped_bytes"] += 1
                start += 1
                continue
            self.stats["frames"] += 1
            start = end
        del buf[:start]
        return frames


class SerialLink:
    """Writes each tick's frame to a serial port without ever blocking the host.

    Frames wait in a small buffer (``buffer_frames``); when it is full the oldest waiting frame
    is dropped (counted), because the robot wants the newest poses, not a backlog. Each
    ``send`` writes what the port takes *now*: the bytes go out through a non-blocking
    ``os.write`` on the port's descriptor (or ``MSG_DONTWAIT`` on a ``socket://`` port), never
    through pyserial's ``write``, which spins on a full kernel buffer (a paused reader once
    stopped the host's publishing for 9.4 s). A frame partly written is finished before the
    next starts, so no frame is ever cut. A frame is started only while the port's output
    queue holds at most ``max_backlog`` bytes.

    When a write fails (the adapter was unplugged, the peer closed), a port this link opened is
    closed and reopened in a background thread every ``reconnect_s`` until it works; frames
    keep going to the buffer meanwhile. Not thread-safe: call ``send`` from one thread.

    Args:
        url: a pyserial URL or device (``/dev/ttyUSB0``, ``COM3``, ``loop://``,
            ``socket://host:port``), opened with ``timeout=0, write_timeout=0``; or an
            already-open ``serial.SerialBase``, used as it is, not closed by ``close()`` and
            not reopened.
        baudrate: bits per second (8N1: a 10-person frame of 200 bytes takes 17 ms at 115200).
        max_backlog: bytes allowed in the port's output queue when a frame is started.
        buffer_frames: frames allowed to wait besides the one being written.
        reconnect_s: seconds between attempts to reopen a failed port.

    Attributes:
        port: the ``serial.SerialBase`` in use (None while reconnecting).
        stats: ``sent`` (frames written whole), ``dropped`` (oldest frames pushed out of the
            buffer), ``errors`` (writes that raised), ``reconnects`` (ports reopened),
            ``clamped`` (values clamped in all).
        clamps: clamped values per frame field.

    Raises:
        SerialLinkError: the port cannot be opened at first; the message names the URL.
    """

    def __init__(self, url: str | serial.SerialBase, baudrate: int = 115200, *, max_backlog: int = 0,
                 buffer_frames: int = 2, reconnect_s: float = 1.0) -> None:
        if not 1 <= buffer_frames <= 1000:
            raise ValueError(f"SerialLink buffer_frames must be in [1, 1000], got {buffer_frames!r}")
        if not (isinstance(reconnect_s, (int, float)) and 0.01 <= reconnect_s <= 3600):
            raise ValueError(f"SerialLink reconnect_s must be in [0.01, 3600] seconds, got {reconnect_s!r}")
        self.baudrate = baudrate
        if not isinstance(url, str):  # an open port (or a fake with write and out_waiting)
            self.port: serial.SerialBase | None = url
            self.url = str(getattr(url, "port", url))
            self._owned = False
        else:
            self.url = url
            self._owned = True
            self.port = self._open()
        self.max_backlog = max_backlog
        self.buffer_frames = buffer_frames
        self.reconnect_s = float(reconnect_s)
        self.stats: dict[str, int] = {"sent": 0, "dropped": 0, "errors": 0, "reconnects": 0, "clamped": 0}
        self.clamps: Counter[str] = Counter()
        self._frames: deque[bytes] = deque()  # waiting frames, oldest first
        self._head_done = 0  # bytes of _frames[0] already written
        self._failing = False
        self._reopening: threading.Thread | None = None
        self._next_try = 0.0
        self._closed = False

    def _open(self) -> serial.SerialBase:
        try:
            return serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0, write_timeout=0)
        except (serial.SerialException, OSError, ValueError) as e:
            raise SerialLinkError(f"cannot open serial port {self.url!r} at {self.baudrate} baud: {e}") from e

    @property
    def pending(self) -> int:
        """Frames waiting to be written (the one partly written included)."""
        return len(self._frames)

    def _backlog(self, port) -> int:
        try:
            return int(port.out_waiting)
        except (NotImplementedError, AttributeError, OSError, serial.SerialException):  # some handlers cannot tell
            return 0

    def _write_some(self, port, data: bytes) -> int:
        """Write what the port takes now, without blocking or spinning; the bytes written."""
        sock = getattr(port, "_socket", None)  # pyserial's socket:// handler
        if sock is not None:
            try:
                return sock.send(data, socket.MSG_DONTWAIT)
            except BlockingIOError:
                return 0
        try:
            fd = port.fileno()
        except (AttributeError, NotImplementedError, OSError, serial.SerialException):
            fd = None
        if fd is not None:
            try:
                return os.write(fd, data)  # pyserial opens ports with O_NONBLOCK
            except BlockingIOError:
                return 0
        try:  # loop:// and other handlers: their own write, told not to wait
            n = port.write(data)
        except serial.SerialTimeoutException:
            return 0
        return len(data) if n is None else int(n)

    def publish(self, poses: PoseArray) -> None:
        """The host's ``Sink`` interface (host/outputs/): ``send``, whether or not the port took it all now."""
        self.send(poses)

    def send(self, poses: PoseArray) -> bool:
        """Queue ``poses`` as one frame and write what the port takes now.

        Returns:
            True if this frame was written whole during this call.
        """
        before = sum(self.clamps.values())
        frame = pack_frame(poses, clamps=self.clamps)
        self.stats["clamped"] += sum(self.clamps.values()) - before
        self._frames.append(frame)
        # Drop the oldest waiting frame, never the one partly written (it would arrive cut).
        while len(self._frames) > self.buffer_frames + (1 if self._head_done else 0):
            del self._frames[1 if self._head_done else 0]
            self.stats["dropped"] += 1
        sent_before = self.stats["sent"]
        port = self.port
        if port is None:
            self._reopen_later()
            return False
        try:
            while self._frames:
                head = self._frames[0]
                if self._head_done == 0 and self._backlog(port) > self.max_backlog:
                    break
                n = self._write_some(port, head[self._head_done:])
                if n <= 0:
                    break
                self._head_done += n
                if self._head_done < len(head):
                    break  # the port took part of it: the rest goes first next time
                self._frames.popleft()
                self._head_done = 0
                self.stats["sent"] += 1
        except (serial.SerialException, OSError) as e:
            self._failed(e)
            return False
        if self._failing:
            log.info("serial link %s: writing again after %d errors", self.url, self.stats["errors"])
            self._failing = False
        return self.stats["sent"] > sent_before and not any(f is frame for f in self._frames)

    def _failed(self, e: Exception) -> None:
        self.stats["errors"] += 1
        if not self._failing:
            log.warning("serial link %s: write failed (%s); frames are buffered (newest %d kept)%s", self.url, e,
                        self.buffer_frames, ", reopening it" if self._owned else "")
            self._failing = True
        self._head_done = 0  # whatever was cut is skipped by the receiver (CRC); resend it whole
        if self._owned:
            port, self.port = self.port, None
            try:
                assert port is not None  # send() only writes to an open port
                port.close()
            except Exception:  # closing a dead port may fail too; it is gone either way
                pass
            self._next_try = time.monotonic() + self.reconnect_s
            self._reopen_later()

    def _reopen_later(self) -> None:
        """Start one background attempt to reopen the port, if it is time (never blocks)."""
        if not self._owned or self._closed or (self._reopening is not None and self._reopening.is_alive()):
            return
        if time.monotonic() < self._next_try:
            return
        self._next_try = time.monotonic() + self.reconnect_s
        self._reopening = threading.Thread(target=self._reopen, name="serial-reopen", daemon=True)
        self._reopening.start()

    def _reopen(self) -> None:
        try:
            port = self._open()
        except SerialLinkError:
            return
        if self._closed:
            port.close()
            return
        self.stats["reconnects"] += 1
        log.info("serial link %s: reopened", self.url)
        self.port = port

    def close(self) -> None:
        """Close the port if this link opened it."""
        self._closed = True
        if self._owned and self.port is not None:
            self.port.close()

    def __enter__(self) -> SerialLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
