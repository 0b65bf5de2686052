"""Tests of the serial frame and link (host/outputs/serial_link.py): pack/unpack, clamping, corruption,
stream resynchronisation, and the link over pyserial's real ``loop://`` port."""

from __future__ import annotations

import math
import re
from collections import Counter
from typing import Any

import numpy as np
import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from superbody.host.messages.pose import PersonPose, PoseArray, decode
from superbody.host.outputs.serial_link import (
    MAX_FRAME_BYTES,
    MAX_FRAME_PEOPLE,
    PERSON_BYTES,
    PERSON_DTYPE,
    SYNC,
    Frame,
    FrameError,
    FrameReader,
    SerialLink,
    SerialLinkError,
    crc16_ccitt_false,
    frame_size,
    pack_frame,
    unpack_frame,
)
from tests.conftest import ROOT

DOCS = ROOT / "docs" / "pose-schema.md"
STAMP = 1_718_000_000_123_456_789


def person(pid: int = 1, **change: Any) -> PersonPose:
    fields = dict(id=pid, x=1.0, y=-2.0, yaw=0.5, vx=0.3, vy=-0.1, yaw_rate=0.0, cov=np.eye(3) * 0.01,
                  confidence=0.8, cameras=("cam-1",), stamp_ns=STAMP, views=1)
    return PersonPose(**{**fields, **change})


def make_poses(n: int = 3, seed: int = 0, seq: int = 42) -> PoseArray:
    rng = np.random.default_rng(seed)
    people = tuple(
        person(i, x=float(rng.uniform(-20, 20)), y=float(rng.uniform(-20, 20)), yaw=float(rng.uniform(-math.pi, math.pi)),
               vx=float(rng.normal(0, 2)), vy=float(rng.normal(0, 2)), confidence=float(rng.uniform(0, 1)),
               views=int(rng.integers(0, 9)))
        for i in range(n)
    )
    return PoseArray("lab", seq, STAMP, people)


def assert_frame_close(poses: PoseArray, frame: Frame) -> None:
    """The frame holds ``poses`` up to the documented rounding."""
    assert frame.seq == poses.seq % 2**32
    assert frame.stamp_ms == poses.stamp_ns // 1_000_000
    assert len(frame.people) == len(poses.people)
    for p, q in zip(poses.people, frame.people):
        assert (q["id"], q["views"]) == (p.id % 2**16, p.views)
        for attr in ("x", "y", "vx", "vy"):
            assert abs(q[attr] - getattr(p, attr)) <= 5e-4 + 1e-12, attr  # 1 mm, 1 mm/s
        assert abs((q["yaw"] - p.yaw + math.pi) % (2 * math.pi) - math.pi) <= 5e-4 + 1e-12  # 1 mrad
        assert abs(q["confidence"] - p.confidence) <= 0.5 / 255 + 1e-12


# --- the format ----------------------------------------------------------------------------


def test_crc_is_ccitt_false() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1  # the catalogue's check value
    assert crc16_ccitt_false(b"") == 0xFFFF


def test_sizes() -> None:
    assert PERSON_BYTES == PERSON_DTYPE.itemsize == 18
    assert (frame_size(0), frame_size(10)) == (20, 200)
    assert MAX_FRAME_BYTES == frame_size(MAX_FRAME_PEOPLE) == 1172
    assert len(pack_frame(make_poses(10))) == 200


