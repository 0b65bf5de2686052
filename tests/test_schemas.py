"""The JSON Schemas shipped for subscribers (and written into MCAP recordings) are generated from
the typed message definitions, accept what the reference encoders write and the examples in the
docs, and reject what the reference decoders reject at the top level."""

from __future__ import annotations

import json
import math
import re
import time

import jsonschema
import numpy as np
import pytest

from superbody.edge.messages import wire
from superbody.edge.resources import MESSAGES, json_schema
from superbody.edge.sim import SimCamera, World
from superbody.edge.site import load_site
from superbody.host.messages import pose as pose_msg
from superbody.host.messages import schemas
from superbody.host.messages import status as host_status
from tests.conftest import ROOT, WTF_SITE


def _validator(message: str) -> jsonschema.protocols.Validator:
    schema = json.loads(json_schema(message))
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)  # a valid draft 2020-12 schema
    return cls(schema)


def _observations() -> list[dict]:
    site = load_site(WTF_SITE)
    world = World(site, 3, seed=1)
    t = time.time_ns()
    return [json.loads(wire.encode(SimCamera(world, cam).observe(t + k * 66_000_000)[0])) for cam in site.camera_ids for k in range(5)]


def _pose_array() -> dict:
    people = tuple(pose_msg.PersonPose(id=i, x=1.0 + i, y=-0.5, yaw=3.14159, vx=0.1, vy=0.0, yaw_rate=0.01, cov=np.eye(3) * 0.02,
                                       confidence=0.8, cameras=("1", "2"), stamp_ns=time.time_ns(), views=2, estimator="hybrid")
                   for i in range(3))
    arr = pose_msg.PoseArray(site="wtf-apartment", seq=1, stamp_ns=time.time_ns(), people=people, latency_ns=2_000_000,
                             cameras_alive=("1", "2", "3"), estimator="hybrid:wtf-apartment.int8.onnx")
    return json.loads(pose_msg.encode(arr))


STATUS = {"cameras_alive": ["1", "2"], "cameras_total": 3, "people": 2, "obs_per_s": 44.9, "latency_ms": {"p50": 1.8, "p99": 3.4},
          "rejected": {"late": 2}, "queue_dropped": 0, "published": 431}


def test_every_message_has_a_schema():
    assert set(MESSAGES) == {"observation", "people", "status"}
    with pytest.raises(ValueError, match="observation, people, status"):
        json_schema("poses")


def test_encoded_messages_validate():
    obs = _observations()
    assert any(o["people"] for o in obs)
    v = _validator("observation")
    for o in obs:
        v.validate(o)
    _validator("people").validate(_pose_array())
    _validator("status").validate(STATUS)
    _validator("status").validate({**STATUS, "latency_ms": {"p50": None, "p99": None}})  # no sample yet


# (message, a change to a valid document, why it is invalid)
BAD = [
    ("observation", lambda d: d.update(version=2), "unknown version"),
    ("observation", lambda d: d.update(extra=1), "unknown field"),
    ("observation", lambda d: d.update(camera="a b"), "camera id outside the key alphabet"),
    ("observation", lambda d: d.update(image=[8, 480]), "image too small"),
    ("people", lambda d: d["people"][0].update(yaw=4.0), "yaw outside [-pi, pi]"),
    ("people", lambda d: d["people"][0].pop("estimator"), "version 2 needs a per-person estimator"),
    ("people", lambda d: d["people"][0].update(cov=[0.0] * 5), "5 covariance entries"),
    ("people", lambda d: d.update(seq=-1), "negative seq"),
    ("status", lambda d: d.update(published=-1), "negative count"),
    ("status", lambda d: d.pop("cameras_alive"), "missing field"),
]


@pytest.mark.parametrize("message, change, why", BAD, ids=[b[2] for b in BAD])
def test_invalid_documents_fail(message, change, why):
    doc = {"observation": lambda: _observations()[0], "people": _pose_array, "status": lambda: json.loads(json.dumps(STATUS))}[message]()
    change(doc)
    with pytest.raises(jsonschema.ValidationError):
        _validator(message).validate(doc)


@pytest.mark.parametrize("message", sorted(MESSAGES))
def test_shipped_schemas_are_generated_from_the_types(message):
    """docs/schemas/ holds exactly what the generator writes (run python -m superbody.host.messages.schemas --write),
    and the package data is that file."""
    text = schemas.render(message)
    shipped = ROOT / "docs" / "schemas" / schemas.FILES[message]
    assert shipped.read_text(encoding="utf-8") == text, f"{shipped} is out of date: run python -m superbody.host.messages.schemas --write"
    assert json_schema(message) == text.encode("utf-8")
    assert schemas.main([]) == 0


def test_generator_reports_a_stale_file(tmp_path, monkeypatch, capsys):
    for name, file_name in schemas.FILES.items():
        (tmp_path / file_name).write_text(schemas.render(name), encoding="utf-8")
    monkeypatch.setattr(schemas, "DOCS_DIR", tmp_path)
    assert schemas.main([]) == 0
    (tmp_path / "people.schema.json").write_text("{}", encoding="utf-8")
    assert schemas.main([]) == 1
    assert "people.schema.json" in capsys.readouterr().err


@pytest.mark.parametrize("message, doc", [("observation", "observation-schema.md"), ("people", "pose-schema.md"), ("status", "status-schema.md")])
def test_docs_examples_validate(message, doc):
    blocks = re.findall(r"```json\n(.*?)\n```", (ROOT / "docs" / doc).read_text(encoding="utf-8"), re.S)
    assert blocks, f"docs/{doc} has no ```json example"
    for block in blocks:
        _validator(message).validate(json.loads(block))


def test_encoded_host_status_validates_with_and_without_latency():
    v = _validator("status")
    for p50, p99 in ((1.84, 3.9), (math.nan, math.nan)):
        status = host_status.HostStatus(cameras_alive=["1", "2"], cameras_total=3, people=2, obs_per_s=44.9,
                                        latency_ms=host_status.latency(p50, p99), rejected={"late": 2}, queue_dropped=0, published=431)
        v.validate(json.loads(host_status.encode(status)))
