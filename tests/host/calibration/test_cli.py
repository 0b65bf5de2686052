"""``superbody calibrate people`` on an MCAP recording of the real dev.json (written as
``superbody record`` writes one): the new site file, what it holds, and the errors it gives."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.people_calibration import dev_frames, knock
from superbody.edge import transport
from superbody.edge.cli import main
from superbody.edge.site import dump_site, load_site
from superbody.host.outputs.record import Recorder
from tests.conftest import WTF_SITE


@pytest.fixture(scope="module")
def recording(dev_json, tmp_path_factory) -> Path:
    site = load_site(WTF_SITE)
    path = tmp_path_factory.mktemp("rec") / "dev.mcap"
    with open(path, "wb") as f:
        rec = Recorder(f)
        for fr in dev_frames(dev_json, site):
            rec.add(transport.observation_key(site.name, fr.camera), fr.payload, fr.stamp_ns)
        rec.close()
    return path


@pytest.fixture
def knocked(tmp_path) -> Path:
    """The apartment's site file with camera 3 knocked (its view moved 3.6 deg)."""
    path = tmp_path / "site.toml"
    path.write_text(dump_site(knock(load_site(WTF_SITE), "3", seed=0, view=True), header="knocked camera 3"))
    return path


def test_refines_the_camera_that_moved(recording: Path, knocked: Path, capsys) -> None:
    before = knocked.read_text()
    assert main(["calibrate", "people", "--recording", str(recording), "--site", str(knocked), "--json-out", str(knocked.with_suffix(".json"))]) == 0
    out = capsys.readouterr().out
    assert knocked.read_text() == before  # the input is never overwritten without --out
    new = knocked.with_name("site.people.toml")
    assert f"wrote {new}" in out
    site, old = load_site(new), load_site(knocked)
    assert site.cameras[:2] == old.cameras[:2] and site.cameras[2] != old.cameras[2]
    text = new.read_text()
    assert text.startswith("# knocked camera 3\n# camera 3: pose from superbody calibrate people --recording")
    doc = json.loads(knocked.with_suffix(".json").read_text())
    assert doc["fixed"] == ["1", "2"] and doc["refined"] == ["3"]
    cam3 = doc["cameras"]["3"]
    assert cam3["health"]["state"] == "moved"
    assert cam3["residual_deg_after"] < 1.0 < 2.0 < cam3["residual_deg_before"]
    assert 1.0 < cam3["turned_deg"] < 4.0
    for line in ("held", "refined", "turned_deg", "before_px"):
        assert line in out


def test_fix_names_the_trusted_cameras(recording: Path, knocked: Path, tmp_path: Path) -> None:
    out = tmp_path / "out.toml"
    assert main(["calibrate", "people", "--recording", str(recording), "--site", str(knocked), "--fix", "1", "--fix", "2",
                 "--focal", "--out", str(out), "--no-progress"]) == 0
    site = load_site(out)
    assert site.cameras[:2] == load_site(knocked).cameras[:2]
    assert "pose and focal length" in out.read_text().splitlines()[1]


def test_nothing_to_refine_on_a_true_calibration(recording: Path, tmp_path: Path, capsys) -> None:
    site = tmp_path / "site.toml"
    site.write_text(WTF_SITE.read_text())
    assert main(["calibrate", "people", "--recording", str(recording), "--site", str(site)]) == 0
    assert "nothing to refine: no camera was found moved; site file not written" in capsys.readouterr().out
    assert not (tmp_path / "site.people.toml").exists()


# (arguments after --site, what the one-line error says)
ERRORS = [
    (["--fix", "9", "--fix", "1"], "--fix: camera(s) 9 not in site 'wtf-apartment'"),
    (["--fix", "1"], "--fix: at least 2 cameras must be held"),
    (["--max-skew", "0"], "--max-skew must be in (0, 1] seconds"),
    (["--max-instants", "0"], "--max-instants must be in [1, 100000]"),
]


@pytest.mark.parametrize("extra, words", ERRORS)
def test_bad_arguments(recording: Path, knocked: Path, capsys, extra: list[str], words: str) -> None:
    assert main(["calibrate", "people", "--recording", str(recording), "--site", str(knocked), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("superbody calibrate people: error: ") and words in err and err.count("\n") == 1


def test_bad_recordings(tmp_path: Path, knocked: Path, capsys) -> None:
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello")
    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        rec = Recorder(f)
        rec.add("superbody/elsewhere/people", b"{}", 1)
        rec.close()
    # (the recording, what the error says)
    for path, words in ((tmp_path / "missing.mcap", "no such file"), (not_mcap, "not an MCAP file"),
                        (other, "no observation of site 'wtf-apartment'")):
        assert main(["calibrate", "people", "--recording", str(path), "--site", str(knocked)]) == 2
        assert words in capsys.readouterr().err