def test_byte_layout() -> None:
    """The documented offsets, read back by hand."""
    poses = PoseArray("lab", 0x01020304, 1_718_000_000_123_999_999, (person(0xBEEF, x=-0.001, yaw=-0.5, views=3),))
    f = pack_frame(poses)
    assert f[:2] == SYNC and f[2] == 1 and int.from_bytes(f[3:5], "little") == 13 + 18
    assert f[5:9] == bytes([4, 3, 2, 1])                                       # seq, little-endian
    assert int.from_bytes(f[9:17], "little") == 1_718_000_000_123              # stamp_ms, floored
    assert f[17] == 1                                                          # count
    rec = f[18:36]
    assert int.from_bytes(rec[0:2], "little") == 0xBEEF                        # id
    assert int.from_bytes(rec[2:6], "little", signed=True) == -1               # x_mm
    assert int.from_bytes(rec[6:10], "little", signed=True) == -2000           # y_mm
    assert int.from_bytes(rec[10:12], "little", signed=True) == -500           # yaw_mrad
    assert (rec[16], rec[17]) == (round(0.8 * 255), 3)                         # confidence, views
    assert int.from_bytes(f[36:38], "little") == crc16_ccitt_false(f[:36])    # CRC over all before it


@pytest.mark.parametrize("n", [0, 1, 10, MAX_FRAME_PEOPLE])  # nobody, one, a busy room, the limit
def test_round_trip(n: int) -> None:
    poses = make_poses(n, seed=n)
    clamps: Counter = Counter()
    frame = unpack_frame(pack_frame(poses, clamps=clamps))
    assert_frame_close(poses, frame)
    assert not clamps


@settings(max_examples=300, deadline=None, database=None)
@given(
    st.lists(st.tuples(st.floats(-2000, 2000), st.floats(-2000, 2000), st.floats(-math.pi, math.pi),
                       st.floats(-32, 32), st.floats(-32, 32), st.floats(0, 1), st.integers(0, 255)), max_size=5),
    st.integers(0, 2**40), st.integers(0, 2**63 - 1),
)
def test_round_trip_property(people: list[tuple], seq: int, stamp_ns: int) -> None:
    poses = PoseArray("lab", seq, stamp_ns, tuple(
        person(i, x=x, y=y, yaw=yaw, vx=vx, vy=vy, confidence=c, views=v) for i, (x, y, yaw, vx, vy, c, v) in enumerate(people)))
    assert_frame_close(poses, unpack_frame(pack_frame(poses)))


# --- clamping ------------------------------------------------------------------------------

CLAMPS = [
    # (change to one person, field in the frame, value in the frame, clamps counted)
    pytest.param({"x": 3e6}, "x", 2147483.647, {"x_mm": 1}, id="x-beyond-i32"),
    pytest.param({"y": -3e6}, "y", -2147483.648, {"y_mm": 1}, id="y-below-i32"),
    pytest.param({"vx": 40.0}, "vx", 32.767, {"vx_mm_s": 1}, id="vx-beyond-i16"),
    pytest.param({"vy": -float("inf")}, "vy", -32.768, {"vy_mm_s": 1}, id="vy-minus-infinity"),
    pytest.param({"x": float("nan")}, "x", 0.0, {"x_mm": 1}, id="nan-becomes-0"),
    pytest.param({"confidence": 1.5}, "confidence", 1.0, {"confidence": 1}, id="confidence-above-1"),
    pytest.param({"confidence": -0.2}, "confidence", 0.0, {"confidence": 1}, id="confidence-negative"),
    pytest.param({"views": 300}, "views", 255, {"views": 1}, id="views-beyond-u8"),
    pytest.param({"vx": 32.7674}, "vx", 32.767, {}, id="rounding-is-not-a-clamp"),
    pytest.param({"yaw": 4.0}, "yaw", round(4.0 - 2 * math.pi, 3), {}, id="yaw-wrapped-not-clamped"),
    pytest.param({"yaw": -math.pi}, "yaw", 3.142, {}, id="yaw-minus-pi-is-pi"),
    pytest.param({"id": 70_000}, "id", 70_000 - 65_536, {}, id="id-wraps-mod-2^16"),
]


