"""The host's settings for a site, from its site file's ``[host]`` table.

Everything per installation lives in the site file (DESIGN.md), the host's settings too::

    [host]
    max_delay_s = 1.0        # HostConfig: how long the host waits for late cameras, ...

    [host.tracker]
    gate_m = 0.8             # TrackerConfig: the tracker's numbers

    [host.filter]
    meas_std_yaw_rad = 0.08  # FilterConfig: the pose filter's

A field the host does not know, or a value out of its range, is a ``SiteError`` naming the table,
the field and what is allowed. ``superbody host run``'s flags override the file; what neither
gives is the dataclasses' default (docs/install.md lists every field, its unit and range).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from superbody.edge.site import Site, SiteError
from superbody.host.aggregator import HostConfig
from superbody.host.filtering.pose_filter import FilterConfig
from superbody.host.tracking.config import TrackerConfig

__all__ = ["host_config"]

_TABLES: dict[str, type] = {"tracker": TrackerConfig, "filter": FilterConfig}


def _scalars(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls) if f.name not in _TABLES}


def _build(cls: type, table: Mapping[str, Any], where: str, site: Site, base: Any = None, **nested: Any) -> Any:
    if not isinstance(table, Mapping):
        raise SiteError(f"{site.source or site.name}: {where} must be a table")
    allowed = _scalars(cls) | (set(nested) if nested else set())
    unknown = sorted(set(table) - allowed - set(_TABLES if cls is HostConfig else ()))
    if unknown:
        raise SiteError(f"{site.source or site.name}: {where}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(sorted(_scalars(cls)))}")
    values = {k: v for k, v in table.items() if k in _scalars(cls)}
    try:
        return dataclasses.replace(base if base is not None else cls(), **values, **nested)
    except (ValueError, TypeError) as e:
        raise SiteError(f"{site.source or site.name}: {where}: {e}") from None


def host_config(site: Site, **overrides: Any) -> HostConfig:
    """The ``HostConfig`` the site file's ``[host]`` table gives, with ``overrides`` (HostConfig
    fields, e.g. from the command line) on top; ``tracker`` and ``filter`` overrides are mappings
    of their fields.

    Raises:
        SiteError: an unknown field or a value out of range (the message names the table and field).
    """
    table = dict(site.host)
    sub = {}
    for name in _TABLES:
        part = table.pop(name, {})
        if not isinstance(part, Mapping):
            raise SiteError(f"{site.source or site.name}: [host.{name}] must be a table, got {part!r}")
        sub[name] = dict(part)
    for name in _TABLES:
        sub[name].update(overrides.pop(name, None) or {})
    parts = {name: _build(cls, sub[name], f"[host.{name}]", site) for name, cls in _TABLES.items()}
    host_overrides = {k: v for k, v in overrides.items() if v is not None}
    for k in host_overrides:
        if k not in _scalars(HostConfig):
            raise ValueError(f"host_config: {k!r} is not a HostConfig field")
    return _build(HostConfig, {**table, **host_overrides}, "[host]", site, **parts)
