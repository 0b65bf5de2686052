"""The JSON Schemas (draft 2020-12) of the three superbody messages, generated from their types.

The typed message definitions are the source: ``edge.messages.wire.ObservationMsg``,
``host.messages.pose.PoseArrayMsg`` (what the host writes: version 2) and ``host.messages.status.HostStatus``.
``msgspec.json.schema_components`` turns them into JSON Schema; this module inlines the
definitions (one self-contained object per message, as MCAP and Foxglove take them) and adds the
``$schema``, ``$id``, title and the notes on what a JSON Schema cannot state. The files are
shipped in ``docs/schemas/`` (installed as the data package ``superbody.schemas``, read through
``edge.resources.json_schema``); ``tests/test_schemas.py`` regenerates them and fails if the
shipped files differ. After changing a message type::

    python -m superbody.host.messages.schemas --write      # rewrites docs/schemas/*.schema.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Final

import msgspec

from superbody.edge.messages import wire
from superbody.host.messages import pose, status

__all__ = ["MESSAGES", "FILES", "generate", "render"]

_INTEGERS_NOTE: Final[str] = ("JSON Schema counts 1.0 as an integer; the reference decoder rejects a float where an "
                              "integer is due.")

# Message name (edge.resources.MESSAGES) -> (type, $id, title, description).
MESSAGES: Final[dict[str, tuple[type, str, str, str]]] = {
    "observation": (
        wire.ObservationMsg, f"{wire.SCHEMA}/{wire.VERSION}", f"{wire.SCHEMA} version {wire.VERSION}",
        "One camera frame: the people a camera's 2D pose detector saw (docs/observation-schema.md). Ranges that depend "
        "on the image size (keypoints and bbox within [-W, 2W] x [-H, 2H], x0 <= x1, y0 <= y1), the histogram's sum and "
        "repeated keys are checked by the reference decoder, not here. " + _INTEGERS_NOTE,
    ),
    "people": (
        pose.PoseArrayMsg, f"{pose.SCHEMA}/{pose.VERSION}", f"{pose.SCHEMA} version {pose.VERSION}",
        "The host's PoseArray: each tracked person's floor pose (docs/pose-schema.md). Distinct ids and camera ids "
        "within a person, views >= len(cameras) and repeated keys are checked by the reference decoder, not here. "
        "Version 1 (still read by the reference decoder) is this without the per-person estimator. " + _INTEGERS_NOTE,
    ),
    "status": (
        status.HostStatus, f"{status.SCHEMA}/{status.VERSION}", f"{status.SCHEMA} version {status.VERSION}",
        "The host's periodic status on superbody/<site>/host/status (docs/status-schema.md). It may gain fields without a "
        "new version, so consumers must ignore fields they do not know.",
    ),
}
FILES: Final[dict[str, str]] = {name: f"{name}.schema.json" for name in MESSAGES}
DOCS_DIR: Final[Path] = Path(__file__).resolve().parents[2] / "docs" / "schemas"


def _inline(node: Any, defs: dict[str, Any]) -> Any:
    """``node`` with every ``{"$ref": "#/$defs/X"}`` replaced by (a copy of) X (the types are not
    recursive), and descriptions on one line."""
    if isinstance(node, dict):
        if set(node) == {"$ref"}:
            return _inline(defs[node["$ref"].rsplit("/", 1)[1]], defs)
        # Docstrings become descriptions: join their wrapped lines.
        return {k: " ".join(v.split()) if k == "description" and isinstance(v, str) else _inline(v, defs) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline(v, defs) for v in node]
    return node


def generate(message: str) -> dict[str, Any]:
    """The JSON Schema of ``message`` ("observation", "people" or "status") as a dict.

    Raises:
        ValueError: unknown message name (listing the valid ones).
    """
    if message not in MESSAGES:
        raise ValueError(f"unknown message {message!r}; messages: {', '.join(MESSAGES)}")
    cls, schema_id, title, description = MESSAGES[message]
    (ref,), defs = msgspec.json.schema_components([cls], ref_template="#/$defs/{name}")
    body = _inline(ref, defs)
    body.pop("title", None)
    body.pop("description", None)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": schema_id, "title": title,
            "description": description, **body}


def render(message: str) -> str:
    """The shipped file's text: ``generate(message)`` as indented JSON with a final newline."""
    return json.dumps(generate(message), indent=1, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m superbody.host.messages.schemas", description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help=f"write the files into {DOCS_DIR} (default: check them)")
    args = ap.parse_args(argv)
    stale = []
    for name, file_name in FILES.items():
        path = DOCS_DIR / file_name
        text = render(name)
        if args.write:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
        elif not path.is_file() or path.read_text(encoding="utf-8") != text:
            stale.append(str(path))
    if stale:
        print(f"schemas: error: out of date (run with --write): {', '.join(stale)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
