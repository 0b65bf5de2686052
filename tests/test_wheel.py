"""The built wheel works on its own: installed into a fresh virtualenv and run from an empty folder.

The fresh virtualenv reuses this environment's third-party packages (numpy, zenoh, onnxruntime...)
through a ``.pth`` line, so nothing is downloaded; superbody itself comes only from the wheel
(installed with ``--no-deps``), never from this checkout: the commands run in an empty folder,
without PYTHONPATH, and the test checks where ``superbody`` was imported from.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from tests.conftest import ROOT, free_port

# What a source tree holds that the wheel must not be built from.
_IGNORE = shutil.ignore_patterns(".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", ".hypothesis", "out")


def _run(cmd: list[str], cwd: Path, env: dict, timeout: float) -> subprocess.CompletedProcess:
    p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, f"{' '.join(map(str, cmd))} exited {p.returncode}\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}"
    return p


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict:
    """Build the wheel from a copy of the working tree and install it into a fresh virtualenv."""
    tmp = tmp_path_factory.mktemp("wheel")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    src = tmp / "src"
    shutil.copytree(ROOT, src, ignore=_IGNORE)  # a clean tree: no stale build/ can leak into the wheel
    dist = tmp / "dist"
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(dist), str(src)], tmp, env, 180)
    wheel = next(dist.glob("superbody-*.whl"))
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp, env, 60)
    py = venv / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], tmp, env, 60).stdout.strip())
    # Third-party dependencies from this environment; superbody's editable finder is not among them
    # (a .pth line adds a folder to sys.path without running the .pth files inside it).
    (site / "_deps_from_test_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", str(wheel)], tmp, env, 120)
    empty = tmp / "empty"
    empty.mkdir()
    return {"wheel": wheel, "venv": venv, "site": site, "empty": empty, "env": env}


@pytest.mark.slow  # the module's fixture builds and installs the wheel (~20 s)
def test_wheel_holds_one_namespace_and_the_shipped_files(installed):
    names = zipfile.ZipFile(installed["wheel"]).namelist()
    tops = {n.split("/")[0] for n in names}
    assert "superbody" in tops and all(t == "superbody" or t.endswith(".dist-info") for t in tops), tops
    for shipped in ("superbody/sites/wtf-apartment.toml", "superbody/sites/lab-example.toml",
                    "superbody/models/wtf-apartment.int8.onnx", "superbody/models/site-independent.int8.onnx",
                    "superbody/edge/py.typed", "superbody/host/py.typed", "superbody/models/py.typed",
                    "superbody/schemas/observation.schema.json", "superbody/schemas/people.schema.json",
                    "superbody/schemas/status.schema.json"):
        assert shipped in names, shipped
    # Nothing named edge, host or models at the top of site-packages.
    assert not [p.name for p in installed["site"].iterdir() if p.name in ("edge", "host", "models")]


@pytest.mark.slow
def test_installed_wheel_runs_version_and_the_demo_from_an_empty_folder(installed):
    bin_ = installed["venv"] / "bin"
    env, empty = installed["env"], installed["empty"]
    out = _run([str(bin_ / "superbody"), "--version"], empty, env, 60).stdout
    assert out.strip().startswith("superbody "), out
    where = _run([str(bin_ / "python"), "-c", "import importlib.util as u, superbody.edge.resources as r; "
                  "print(r.__file__); print(r.site_path()); print([u.find_spec(n) is None for n in ('edge', 'host', 'models')]); "
                  "import json; print(json.loads(r.json_schema('people'))['$id'])"],
                 empty, env, 60).stdout.splitlines()
    assert where[0].startswith(str(installed["site"])), where  # imported from the wheel, not this checkout
    assert where[1].startswith(str(installed["site"])), where  # the default site file is package data
    assert where[2] == "[True, True, True]", where  # no top-level edge/host/models to shadow a user's own
    assert where[3] == "superbody.people/2", where  # the JSON Schemas are package data (superbody.schemas)
    summary = empty / "summary.json"
    demo = _run([str(bin_ / "superbody"), "demo", "--duration", "15", "--clock-scale", "3", "--no-table",
                 "--port", str(free_port()), "--json-summary", str(summary)], empty, env, 120)
    doc = json.loads(summary.read_text())
    assert doc["poses_published"] > 0, demo.stdout
    assert doc["people_confirmed"] >= 1, demo.stdout
    assert doc["tracks"] >= doc["people_confirmed"] and len(doc["confirm_delay_s"]) <= doc["people_confirmed"], doc  # as printed
    assert [p.name for p in empty.iterdir()] == ["summary.json"]  # the demo wrote nothing else where it ran