@pytest.mark.parametrize("change, field, value, counted", CLAMPS)
def test_values_are_clamped_and_counted(change: dict, field: str, value: float, counted: dict) -> None:
    clamps: Counter = Counter()
    frame = unpack_frame(pack_frame(PoseArray("lab", 1, STAMP, (person(**change),)), clamps=clamps))
    assert frame.people[0][field] == pytest.approx(value, abs=1e-9)
    assert dict(clamps) == counted


def test_header_values_wrap_or_clamp() -> None:
    clamps: Counter = Counter()
    poses = PoseArray("lab", 2**32 + 5, -1, tuple(person(i) for i in range(MAX_FRAME_PEOPLE + 3)))
    frame = unpack_frame(pack_frame(poses, clamps=clamps))
    assert (frame.seq, frame.stamp_ms, len(frame.people)) == (5, 0, MAX_FRAME_PEOPLE)  # seq wraps, people cut
    assert dict(clamps) == {"count": 3, "stamp_ms": 1}


# --- bad frames ----------------------------------------------------------------------------


def recrc(frame: bytes | bytearray) -> bytes:
    """``frame`` with its CRC recomputed, to reach the checks behind the CRC."""
    body = bytes(frame[:-2])
    return body + crc16_ccitt_false(body).to_bytes(2, "little")


GOOD = pack_frame(make_poses(2))

BAD_FRAMES = [
    pytest.param(b"", "length", id="empty"),
    pytest.param(GOOD[:4], "length", id="shorter-than-header"),
    pytest.param(GOOD[:-1], "length", id="truncated"),
    pytest.param(GOOD + b"\x00", "length", id="one-byte-too-many"),
    pytest.param(b"\x5a\xa5" + GOOD[2:], "sync", id="sync-swapped"),
    pytest.param(recrc(GOOD[:2] + b"\x02" + GOOD[3:]), "version", id="version-2"),
    pytest.param(recrc(GOOD[:3] + (14).to_bytes(2, "little") + GOOD[5:19] + b"\x00\x00"), "length", id="length-not-13-plus-18k"),
    pytest.param(recrc(GOOD[:3] + (13 + 18 * 65).to_bytes(2, "little") + GOOD[5:] + bytes(18 * 63)), "length", id="more-than-64-people"),
    pytest.param(recrc(GOOD[:17] + b"\x03" + GOOD[18:]), "count", id="count-disagrees-with-length"),
    pytest.param(GOOD[:-2] + bytes([GOOD[-2] ^ 1, GOOD[-1]]), "crc", id="crc-bit-flipped"),
]


@pytest.mark.parametrize("data, reason", BAD_FRAMES)
def test_bad_frame_names_what_is_wrong(data: bytes, reason: str) -> None:
    with pytest.raises(FrameError) as info:
        unpack_frame(data)
    assert info.value.reason == reason
    assert str(info.value).startswith(f"{reason}: ")


def test_every_single_bit_flip_is_detected() -> None:
    for i in range(len(GOOD)):
        for bit in range(8):
            bad = bytearray(GOOD)
            bad[i] ^= 1 << bit
            with pytest.raises(FrameError) as info:
                unpack_frame(bytes(bad))
            expected = {0: "sync", 1: "sync", 2: "version", 3: "length", 4: "length"}.get(i, "crc")
            assert info.value.reason == expected, (i, bit, str(info.value))


# --- the stream reader ---------------------------------------------------------------------


def frames_of(n: int, people: int = 2) -> list[bytes]:
    return [pack_frame(make_poses(people, seed=k, seq=k)) for k in range(n)]


def test_reader_finds_frames_between_garbage() -> None:
    fs = frames_of(3)
    stream = b"hello\xa5" + fs[0] + b"\x00\x5a\xa5" + fs[1] + SYNC + b"\x01" + fs[2] + b"\xa5"
    reader = FrameReader()
    assert [f.seq for f in reader.feed(stream)] == [0, 1, 2]
    assert reader.stats["frames"] == 3
    assert reader.buffered == 1  # the trailing 0xA5 might start a sync word


