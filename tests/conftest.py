"""Shared test helpers: free loopback ports, superbody processes, the dataset path."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from superbody.host.demo import stop_processes

ROOT = Path(__file__).resolve().parents[1]
DEV_JSON = ROOT.parent / "shared" / "datasets" / "wheresthefellow" / "dev.json"
LAB_SITE = ROOT / "deploy" / "sites" / "lab-example.toml"
WTF_SITE = ROOT / "deploy" / "sites" / "wtf-apartment.toml"


# The packages whose versions decide what the tests see (numerics, codecs, transport), printed in
# pytest's header so that every failure report says which environment it ran in.
_REPORTED_PACKAGES = ("numpy", "scipy", "onnxruntime", "onnx", "torch", "opencv-python-headless", "eclipse-zenoh", "msgspec", "depthai")


def pytest_report_header(config) -> list[str]:
    from importlib.metadata import PackageNotFoundError, version

    def of(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return "absent"

    import platform

    cpu = next((line.split(":", 1)[1].strip() for line in _cpuinfo() if line.startswith("model name")), platform.processor() or "?")
    flags = next((line.split(":", 1)[1].split() for line in _cpuinfo() if line.startswith("flags")), [])
    simd = ",".join(f for f in ("avx2", "avx512f", "avx512_vnni", "avx_vnni", "amx_int8") if f in flags) or "-"
    return [
        "superbody environment: " + ", ".join(f"{name} {of(name)}" for name in _REPORTED_PACKAGES),
        f"superbody machine: Python {platform.python_version()}, {os.cpu_count()} cpus, {cpu} ({simd})",
    ]


def _cpuinfo() -> list[str]:
    try:
        return Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return []


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Processes:
    """Starts ``superbody`` subcommands as separate processes and always stops them."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def start(self, *args: str, stdout=subprocess.DEVNULL) -> subprocess.Popen:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        p = subprocess.Popen([sys.executable, "-m", "superbody.edge.cli", *args], cwd=ROOT, env=env,
                             stdout=stdout, stderr=subprocess.PIPE, text=True)
        self.procs.append(p)
        return p

    def stop_all(self) -> None:
        stop_processes(self.procs)


@pytest.fixture
def processes():
    procs = Processes()
    yield procs
    procs.stop_all()


@pytest.fixture(scope="session")
def dev_json() -> Path:
    assert DEV_JSON.is_file(), f"the WheresTheFellow dev split is expected at {DEV_JSON} (see README)"
    return DEV_JSON


class HostWatch:
    """A host's PoseArrays and status messages on one site, as they arrive (for multi-process tests)."""

    def __init__(self, session, site: str):
        from superbody.edge import transport

        self.arrays: list = []
        self.status: list[dict] = []
        self.arrived: list[float] = []  # time.monotonic() of each PoseArray's arrival
        self.status_arrived: list[float] = []
        self.cv = threading.Condition()
        self.subs = [session.declare_subscriber(transport.people_key(site), self._people),
                     session.declare_subscriber(transport.host_status_key(site), self._status)]

    def _people(self, sample) -> None:
        from superbody.host.messages import pose as pose_msg

        arr = pose_msg.decode(sample.payload.to_bytes())
        with self.cv:
            self.arrays.append(arr)
            self.arrived.append(time.monotonic())
            self.cv.notify_all()

    def _status(self, sample) -> None:
        doc = json.loads(sample.payload.to_bytes())
        with self.cv:
            self.status.append(doc)
            self.status_arrived.append(time.monotonic())
            self.cv.notify_all()

    def wait(self, predicate, timeout: float) -> bool:
        with self.cv:
            return self.cv.wait_for(predicate, timeout=timeout)

    def close(self) -> None:
        for s in self.subs:
            s.undeclare()
