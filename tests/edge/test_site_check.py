"""Site checks (edge/site_check.py) and the ``superbody site check | floor-plot`` commands."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from superbody.edge.camera import Camera, look_at_rotation
from superbody.edge.cli import main
from superbody.edge.floor import guess_layout, polygon_area, visible_floor
from superbody.edge.site import Site, dump_site, load_site
from superbody.edge.site_check import check_camera, check_site, fov_deg, pitch_deg
from tests.conftest import ROOT, WTF_SITE


def _cam(pos=(0.0, 0.0, 2.5), target=(4.0, 0.0, 1.0), **kw) -> Camera:
    R = look_at_rotation(np.array(pos, float), np.array(target, float))
    base = dict(id="a", width=1280, height=720, fps=15.0, fx=900.0, fy=900.0, cx=640.0, cy=360.0,
                position=tuple(float(v) for v in pos), rotation=tuple(tuple(float(v) for v in r) for r in R))
    return Camera(**{**base, **kw})


# (camera, severity and field of the finding, or None for no finding)
CAMERAS = [
    (_cam(), None),  # a wall camera 2.5 m up looking down into the room
    (_cam(pos=(0, 0, -0.5), target=(4, 0, -1)), ("error", ".position")),  # below the floor (the up axis upside down)
    (_cam(target=(4.0, 0.0, 6.0)), ("error", ".rotation")),  # aimed 42 deg above the horizon: no floor in view
    (_cam(pos=(0, 0, 25.0), target=(4, 0, 0)), ("warning", ".position")),  # 25 m up: centimetres read as metres?
    (_cam(fx=5.0, fy=5.0), ("error", ".fx")),  # a 179 deg pinhole: intrinsics of another image size
    (_cam(fx=4000.0, fy=4000.0), ("warning", ".fx")),  # 18 deg: a telephoto, unusual indoors
    (_cam(fy=600.0), ("warning", ".fy")),  # fx / fy = 1.5: not square pixels
    (_cam(fy=300.0), ("error", ".fy")),  # fx / fy = 3
    (_cam(cx=1100.0), ("warning", ".cx")),  # principal point far off-centre: the image size wrong?
    (_cam(dist=(0.9, 0.0, 0.0, 0.0, -3.0)), ("warning", ".dist")),  # distortion folding back inside the image
]


@pytest.mark.parametrize("cam, finding", CAMERAS)
def test_check_camera(cam, finding):
    found = check_camera(cam, 0)
    if finding is None:
        assert found == []
    else:
        assert [(f.severity, f.field) for f in found] == [(finding[0], f"cameras[0] (a){finding[1]}")], found


def test_pitch_and_fov():
    cam = _cam(target=(4.0, 0.0, 2.5))  # level
    assert pitch_deg(cam) == pytest.approx(0.0, abs=1e-9)
    assert pitch_deg(_cam(target=(1.5, 0.0, 1.0))) == pytest.approx(45.0)
    assert fov_deg(cam)[0] == pytest.approx(2 * np.degrees(np.arctan(640 / 900)))


def test_the_shipped_sites_pass():
    assert check_site(load_site(WTF_SITE)) == []


def test_a_floor_no_camera_sees_is_a_warning():
    site = load_site(WTF_SITE)
    far = replace(site, floor=((20.0, 20.0), (30.0, 20.0), (30.0, 30.0), (20.0, 30.0)))
    found = check_site(far)
    assert {f.field for f in found} >= {"floor.polygon", "cameras[0] (1)"}
    assert all(f.severity == "warning" for f in found)


def test_site_check_command(tmp_path, capsys):
    assert main(["site", "check", str(WTF_SITE)]) == 0
    assert "3 cameras, 0 warning(s)" in capsys.readouterr().out
    site = load_site(WTF_SITE)
    low = site.cameras[0]
    bad = replace(site, cameras=(replace(low, position=(low.position[0], low.position[1], -1.0)), *site.cameras[1:]))
    (tmp_path / "bad.toml").write_text(dump_site(bad))
    assert main(["site", "check", str(tmp_path / "bad.toml")]) == 2
    std = capsys.readouterr()
    assert "cameras[0] (1).position: z = -1.000 m is not above the floor" in std.out and "1 error(s)" in std.err
    assert main(["site", "check", str(tmp_path / "missing.toml")]) == 2
    assert "cannot read site file" in capsys.readouterr().err


def test_floor_plot_command(tmp_path):
    pytest.importorskip("matplotlib")
    site = Site(name="one", cameras=(_cam(),), floor=((1.0, -2.0), (6.0, -2.0), (6.0, 2.0), (1.0, 2.0)))
    (tmp_path / "one.toml").write_text(dump_site(site))
    out = tmp_path / "plots" / "floor.png"
    assert main(["site", "floor-plot", str(tmp_path / "one.toml"), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


def _install_md_sites() -> list[str]:
    """The whole example sites of docs/install.md: its TOML blocks with a [site] table (others are parts of one)."""
    text = (ROOT / "docs" / "install.md").read_text()
    return [b for b in re.findall(r"```toml\n(.*?)```", text, re.S) if "[site]" in b]


@pytest.mark.parametrize("text, layout", list(zip(_install_md_sites(), ("wall", "ring", "ceiling"))))
def test_the_install_guides_example_sites_load_and_pass_the_checks(tmp_path, text, layout):
    (tmp_path / "s.toml").write_text(text)
    site = load_site(tmp_path / "s.toml")
    assert check_site(site) == []
    assert guess_layout(site.cameras) == layout
    if layout != "wall":  # the ring's and the ceiling's polygons are the derived ones, as the guide says
        derived = visible_floor(site.cameras, layout=layout)
        assert polygon_area(derived) == pytest.approx(polygon_area(site.floor), rel=0.05)


def test_the_install_guide_has_the_three_layouts():
    assert len(_install_md_sites()) == 3
