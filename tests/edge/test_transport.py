"""Zenoh key names and session options."""

import pytest

from superbody.edge.transport import camera_from_key, observation_key, people_key, session_config


@pytest.mark.parametrize(
    "site, camera, expected",
    [
        ("lab", "cam-1", "superbody/lab/cameras/cam-1/observations"),  # one camera
        ("lab", "*", "superbody/lab/cameras/*/observations"),           # every camera of the site
    ],
)
def test_observation_key(site: str, camera: str, expected: str) -> None:
    assert observation_key(site, camera) == expected


@pytest.mark.parametrize("site, camera", [("a/b", "1"), ("lab", "**"), ("*", "1"), ("", "1")])
def test_observation_key_rejects_bad_names(site: str, camera: str) -> None:
    with pytest.raises(ValueError):
        observation_key(site, camera)




def test_people_key_and_camera_from_key():
    assert people_key("lab") == "superbody/lab/people"
    assert camera_from_key("superbody/lab/cameras/nw/observations") == "nw"
    assert camera_from_key("superbody/lab/people") is None
    with pytest.raises(ValueError, match="site"):
        people_key("lab\n")


def test_session_config_rejects_unknown_mode():
    with pytest.raises(ValueError, match="peer, client, router"):
        session_config("server")


@pytest.mark.parametrize(
    ("endpoint", "listen", "ok"),
    [
        ("tcp/127.0.0.1:7447", False, True),
        ("tcp/[::1]:7447", False, True),          # IPv6 in brackets
        ("tls/localhost:7447", False, True),
        ("tcp/127.0.0.1:0", True, True),          # any free port, when listening
        ("tcp/127.0.0.1:0", False, False),        # ... but nothing to connect to
        ("tcp/127.0.0.1:99999", False, False),    # beyond 65535: used to be retried for ever
        ("tcp/127.0.0.1:", False, False),
        ("foo", False, False),
        ("", False, False),
        ("http/127.0.0.1:80", False, False),      # not a Zenoh protocol
    ],
)
def test_check_endpoint(endpoint, listen, ok):
    from superbody.edge.transport import ConfigError, check_endpoint

    if ok:
        assert check_endpoint(endpoint, listen=listen) == endpoint
    else:
        with pytest.raises(ConfigError, match="--connect"):
            check_endpoint(endpoint, "--connect", listen=listen)


def test_default_peer_listens_on_loopback_only_and_caps_message_size():
    from superbody.edge.transport import MAX_MESSAGE_BYTES

    conf = session_config()
    assert conf.get_json("listen/endpoints") == '["tcp/127.0.0.1:0"]'
    assert int(conf.get_json("transport/link/rx/max_message_size")) == MAX_MESSAGE_BYTES
    assert session_config("peer", listen=["tcp/127.0.0.1:7000"]).get_json("listen/endpoints") == '["tcp/127.0.0.1:7000"]'


@pytest.mark.parametrize("mode", ["peer", "client", "router"])
def test_shared_memory_is_off(mode):
    # With it on (Zenoh's default), every same-machine sender's 16 MiB pool is mapped into the receiver
    # (the soak's memory growth; tests/host/test_attacks.py reproduces it over loopback).
    import json

    from tests.conftest import ROOT

    assert json.loads(session_config(mode).get_json("transport/shared_memory/enabled")) is False
    for path in sorted((ROOT / "deploy" / "zenoh" / "loopback").glob("*.json5")):
        assert json.loads(session_config(None, config_file=str(path)).get_json("transport/shared_memory/enabled")) is False, path


# --- the Zenoh examples' conventions: --cfg KEY:VALUE, logging from the environment ----------


@pytest.mark.parametrize("text, expected", [
    ("transport/link/tx/lease:3000", ("transport/link/tx/lease", "3000")),                           # a number
    ('connect/endpoints:["tcp/127.0.0.1:7447"]', ("connect/endpoints", '["tcp/127.0.0.1:7447"]')),  # the value keeps its colons
    (" mode : \"client\" ", ("mode", '"client"')),                                                  # spaces trimmed
])
def test_parse_cfg(text, expected):
    from superbody.edge.transport import parse_cfg

    assert parse_cfg(text) == expected


@pytest.mark.parametrize("text", ["mode", ":3000", "transport/link/tx/lease:", ""])
def test_parse_cfg_rejects(text):
    from superbody.edge.transport import ConfigError, parse_cfg

    with pytest.raises(ConfigError, match="KEY:VALUE"):
        parse_cfg(text)


def test_cfg_is_applied_last_and_wins():
    conf = session_config("peer", cfg=['mode:"client"', "scouting/multicast/enabled:true"])
    assert conf.get_json("mode") == '"client"'
    assert conf.get_json("scouting/multicast/enabled") == "true"  # over our default of false


def test_cfg_that_zenoh_refuses_names_the_setting():
    from superbody.edge.transport import ConfigError

    with pytest.raises(ConfigError, match="no/such/key"):
        session_config("peer", cfg=["no/such/key:1"])


def test_cli_cfg_error_is_one_line(tmp_path):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "superbody.edge.cli", "router", "--listen", "tcp/127.0.0.1:0", "--cfg", "mode"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("superbody router: error: --cfg 'mode'"), r.stderr


def test_zenoh_logging_follows_rust_log():
    """RUST_LOG=debug shows Zenoh's own log lines, as with Zenoh's examples; by default they are quiet."""
    import os
    import signal
    import subprocess
    import sys

    from tests.conftest import free_port

    def run(env_extra: dict) -> str:
        env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"} | env_extra
        p = subprocess.Popen([sys.executable, "-m", "superbody.edge.cli", "router", "--listen", f"tcp/127.0.0.1:{free_port()}"],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        try:
            p.wait(timeout=3)
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGTERM)
        return p.communicate(timeout=20)[0]

    assert "zenoh::net::runtime" in run({"RUST_LOG": "debug"})  # a Rust module path: Zenoh's own log line
    assert "zenoh::" not in run({})