def test_reader_handles_split_reads() -> None:
    fs = frames_of(3)
    stream = b"".join(fs)
    for size in (1, 2, 5, 7, 19, 64):  # chunks cutting the sync word, header, records and CRC
        reader = FrameReader()
        got = [f for k in range(0, len(stream), size) for f in reader.feed(stream[k : k + size])]
        assert [f.seq for f in got] == [0, 1, 2], size
        assert (reader.buffered, reader.stats["skipped_bytes"]) == (0, 0)


def test_reader_recovers_a_frame_behind_a_false_header() -> None:
    """A sync word with a plausible header in the garbage must not swallow the next real frame."""
    fake = SYNC + b"\x01" + (13 + 18 * 3).to_bytes(2, "little") + b"\x00" * 7  # claims 74 payload bytes
    real = frames_of(1)[0]
    reader = FrameReader()
    assert reader.feed(fake + real) == []  # still waiting: the false frame is not complete yet
    got = reader.feed(bytes(MAX_FRAME_BYTES))
    assert [f.seq for f in got] == [0]
    assert reader.stats["bad_crc"] == 1


def test_reader_skips_corrupted_frame_and_keeps_the_next() -> None:
    fs = frames_of(3)
    bad = bytearray(fs[1])
    bad[30] ^= 0x10
    reader = FrameReader()
    assert [f.seq for f in reader.feed(fs[0] + bytes(bad) + fs[2])] == [0, 2]
    assert reader.stats["bad_crc"] >= 1


def test_reader_buffer_stays_bounded() -> None:
    reader = FrameReader()
    header = SYNC + b"\x01" + (13 + 18 * 64).to_bytes(2, "little")  # each claims a maximal frame
    rng = np.random.default_rng(0)
    for _ in range(200):
        reader.feed(header + rng.bytes(int(rng.integers(0, 700))))
        assert reader.buffered < MAX_FRAME_BYTES
    assert reader.feed(bytes(MAX_FRAME_BYTES) + frames_of(1)[0])[0].seq == 0


@settings(max_examples=200, deadline=None, database=None)
@given(st.lists(st.tuples(st.binary(max_size=60), st.integers(0, 4)), min_size=1, max_size=5), st.integers(1, 300))
def test_reader_recovers_every_frame_from_garbage(parts: list[tuple[bytes, int]], chunk: int) -> None:
    stream = b"".join(g + pack_frame(make_poses(n, seed=k, seq=k)) for k, (g, n) in enumerate(parts))
    stream += bytes(MAX_FRAME_BYTES)  # enough to finish any false frame the last garbage began
    reader = FrameReader()
    got = [f for k in range(0, len(stream), chunk) for f in reader.feed(stream[k : k + chunk])]
    assert [f.seq for f in got] == list(range(len(parts)))


# --- the link ------------------------------------------------------------------------------


@pytest.fixture
def loop_port():
    port = serial.serial_for_url("loop://", timeout=0)
    yield port
    port.close()


def test_link_end_to_end_over_loop_port(loop_port: serial.SerialBase) -> None:
    link = SerialLink(loop_port)
    reader = FrameReader()
    sent = [make_poses(n, seed=n, seq=n) for n in (0, 1, 10)]
    got = []
    for poses in sent:
        assert link.send(poses)
        got += reader.feed(loop_port.read(4096))
    assert len(got) == 3
    for poses, frame in zip(sent, got):
        assert_frame_close(poses, frame)
    assert link.stats == {"sent": 3, "dropped": 0, "errors": 0, "reconnects": 0, "clamped": 0}
    link.close()
    assert loop_port.is_open  # a port passed in belongs to the caller


