"""Shared test helpers: free loopback ports, superbody processes, the dataset path."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DEV_JSON = ROOT.parent / "shared" / "datasets" / "wheresthefellow" / "dev.json"
LAB_SITE = ROOT / "deploy" / "sites" / "lab-example.toml"
WTF_SITE = ROOT / "deploy" / "sites" / "wtf-apartment.toml"


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
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.fixture
def processes():
    procs = Processes()
    yield procs
    procs.stop_all()


@pytest.fixture(scope="session")
def dev_json() -> Path:
    assert DEV_JSON.is_file(), f"the WheresTheFellow dev split is expected at {DEV_JSON} (see README)"
    return DEV_JSON
