"""The host's settings from the site file's [host] table (host.settings): fields, ranges, overrides."""

from __future__ import annotations

import tomllib

import pytest

from superbody.edge.site import SiteError, dump_site, load_site, parse_site
from superbody.host.aggregator import HostConfig
from superbody.host.settings import host_config
from tests.conftest import LAB_SITE

BASE = tomllib.loads(dump_site(load_site(LAB_SITE)))


def site_with(host: dict | None):
    doc = dict(BASE)
    if host is not None:
        doc["host"] = host
    return parse_site(doc, path="lab.toml")


def test_a_site_without_a_host_table_gives_the_defaults():
    assert host_config(site_with(None)) == HostConfig()


def test_the_site_file_sets_the_host_tracker_and_filter_and_flags_win():
    site = site_with({"max_delay_s": 1.0, "freshness_s": 0.3, "tracker": {"gate_m": 0.8, "min_joints": 4},
                      "filter": {"meas_std_xy_m": 0.05}})
    cfg = host_config(site)
    assert (cfg.max_delay_s, cfg.freshness_s, cfg.tracker.gate_m, cfg.tracker.min_joints, cfg.filter.meas_std_xy_m) == (1.0, 0.3, 0.8, 4, 0.05)
    assert cfg.tracker.d_max == HostConfig().tracker.d_max  # what neither gives: the default
    flags = host_config(site, max_delay_s=0.5, freshness_s=None, tracker={"d_max": 0.5}, filter={"enabled": False})
    assert (flags.max_delay_s, flags.freshness_s, flags.tracker.d_max, flags.tracker.gate_m, flags.filter.enabled) == (0.5, 0.3, 0.5, 0.8, False)
    assert parse_site(tomllib.loads(dump_site(site)), path="lab.toml").host == site.host  # written back as it was


@pytest.mark.parametrize(
    ("host", "message"),
    [
        ({"max_delay": 1.0}, r"lab.toml: \[host\]: unknown field\(s\) max_delay; allowed: .*max_delay_s"),       # a misspelt field
        ({"tracker": {"gate": 1}}, r"\[host.tracker\]: unknown field\(s\) gate; allowed: .*gate_m"),
        ({"tracker": {"gate_m": -1.0}}, r"\[host.tracker\]: TrackerConfig.gate_m must be a number in \(0.0, 100.0\], got -1.0"),
        ({"tracker": {"edge_margin": 0.5}}, r"\[host.tracker\]: TrackerConfig.edge_margin must be a number in \[0.0, 0.45\], got 0.5"),
        ({"max_delay_s": 5.0}, r"\[host\]: HostConfig.max_delay_s .* must be shorter than tracker.remove_after_s"),  # out of its range
        ({"filter": "fast"}, r"\[host.filter\] must be a table"),
    ],
)
def test_bad_host_settings_name_the_table_and_the_field(host, message):
    with pytest.raises(SiteError, match=message):
        host_config(site_with(host))


def test_every_host_setting_is_documented_in_install_md():
    import dataclasses

    from superbody.host.filtering.pose_filter import FilterConfig
    from superbody.host.tracking.config import TrackerConfig
    from tests.conftest import ROOT

    text = (ROOT / "docs" / "install.md").read_text()
    section = text[text.index("**`[host]`**"):text.index("### The floor polygon")]
    for cls in (HostConfig, TrackerConfig, FilterConfig):
        for f in dataclasses.fields(cls):
            if f.name not in ("tracker", "filter"):
                assert f"`{f.name}`" in section, f"{cls.__name__}.{f.name} is not in docs/install.md's [host] section"


def test_the_install_guides_host_example_is_a_valid_host_table():
    import re

    from tests.conftest import ROOT

    blocks = re.findall(r"```toml\n(.*?)```", (ROOT / "docs" / "install.md").read_text(), re.S)
    (host,) = [b for b in blocks if b.lstrip().startswith("[host]")]
    cfg = host_config(parse_site({**BASE, **tomllib.loads(host)}, path="lab.toml"))
    assert cfg.max_delay_s == 1.0 and cfg.tracker.gate_m == 0.8
