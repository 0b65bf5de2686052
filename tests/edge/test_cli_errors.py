"""Bad command-line values: one line ``superbody <cmd>: error: ...`` naming the value, exit code 2,
no traceback (issue 11 #8). Run in-process through ``superbody.edge.cli.main``."""

from __future__ import annotations

import socket

import pytest

from superbody.edge.cli import main
from tests.conftest import ROOT, WTF_SITE

SITE = str(WTF_SITE)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    (d / "empty.onnx").write_bytes(b"")
    (d / "truncated.onnx").write_bytes((ROOT / "models" / "wtf-apartment.int8.onnx").read_bytes()[:3000])
    (d / "bad.json5").write_text("{mode: ")
    (d / "latin1.toml").write_bytes(b'[site]\nname = "caf\xe9"\n')
    (d / "host-typo.toml").write_text(WTF_SITE.read_text() + "\n[host.tracker]\ngate = 0.8\n")
    return d


def _run(capsys, argv: list[str]) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse's own errors
        rc = e.code
    err = capsys.readouterr().err.strip().splitlines()
    return rc, err[-1] if err else ""


CASES = [
    # (argv with {d} for the files' folder, the command named, what the line must name)
    (["host", "run", "--site", SITE, "--model", "{d}/empty.onnx"], "host run", "empty.onnx: not a loadable ONNX model (0 bytes)"),
    (["host", "run", "--site", SITE, "--model", "{d}/truncated.onnx"], "host run", "truncated.onnx: not a loadable ONNX model (3000 bytes)"),
    (["host", "run", "--site", "{d}/host-typo.toml", "--estimator", "analytic"], "host run", "[host.tracker]: unknown field(s) gate; allowed:"),
    (["host", "run", "--site", SITE, "--estimator", "analytic", "--max-delay", "3"], "host run", "--max-delay must be a number in [0, 1.9]"),
    (["edge", "run", "--site", SITE, "--camera", "1", "--connect", "foo"], "edge run", "--connect 'foo'"),
    (["edge", "run", "--site", SITE, "--camera", "1", "--connect", ""], "edge run", "--connect ''"),
    (["host", "run", "--site", SITE, "--estimator", "analytic", "--connect", "tcp/127.0.0.1:99999"], "host run", "[1, 65535]"),
    (["router", "--listen", "foo"], "router", "--listen 'foo'"),
    (["router", "--listen", "tcp/127.0.0.1:70000"], "router", "[0, 65535]"),
    (["host", "run", "--site", SITE, "--estimator", "analytic", "--config", "{d}/missing.json5"], "host run", "missing.json5: not a readable Zenoh JSON5 config"),
    (["host", "run", "--site", SITE, "--estimator", "analytic", "--config", "{d}/bad.json5"], "host run", "bad.json5: not a readable Zenoh JSON5 config"),
    (["router", "--config", "{d}/bad.json5"], "router", "bad.json5: not a readable Zenoh JSON5 config"),
    (["demo", "--site", "{d}/latin1.toml"], "demo", "latin1.toml: not UTF-8 text (byte 0xe9 at offset 18, line 2)"),
    (["edge", "run", "--site", "{d}/latin1.toml", "--camera", "1"], "edge run", "latin1.toml: not UTF-8 text"),
    (["demo", "--port", "99999"], "demo", "--port must be in [0, 65535], got 99999"),
    # the demo's camera timing: ranges, the CAMERA=VALUE form, and camera ids the site has
    (["demo", "--delay", "40"], "demo", "--delay must be a number in [0, 30], got '40'"),
    (["demo", "--jitter", "-1"], "demo", "--jitter must be a number in [0, 10], got '-1'"),
    (["demo", "--camera-delay", "1:0.8"], "demo", "--camera-delay must be CAMERA=SECONDS with SECONDS in [0, 30], got '1:0.8'"),
    (["demo", "--camera-delay", "1=late"], "demo", "--camera-delay 1=...: SECONDS must be a number in [0, 30], got 'late'"),
    (["demo", "--camera-fps", "3=0"], "demo", "--camera-fps 3=...: FPS must be a number in [0.1, 1000], got '0'"),
    (["demo", "--camera-delay", "9=0.5"], "demo", "--camera-delay 9=...: camera '9' is not in site 'wtf-apartment'; cameras: 1, 2, 3"),
    (["demo", "--camera-fps", "nw=5"], "demo", "--camera-fps nw=...: camera 'nw' is not in site 'wtf-apartment'; cameras: 1, 2, 3"),
]


@pytest.mark.parametrize(("argv", "command", "named"), CASES, ids=[" ".join(c[0][:2]) + f" {i}" for i, c in enumerate(CASES)])
def test_bad_values_give_one_line_and_exit_2(capsys, files, argv, command, named):
    rc, line = _run(capsys, [a.replace("{d}", str(files)) for a in argv])
    assert rc == 2
    assert line.startswith(f"superbody {command}: error: "), line
    assert named in line, line
    assert "Traceback" not in line and ".rs:" not in line


def test_a_router_port_already_in_use_is_one_line(capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        rc, line = _run(capsys, ["router", "--listen", f"tcp/127.0.0.1:{port}"])
    assert rc == 2 and line.startswith("superbody router: error: zenoh: ") and "Address already in use" in line, line
    assert ".rs:" not in line
