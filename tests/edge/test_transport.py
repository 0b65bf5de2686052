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