def test_link_keeps_the_newest_frames_while_the_port_is_busy(loop_port: serial.SerialBase) -> None:
    """Nothing read yet: the first frame still waits in the port; later ones wait in the buffer,
    the oldest pushed out, and the newest goes as soon as the port has room."""
    link = SerialLink(loop_port, buffer_frames=1)
    assert link.send(make_poses(1, seq=1))
    assert not link.send(make_poses(1, seq=2)) and link.pending == 1
    assert not link.send(make_poses(1, seq=3)) and link.pending == 1  # 2 dropped: 3 is newer
    assert [f.seq for f in FrameReader().feed(loop_port.read(4096))] == [1]
    assert link.send(make_poses(1, seq=4))  # 3 was pushed out by 4 (a buffer of one)
    assert [f.seq for f in FrameReader().feed(loop_port.read(4096))] == [4]
    assert link.stats == {"sent": 2, "dropped": 2, "errors": 0, "reconnects": 0, "clamped": 0}


def test_link_with_backlog_allowance_queues_frames(loop_port: serial.SerialBase) -> None:
    link = SerialLink(loop_port, max_backlog=1000)
    for k in range(3):
        assert link.send(make_poses(2, seq=k))
    assert [f.seq for f in FrameReader().feed(loop_port.read(4096))] == [0, 1, 2]


def test_link_opened_by_url_is_non_blocking() -> None:
    """pyserial's loop:// with write_timeout=0 refuses every write as one that would block."""
    with SerialLink("loop://", baudrate=57600) as link:
        assert (link.port.timeout, link.port.write_timeout, link.port.baudrate) == (0, 0, 57600)
        assert not link.send(make_poses(2)) and link.pending == 1
        assert link.stats == {"sent": 0, "dropped": 0, "errors": 0, "reconnects": 0, "clamped": 0}
    assert not link.port.is_open  # a port it opened, it closes


def test_link_counts_errors_and_never_raises(loop_port: serial.SerialBase) -> None:
    link = SerialLink(loop_port)
    loop_port.close()  # as if the adapter was unplugged
    for _ in range(3):
        assert not link.send(make_poses(1))
    assert link.stats == {"sent": 0, "dropped": 1, "errors": 3, "reconnects": 0, "clamped": 0}
    assert link.pending == 2  # the newest, kept for when it works again


class ShortWrites:
    """A port whose driver takes only part of each write (a fake, not a mock)."""

    port = "fake://short"
    out_waiting = 0

    def __init__(self) -> None:
        self.written = b""

    def write(self, data: bytes) -> int:
        self.written += data[:7]
        return min(7, len(data))


def test_a_partly_written_frame_is_finished_never_cut() -> None:
    port = ShortWrites()
    link = SerialLink(port, buffer_frames=1)
    first = make_poses(1, seq=1)
    assert not link.send(first)  # 7 bytes out, the rest waits
    assert FrameReader().feed(port.written) == []
    sends = 1
    while link.stats["sent"] == 0 and sends < 100:  # bounded
        link.send(make_poses(1, seq=100 + sends))  # newer frames push each other out, never the cut one
        sends += 1
    (frame,) = FrameReader().feed(port.written)
    assert frame.seq == 1 and link.stats["dropped"] == sends - 2


def test_link_counts_clamps() -> None:
    port = ShortWrites()
    port.write = lambda data: len(data)  # type: ignore[method-assign]
    link = SerialLink(port)
    link.send(PoseArray("lab", 1, STAMP, (person(1, vx=50.0, views=999), person(2, vy=-50.0))))
    assert link.stats["clamped"] == 3
    assert link.clamps == Counter({"vx_mm_s": 1, "views": 1, "vy_mm_s": 1})


@pytest.mark.parametrize("url", ["/dev/superbody-no-such-port", "nosuchscheme://x"])
def test_unopenable_port_names_the_url(url: str) -> None:
    with pytest.raises(SerialLinkError, match=re.escape(repr(url))):
        SerialLink(url)


# --- the documented example ----------------------------------------------------------------


