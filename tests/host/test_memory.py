"""host.memory: glibc's mmap threshold pinned, so a burst of large buffers is given back."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

from superbody.host.memory import pin_mmap_threshold

GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"

# A burst as the host meets it: a large buffer freed, then 40 buffers of 600 KB (a stranger's
# payloads) each followed by a small allocation that lives on (the host's own work), then the
# large ones freed. Prints how much of the burst stayed resident, in MB.
BURST = """
import sys
from superbody.host.memory import pin_mmap_threshold
if sys.argv[1] == "pinned":
    assert pin_mmap_threshold()
def rss_kb():
    return int(next(l for l in open("/proc/self/status") if l.startswith("VmRSS:")).split()[1])
first = bytearray(2_000_000)
first[-1] = 1
del first
before = rss_kb()
big, small = [], []
for k in range(40):
    buf = bytearray(600_000)
    buf[::4096] = bytes(len(buf[::4096]))  # touch every page
    big.append(buf)
    small.append(bytearray(2_000))
del big, buf
print((rss_kb() - before) / 1024)
"""


def _kept_mb(mode: str) -> float:
    out = subprocess.run([sys.executable, "-c", BURST, mode], capture_output=True, text=True, timeout=60, check=True)
    return float(out.stdout.strip())


@pytest.mark.skipif(not GLIBC, reason="the dynamic mmap threshold is glibc's")
def test_a_burst_of_large_buffers_is_given_back():
    default, pinned = _kept_mb("default"), _kept_mb("pinned")
    # glibc's default: the threshold rose to the first freed buffer, the burst went to the heap
    # and its holes, pinned in place by the small allocations, stay resident.
    assert default > 15, default
    assert pinned < 2, pinned


def test_the_threshold_is_checked():
    with pytest.raises(ValueError, match="mmap threshold"):
        pin_mmap_threshold(0)
    assert pin_mmap_threshold() == GLIBC


# Small blocks as a flood of fake people leaves them: 40 MB of 1 KB buffers, every 64th kept
# alive (tracks that outlive the burst), the rest freed. Prints the resident MB given back by
# release_free_memory.
SMALL = """
from superbody.host.memory import release_free_memory
def rss_kb():
    return int(next(l for l in open("/proc/self/status") if l.startswith("VmRSS:")).split()[1])
blocks = [bytearray(1000) for _ in range(40_000)]
for b in blocks:
    b[::512] = b"xx"  # touch them
kept = blocks[::64]
del blocks
before = rss_kb()
released = release_free_memory()
print(released, (before - rss_kb()) / 1024)
"""


@pytest.mark.skipif(not GLIBC, reason="malloc_trim is glibc's")
def test_free_small_blocks_between_live_ones_are_given_back():
    out = subprocess.run([sys.executable, "-c", SMALL], capture_output=True, text=True, timeout=60, check=True)
    released, given_back_mb = out.stdout.split()
    assert released == "True"
    # ~39 MB of the 40 are free but pinned between live blocks; the trim returns whole free pages.
    assert float(given_back_mb) > 20, out.stdout
