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
