"""Tests of the host status message (host/messages/status.py): strict JSON before the first latency
sample, the encoder's checks, and the decoder's errors."""

from __future__ import annotations

import json
import math

import pytest

from superbody.edge.messages.payload import REASONS, DecodeError
from superbody.host.messages import status as hs


def make_camera(**change) -> hs.CameraStatus:
    fields = dict(id="3", alive=True, state="too_late", fps=14.9, delay_ms=hs.delay(1.9, 2.3), frames=300, fused=0,
                  dropped={"too_late": 300}, problems=["too_late: frames arrive 2.30 s after capture (p95)"],
                  calibration=hs.Calibration(state="ok", residual_deg=0.8, residual_px=3.1, samples=1200))
    return hs.CameraStatus(**{**fields, **change})


def make_status(**change) -> hs.HostStatus:
    fields = dict(cameras_alive=["1", "2"], cameras_total=3, people=2, obs_per_s=44.9, latency_ms=hs.latency(1.84, 3.9),
                  rejected={"late": 2}, queue_dropped=0, published=431,
                  health=hs.Health(state="degraded", reasons=["camera 3: too_late: frames arrive 2.30 s after capture (p95)"]),
                  cameras=[make_camera()])
    return hs.HostStatus(**{**fields, **change})


def _strict_loads(payload: bytes):
    """A parser as strict as JSON.parse or serde_json: NaN and Infinity are not JSON."""
    def refuse(name: str):
        raise ValueError(f"{name} is not JSON")
    return json.loads(payload, parse_constant=refuse)


def test_no_latency_sample_yet_is_null_not_nan() -> None:
    """The defect of docs/status-schema.md: the host wrote the bare token NaN before the first sample."""
    status = make_status(latency_ms=hs.latency(math.nan, math.nan))
    doc = _strict_loads(hs.encode(status))
    assert doc["latency_ms"] == {"p50": None, "p99": None}
    assert hs.decode(hs.encode(status)) == status


def test_round_trip_and_field_order() -> None:
    status = make_status()
    payload = hs.encode(status)
    assert list(_strict_loads(payload)) == ["cameras_alive", "cameras_total", "people", "obs_per_s", "latency_ms", "rejected",
                                             "queue_dropped", "published", "health", "cameras"]
    assert hs.decode(payload) == status
    cam = _strict_loads(payload)["cameras"][0]
    assert list(cam) == ["id", "alive", "state", "fps", "delay_ms", "frames", "fused", "dropped", "problems", "calibration"]


def test_a_status_of_a_host_before_issue_37_still_decodes() -> None:
    # health and cameras came later, in version 1: a subscriber reads an older host's status too.
    doc = json.loads(hs.encode(make_status()))
    del doc["health"], doc["cameras"]
    old = hs.decode(json.dumps(doc).encode())
    assert old.health is None and old.cameras is None


def test_decoder_ignores_fields_it_does_not_know() -> None:
    doc = json.loads(hs.encode(make_status()))
    doc["cpu_percent"] = 12.5  # a later host may add fields without a version change
    assert hs.decode(json.dumps(doc).encode()) == make_status()


@pytest.mark.parametrize(
    "change, field",
    [
        ({"people": -1}, "people"),                                   # negative count
        ({"cameras_total": 0}, "cameras_total"),                      # a site has at least one camera
        ({"obs_per_s": math.inf}, "obs_per_s"),                       # would be written as null
        ({"obs_per_s": math.nan}, "obs_per_s"),
        ({"latency_ms": hs.Latency(p50=-1.0, p99=2.0)}, "latency_ms.p50"),
        ({"latency_ms": hs.Latency(p50=1.0, p99=math.nan)}, "latency_ms.p99"),  # use latency() to map NaN to null
        ({"cameras_alive": ["1", "1"]}, "cameras_alive"),             # repeated camera
        ({"cameras_alive": ["a b"]}, "cameras_alive"),                # outside the key alphabet
        ({"rejected": {"late": -2}}, "rejected"),
        ({"health": hs.Health(state="fine", reasons=[])}, "health"),                        # ok or degraded only
        ({"cameras": [make_camera(state="sleepy")]}, "cameras"),                          # a state it does not have
        ({"cameras": [make_camera(delay_ms=hs.Delay(p50=-1.0, p95=None))]}, "cameras"),  # a negative delay
        ({"cameras": [make_camera(calibration=hs.Calibration(state="ok", residual_deg=math.nan, samples=3))]}, "cameras"),  # NaN: use null
        ({"published": 1.0}, "published"),                            # a float for a counter
    ],
)
def test_encode_refuses_invalid_values(change: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"cannot encode host status: {field} "):
        hs.encode(make_status(**change))


