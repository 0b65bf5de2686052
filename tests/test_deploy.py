"""The deployment files: systemd units, their environment file and the host's container recipe.

Each unit is parsed strictly (sections, known keys, no duplicates but EnvironmentFile), checked by
``systemd-analyze verify`` where systemd is installed (any warning fails), and each ExecStart,
with the environment file's values and an instance name substituted, must parse as a
``superbody`` command line. The container recipe cannot be built here (no container engine); its
COPY sources must exist and its command must parse the same way.
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from superbody.edge.cli import build_parser
from tests.conftest import ROOT

SYSTEMD = ROOT / "deploy" / "systemd"
CONTAINERFILE = ROOT / "deploy" / "container" / "Containerfile"
UNITS = sorted(p.name for p in SYSTEMD.iterdir() if p.suffix in (".service", ".target"))
SERVICES = [u for u in UNITS if u.endswith(".service")]
BINARY = "/opt/superbody/bin/superbody"  # where docs/install.md installs it

# The keys these units may use, by section: a typo'd key is an error here, not a silent no-op.
KNOWN = {
    "Unit": {"Description", "Documentation", "Wants", "Requires", "After", "Before", "PartOf", "BindsTo",
             "StartLimitIntervalSec", "StartLimitBurst", "ConditionPathExists"},
    "Service": {"Type", "EnvironmentFile", "Environment", "ExecStart", "ExecStartPre", "Restart", "RestartSec",
                "RestartPreventExitStatus", "DynamicUser", "User", "Group", "SupplementaryGroups", "NoNewPrivileges",
                "ProtectSystem", "ProtectHome", "PrivateTmp", "StateDirectory", "WorkingDirectory", "TimeoutStopSec",
                "KillSignal"},
    "Install": {"WantedBy", "RequiredBy", "Also", "DefaultInstance"},
}
REPEATABLE = {"EnvironmentFile", "Environment", "ExecStartPre"}


def parse_unit(text: str, name: str) -> dict[str, dict[str, list[str]]]:
    """A strict reading of a unit file: {section: {key: [values]}}; raises ValueError naming the line."""
    out: dict[str, dict[str, list[str]]] = {}
    section = None
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        if line.endswith("\\"):
            raise ValueError(f"{name}:{n}: no continuation lines, please")
        m = re.fullmatch(r"\[([A-Za-z]+)\]", line)
        if m:
            section = m.group(1)
            if section not in KNOWN or section in out:
                raise ValueError(f"{name}:{n}: unexpected or repeated section [{section}]")
            out[section] = {}
            continue
        if section is None or "=" not in line:
            raise ValueError(f"{name}:{n}: expected Key=Value inside a section, got {raw!r}")
        key, value = (s.strip() for s in line.split("=", 1))
        if key not in KNOWN[section]:
            raise ValueError(f"{name}:{n}: unknown key {key!r} in [{section}]")
        if key in out[section] and key not in REPEATABLE:
            raise ValueError(f"{name}:{n}: {key} given twice")
        out[section].setdefault(key, []).append(value)
    return out


def parse_env(text: str) -> dict[str, str]:
    env = {}
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        m = re.fullmatch(r"([A-Z_][A-Z0-9_]*)=(.*)", line)
        assert m, f"superbody.env:{n}: not KEY=VALUE: {raw!r}"
        env[m.group(1)] = m.group(2)
    return env


def expand(cmd: str, env: dict[str, str], instance: str) -> list[str]:
    """systemd's expansion: ${VAR} is one word, $VAR splits on whitespace, %i is the instance."""
    words = []
    for word in shlex.split(cmd.replace("%i", instance)):
        m = re.fullmatch(r"\$([A-Z_][A-Z0-9_]*)", word)
        if m:
            words += env[m.group(1)].split()
            continue
        words.append(re.sub(r"\$\{([A-Z_][A-Z0-9_]*)\}", lambda g: env[g.group(1)], word))
    return words


