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
