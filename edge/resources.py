"""The files shipped inside the package: the site files, the models and the message schemas.

Every default path goes through here, so that it works the same from a checkout (editable
install) and from an installed wheel. The repository layout stays the one source: the site files
live in ``deploy/sites/`` and install as the data package ``superbody.sites`` (a setuptools
``package-dir`` mapping, no copy; its ``__init__.py`` makes it a regular package, which the
editable install's finder needs), the models live in ``models/`` and are package data of
``superbody.models``, and the JSON Schemas live in ``docs/schemas/`` and install the same way as
``superbody.schemas``.
"""

from __future__ import annotations

from importlib import resources
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["DEFAULT_SITE", "MESSAGES", "site_path", "shipped_sites", "model_path", "json_schema", "package_version"]

SITES_PACKAGE = "superbody.sites"
MODELS_PACKAGE = "superbody.models"
DEFAULT_SITE = "wtf-apartment"  # the paper's apartment: the demo's and the tools' default
SCHEMAS_PACKAGE = "superbody.schemas"
# Message name -> its JSON Schema in docs/schemas/, generated from the message's type by
# superbody.host.messages.schemas: edge.messages.wire.ObservationMsg, host.messages.pose.PoseArrayMsg, host.messages.status.HostStatus.
MESSAGES = {
    "observation": (SCHEMAS_PACKAGE, "observation.schema.json"),
    "people": (SCHEMAS_PACKAGE, "people.schema.json"),
    "status": (SCHEMAS_PACKAGE, "status.schema.json"),
}


def _folder(package: str) -> Path:
    """The installed folder of a data package, as a real path (the processes we start read from it)."""
    root = resources.files(package)
    if not isinstance(root, Path):  # e.g. imported from a zip: there is no file to hand a subprocess
        raise FileNotFoundError(f"{package} is not installed as files on disk ({root}); install superbody from a wheel or a checkout")
    return root


def shipped_sites() -> tuple[str, ...]:
    """Names of the site files shipped with superbody (``deploy/sites/<name>.toml``), sorted."""
    return tuple(sorted(p.stem for p in _folder(SITES_PACKAGE).glob("*.toml")))


def site_path(name: str = DEFAULT_SITE) -> Path:
    """The shipped site file ``<name>.toml``.

    Raises:
        FileNotFoundError: no such shipped site; the message lists the shipped ones.
    """
    p = _folder(SITES_PACKAGE) / f"{name}.toml"
    if not p.is_file():
        raise FileNotFoundError(f"no shipped site {name!r}; shipped sites: {', '.join(shipped_sites())}")
    return p


def model_path(file_name: str) -> Path | None:
    """A shipped model file (e.g. ``wtf-apartment.int8.onnx``), or None if there is none."""
    p = _folder(MODELS_PACKAGE) / file_name
    return p if p.is_file() else None


def json_schema(message: str) -> bytes:
    """The JSON Schema (draft 2020-12) of a message: ``"observation"``, ``"people"`` or ``"status"``.

    Raises:
        ValueError: unknown message name (listing the valid ones).
    """
    if message not in MESSAGES:
        raise ValueError(f"unknown message {message!r}; messages: {', '.join(MESSAGES)}")
    package, name = MESSAGES[message]
    return (_folder(package) / name).read_bytes()


def package_version() -> str:
    """The installed distribution's version (``superbody --version``)."""
    try:
        return version("superbody")
    except PackageNotFoundError:  # running from a checkout that was never installed
        return "0+unknown"