def test_docs_example_frame_is_the_json_example_packed() -> None:
    """docs/pose-schema.md shows the JSON example and its serial frame: they must agree."""
    text = DOCS.read_text(encoding="utf-8")
    doc = re.search(r"```json\n(.*?)\n```", text, re.S)
    hexdump = re.search(r"```text\n# serial frame\n(.*?)\n```", text, re.S)
    assert doc and hexdump, "docs/pose-schema.md needs the ```json example and the ```text # serial frame hex dump"
    frame = bytes.fromhex(re.sub(r"(?m)#.*$", "", hexdump.group(1)))
    assert frame == pack_frame(decode(doc.group(1).encode()))
    assert unpack_frame(frame).seq == decode(doc.group(1).encode()).seq


def test_a_paused_reader_on_a_pty_never_blocks_send() -> None:
    """Issue 11 #5: with nobody reading a pty, pyserial's write spun once ~20 KB were buffered
    and the host stopped publishing. Here 2000 ten-person frames (~400 KB) go to a pty whose
    reader never reads; every send must return at once."""
    import os
    import threading
    import time

    master, slave = os.openpty()
    try:
        link = SerialLink(os.ttyname(slave), buffer_frames=4)
        poses = make_poses(10)
        worst = []

        def hammer() -> None:
            for _ in range(2000):
                t = time.perf_counter()
                link.send(poses)
                worst.append(time.perf_counter() - t)

        th = threading.Thread(target=hammer, daemon=True)
        th.start()
        th.join(timeout=20)
        assert not th.is_alive(), f"send blocked after {len(worst)} frames"
        assert max(worst) < 0.05 and link.stats["sent"] > 0 and link.stats["dropped"] > 1000 and link.pending <= 5
        # The reader comes back: it gets whole frames, the newest ones among them.
        os.set_blocking(master, False)
        data = b""
        for _ in range(200):  # bounded drain
            try:
                data += os.read(master, 65536)
            except BlockingIOError:
                if not link.pending:
                    break
                link.send(poses)
        assert len(FrameReader().feed(data)) >= link.stats["sent"] - 1
        link.close()
    finally:
        os.close(master)
        os.close(slave)


def test_the_link_reconnects_after_the_device_goes_away() -> None:
    """Issue 11 #5: a ``socket://`` peer closed and listening again: 0 reconnects in 10 s."""
    import socket
    import time

    def listen(port: int = 0) -> socket.socket:
        srv = socket.socket()
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind(("127.0.0.1", port))
        srv.listen(1)
        srv.settimeout(5)
        return srv

    srv = listen()
    port = srv.getsockname()[1]
    link = SerialLink(f"socket://127.0.0.1:{port}", reconnect_s=0.05)
    peer, _ = srv.accept()
    assert link.send(make_poses(1, seq=1))
    peer.settimeout(5)
    assert [f.seq for f in FrameReader().feed(peer.recv(4096))] == [1]
    peer.close()  # the device goes away ...
    srv.close()
    deadline = time.monotonic() + 10
    while link.stats["errors"] == 0 and time.monotonic() < deadline:  # TCP notices on the 2nd write
        link.send(make_poses(1, seq=2))
        time.sleep(0.01)
    assert link.stats["errors"] >= 1
    srv = listen(port)  # ... and comes back
    try:
        seq = 100
        while link.stats["reconnects"] == 0 and time.monotonic() < deadline:
            seq += 1
            link.send(make_poses(1, seq=seq))
            time.sleep(0.02)
        assert link.stats["reconnects"] == 1
        peer, _ = srv.accept()
        peer.settimeout(5)
        assert link.send(make_poses(1, seq=999)) or link.pending
        got: list = []
        reader = FrameReader()
        while 999 not in [f.seq for f in got] and time.monotonic() < deadline:
            got += reader.feed(peer.recv(4096))
            link.send(make_poses(1, seq=999))
        assert 999 in [f.seq for f in got]
        peer.close()
    finally:
        link.close()
        srv.close()