def _payload(edit) -> bytes:
    doc = json.loads(hs.encode(make_status()))
    edit(doc)
    return json.dumps(doc).encode()


@pytest.mark.parametrize(
    "payload, field, reason",
    [
        (b"", "$", "not_json"),
        (b"[]", "$", "type"),
        (b'{"p": NaN}', "$", "non_finite"),
        (b"{" + b" " * hs.MAX_PAYLOAD_BYTES + b"}", "$", "oversize"),
        (_payload(lambda d: d.pop("published")), "published", "missing"),
        (_payload(lambda d: d.update(people=-1)), "people", "range"),
        (_payload(lambda d: d.update(people="2")), "people", "type"),
        (_payload(lambda d: d["latency_ms"].update(p50="x")), "latency_ms.p50", "type"),
        (_payload(lambda d: d["latency_ms"].pop("p99")), "latency_ms.p99", "missing"),
        (_payload(lambda d: d.update(cameras_alive=["1", "1"])), "cameras_alive", "range"),
        (hs.encode(make_status()).replace(b'"people":2', b'"people":2,"people":3'), "people", "duplicate_key"),
    ],
)
def test_bad_payload_names_field_and_reason(payload: bytes, field: str, reason: str) -> None:
    with pytest.raises(DecodeError) as info:
        hs.decode(payload)
    assert (info.value.field, info.value.reason) == (field, reason), str(info.value)
    assert info.value.reason in REASONS


def test_host_status_before_any_observation_is_strict_json() -> None:
    """A real host loop on loopback Zenoh, no camera: its status must parse as strict JSON, latency null."""
    import threading

    import zenoh

    from superbody.edge import transport
    from superbody.edge.clock import WorldClock
    from superbody.edge.site import load_site
    from superbody.host.aggregator import Aggregator, HostConfig
    from superbody.host.estimation.analytic import AnalyticEstimator
    from superbody.host.service import run_host
    from tests.conftest import WTF_SITE, free_port

    site = load_site(WTF_SITE)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    agg = Aggregator(site, AnalyticEstimator(site), "analytic", HostConfig(status_every_s=0.2))
    stop = threading.Event()
    host = threading.Thread(target=lambda: run_host(transport.session_config("peer", connect=[], listen=[endpoint]), agg,
                                                    WorldClock(), stop, duration_s=30), daemon=True)
    payloads: list[bytes] = []
    encodings: list[str] = []
    cv = threading.Condition()

    def on_status(sample) -> None:
        with cv:
            encodings.append(str(sample.encoding))
            payloads.append(sample.payload.to_bytes())
            cv.notify_all()

    host.start()
    try:
        with zenoh.open(transport.session_config("peer", connect=[endpoint])) as session:
            sub = session.declare_subscriber(transport.host_status_key(site.name), on_status)
            with cv:
                assert cv.wait_for(lambda: len(payloads) >= 2, timeout=20), "no host status"
            sub.undeclare()
    finally:
        stop.set()
        host.join(timeout=20)
    doc = _strict_loads(payloads[-1])
    assert doc["latency_ms"] == {"p50": None, "p99": None}
    assert hs.decode(payloads[-1]).cameras_total == len(site.cameras)
    assert set(encodings) == {hs.ENCODING} == {"application/json;superbody.host_status/1"}  # named and versioned, as every message