def check_command(argv: list[str]) -> None:
    """The arguments parse as a superbody command line (argparse exits 2 on any error)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:
        pytest.fail(f"superbody {' '.join(argv)}: does not parse (exit {e.code})")
    assert callable(args.func)


ENV = parse_env((SYSTEMD / "superbody.env").read_text())


def test_the_expected_units_are_shipped():
    assert UNITS == ["superbody-camera@.service", "superbody-host.service", "superbody-router.service", "superbody.target"]


@pytest.mark.parametrize("unit", UNITS)
def test_unit_parses_strictly(unit):
    doc = parse_unit((SYSTEMD / unit).read_text(), unit)
    assert doc["Unit"]["Description"]
    assert doc["Install"]["WantedBy"] == (["multi-user.target"] if unit.endswith(".target") else ["superbody.target"])


@pytest.mark.parametrize("unit", SERVICES)
def test_service_restarts_reads_the_env_file_and_runs_a_superbody_command(unit):
    svc = parse_unit((SYSTEMD / unit).read_text(), unit)["Service"]
    assert svc["Restart"] == ["always"] and float(svc["RestartSec"][0]) > 0
    assert svc["RestartPreventExitStatus"] == ["2"]  # a CLI error (exit 2) does not loop
    assert svc["EnvironmentFile"][0] == "/etc/superbody/superbody.env"
    argv = expand(svc["ExecStart"][0], ENV, instance="1")
    assert argv[0] == BINARY
    check_command(argv[1:])


def test_a_camera_instance_per_camera_of_a_shipped_site():
    from superbody.edge.resources import site_path
    from superbody.edge.site import load_site

    svc = parse_unit((SYSTEMD / "superbody-camera@.service").read_text(), "camera")["Service"]
    for cam in load_site(site_path("lab-example")).camera_ids:
        argv = expand(svc["ExecStart"][0], ENV, instance=cam)
        assert argv[argv.index("--camera") + 1] == cam
        check_command(argv[1:])


def test_a_typo_is_caught():
    text = (SYSTEMD / "superbody-host.service").read_text().replace("RestartSec=", "RestartSecs=")
    with pytest.raises(ValueError, match="RestartSecs"):
        parse_unit(text, "typo.service")
    with pytest.raises(pytest.fail.Exception, match="does not parse"):  # argparse rejects an unknown option
        check_command(["host", "run", "--site", "s.toml", "--sitee", "x"])


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed (the strict parse above still ran)")
def test_systemd_analyze_verify(tmp_path):
    # verify checks that ExecStart's program exists: point it at this environment's console script.
    exe = Path(sys.executable).with_name("superbody")
    assert exe.is_file(), exe
    for unit in UNITS:
        (tmp_path / unit).write_text((SYSTEMD / unit).read_text().replace(BINARY, str(exe)))
    for unit in ["superbody.target", "superbody-router.service", "superbody-host.service", "superbody-camera@1.service"]:
        p = subprocess.run(["systemd-analyze", "verify", str(tmp_path / unit)], capture_output=True, text=True, timeout=60)
        assert p.returncode == 0 and not p.stderr.strip() and not p.stdout.strip(), f"{unit}: {p.stdout}{p.stderr}"


def test_containerfile_copies_what_exists_and_runs_the_host():
    lines = [ln for ln in CONTAINERFILE.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    instructions = [ln.split(None, 1) for ln in lines if not ln.startswith(" ")]
    ops = [op for op, _ in instructions]
    assert ops.count("FROM") == 2 and ops[0] == "FROM"
    for op, rest in instructions:
        if op == "COPY" and not rest.startswith("--from"):
            *sources, _dest = rest.split()
            for s in sources:
                assert (ROOT / s).exists(), f"COPY {s}: not in the repository"
    entry = json.loads(dict(instructions)["ENTRYPOINT"])
    cmd = json.loads(dict(instructions)["CMD"])
    assert entry == ["superbody"]
    assert cmd[:2] == ["host", "run"]
    check_command(cmd)
