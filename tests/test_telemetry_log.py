"""FlightLogger -> MCAP -> read_flight round trip with real pymavlink frames."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from mcap.reader import make_reader
from telemetry_frames import ORIGIN, SCENARIO_TEXT, flight_frames, make_plan, mavlink

from gcs_planner import __version__
from gcs_planner.telemetry import FlightLogger, read_flight
from gcs_planner.telemetry.encode import message_json
from gcs_planner.telemetry.schemas import (
    EVENT_SCHEMA,
    GEOJSON_SCHEMA,
    LOCATION_FIX_SCHEMA,
    mavlink_json_schema,
)

SYSIDS = [1, 2, 3]


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "flight.mcap"
    frames = flight_frames(SYSIDS, samples=60)
    with FlightLogger(path, ORIGIN, plan=make_plan(SYSIDS), scenario_text=SCENARIO_TEXT) as logger:
        for msg, raw, t_s in frames:
            logger.on_frame(msg, raw, t_s)
        logger.log_event({"type": "upload_done", "sysid": 2}, t_s=frames[-1][2])
    return path, frames


def test_every_vehicle_position_plan_and_metadata_read_back(logged):
    path, frames = logged
    flight = read_flight(path)
    assert not flight.truncated and flight.error is None
    assert flight.sysids == SYSIDS
    for s in SYSIDS:
        sent = [m for m, _, _ in frames if m.get_srcSystem() == s and m.get_type() == "GLOBAL_POSITION_INT"]
        track = flight.positions[s]
        assert len(track) == len(sent) == 60
        np.testing.assert_allclose(track.lat_deg, [m.lat * 1e-7 for m in sent], rtol=0, atol=1e-12)
        np.testing.assert_allclose(track.lon_deg, [m.lon * 1e-7 for m in sent], rtol=0, atol=1e-12)
        np.testing.assert_allclose(track.alt_m, [m.alt * 1e-3 for m in sent])
        np.testing.assert_allclose(track.rel_alt_m, 30.0)
        np.testing.assert_allclose(track.ground_speed_mps, 10.0)
        np.testing.assert_allclose(track.heading_deg, 90.0)
        np.testing.assert_allclose(np.diff(track.t_s), 0.1, atol=2e-6)  # us-rounded
        t, seq = flight.mission_current[s]
        assert list(seq) == list(range(6))
    assert flight.plan is not None and flight.plan.to_dict() == make_plan(SYSIDS).to_dict()
    assert flight.scenario_text == SCENARIO_TEXT
    meta = flight.metadata["gcs_planner"]
    assert meta["tool_version"] == __version__
    assert json.loads(meta["origin"]) == {
        "lat_deg": ORIGIN.lat_deg,
        "lon_deg": ORIGIN.lon_deg,
        "alt_m": ORIGIN.alt_m,
    }
    assert json.loads(meta["vehicles"]) == SYSIDS
    assert "AMSL" in json.loads(meta["altitude_datums"])["GLOBAL_POSITION_INT.alt"]
    assert json.loads(flight.metadata["gcs_planner.summary"]["frames_per_sysid"]) == {
        str(s): sum(1 for m, _, _ in frames if m.get_srcSystem() == s) for s in SYSIDS
    }
    assert flight.origin == ORIGIN
    assert flight.events == [(pytest.approx(frames[-1][2]), {"type": "upload_done", "sysid": 2})]


def test_raw_channel_keeps_every_frame_byte_for_byte(logged):
    path, frames = logged
    flight = read_flight(path)
    assert [f.data for f in flight.frames] == [raw for _, raw, _ in frames]
    assert [f.t_ns for f in flight.frames] == [round(t * 1e6) * 1000 for _, _, t in frames]  # whole us
    assert flight.recovered_messages > len(frames)  # raw + JSON + LocationFix + GeoJSON + events


def test_decoded_json_channels_match_pymavlink(logged):
    path, frames = logged
    flight = read_flight(path)
    assert {"GLOBAL_POSITION_INT", "HEARTBEAT", "MISSION_CURRENT", "STATUSTEXT"} <= flight.message_types()
    got = flight.messages("STATUSTEXT", sysid=2)
    assert [fields["text"] for _, _, fields in got] == ['vehicle "2" ready']
    sent = [m.to_dict() for m, _, _ in frames if m.get_srcSystem() == 3 and m.get_type() == "HEARTBEAT"]
    got = [fields for _, _, fields in flight.messages("HEARTBEAT", sysid=3)]
    assert got == [{k: v for k, v in d.items() if k != "mavpackettype"} for d in sent]


def test_standard_mcap_reader_sees_foxglove_channels_and_schemas(logged):
    path, _ = logged
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {s.name: s for s in summary.schemas.values()}
        assert {"foxglove.LocationFix", "foxglove.GeoJSON", "mavlink.GLOBAL_POSITION_INT"} <= set(schemas)
        assert all(s.encoding == "jsonschema" and b"$ref" not in s.data for s in schemas.values())
        topics = {c.topic for c in summary.channels.values()}
        assert {f"/vehicle/{s}/location" for s in SYSIDS} <= topics
        assert {"/plan/routes", "/scenario/obstacles", "/events"} <= topics
        fixes = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/vehicle/2/location"])]
        assert len(fixes) == 60 and fixes[0]["frame_id"] == "vehicle2"
        track = read_flight(path).positions[2]
        assert [f["latitude"] for f in fixes] == [round(v, 7) for v in track.lat_deg]
        assert [f["altitude"] for f in fixes] == [round(v, 3) for v in track.alt_m]  # AMSL
        assert [f["timestamp"]["sec"] * 10**9 + f["timestamp"]["nsec"] for f in fixes] == [
            round(t * 1e6) * 1000 for t in track.t_s
        ]
        assert set(json.loads(schemas["foxglove.LocationFix"].data)["required"]) <= set(fixes[0])
        routes = next(reader.iter_messages(topics=["/plan/routes"]))[2]
        collection = json.loads(json.loads(routes.data)["geojson"])
        assert [f["properties"]["sysid"] for f in collection["features"]] == SYSIDS
        assert {a.name for a in reader.iter_attachments()} == {"plan.json", "scenario.toml"}
        assert summary.statistics.message_count == read_flight(path).recovered_messages


def test_logger_writes_to_a_stream_and_a_tlog(tmp_path):
    frames = flight_frames([7], samples=5)
    stream = io.BytesIO()
    with FlightLogger(stream, ORIGIN, tlog_path=tmp_path / "f.tlog") as logger:
        for msg, raw, t_s in frames:
            logger.on_frame(msg, raw, t_s)
    logger.on_frame(*frames[0])  # a subscription outliving the logger: ignored, no error
    assert not stream.closed and stream.getvalue().endswith(b"\x89MCAP0\r\n")
    data = (tmp_path / "f.tlog").read_bytes()
    assert data == b"".join(int.to_bytes((round(t * 1e6)) & ~3, 8, "big") + raw for _, raw, t in frames)


def test_monotonic_clock_is_mapped_to_unix_time(tmp_path):
    frames = flight_frames([1], samples=3, t0_s=100.0)
    with FlightLogger(tmp_path / "m.mcap", ORIGIN) as logger:
        for msg, raw, t_s in frames:
            logger.on_frame(msg, raw, t_s)
    flight = read_flight(tmp_path / "m.mcap")
    assert flight.start_time_s > 1.6e9
    np.testing.assert_allclose(np.diff(flight.positions[1].t_s), 0.1, atol=2e-6)  # us-rounded


@pytest.mark.parametrize(
    "cls", sorted(mavlink.mavlink_map.values(), key=lambda c: c.id), ids=lambda c: c.msgname
)
def test_every_mavlink_type_encodes_as_json_matching_its_schema(cls):
    rng = np.random.default_rng(cls.id)
    values = []
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    for name, ctype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        n = lengths[name]
        if ctype == "char":
            values.append(b'a"\\b'[: n or 1])
        elif ctype in ("float", "double"):
            v = [float(x) for x in rng.normal(size=max(n, 1))]
            values.append(v if n else v[0])
        else:
            v = [int(x) for x in rng.integers(0, 100, size=max(n, 1))]
            values.append(v if n else v[0])
    raw = cls(*values).pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=1))
    msg = mavlink.MAVLink(None).decode(bytearray(raw))
    doc = json.loads(message_json(msg))
    expected = json.loads(json.dumps({k: v for k, v in msg.to_dict().items() if k != "mavpackettype"}))
    assert list(doc) == list(expected)
    for name, ctype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        if ctype == "float":  # printed with 9 significant digits: exact as float32
            np.testing.assert_array_equal(np.float32(doc[name]), np.float32(expected[name]), err_msg=name)
        else:
            assert doc[name] == expected[name], name
    schema = mavlink_json_schema(cls)
    assert schema["title"] == f"mavlink.{cls.msgname}" and list(schema["properties"]) == list(doc)
    assert "$ref" not in json.dumps(schema)
    _assert_foxglove_parsable(schema)


_FOXGLOVE_TYPES = {"boolean", "string", "number", "integer", "object", "array"}


def _assert_foxglove_parsable(schema: dict, path: str = "") -> None:
    """The rules of Foxglove's JSON Schema parser (mcap-support parseJsonSchema): object roots,
    one type string per field, arrays of scalars/objects, oneOf only with numeric consts."""
    assert schema["type"] == "object", path
    for name, field in schema["properties"].items():
        where = f"{path}.{name}"
        if "oneOf" in field:
            assert all(isinstance(alt["const"], int) for alt in field["oneOf"]), where
            continue
        assert field["type"] in _FOXGLOVE_TYPES, where
        if field["type"] == "object":
            _assert_foxglove_parsable(field, where)
        elif field["type"] == "array":
            assert field["items"]["type"] in _FOXGLOVE_TYPES - {"array"}, where
            if field["items"]["type"] == "object":
                _assert_foxglove_parsable(field["items"], where)


def test_foxglove_schemas_parse_with_foxgloves_rules():
    for schema in (LOCATION_FIX_SCHEMA, GEOJSON_SCHEMA, EVENT_SCHEMA):
        _assert_foxglove_parsable(schema)


def test_non_finite_floats_become_null():
    msg = mavlink.MAVLink_attitude_message(1, float("nan"), float("inf"), 0.5, 0.0, 0.0, 0.0)
    doc = json.loads(message_json(msg))
    assert doc["roll"] is None and doc["pitch"] is None and doc["yaw"] == 0.5


def test_link_loss_counts_sequence_gaps(tmp_path):
    frames = flight_frames([1, 2], samples=80)
    v1 = [f for f in frames if f[0].get_srcSystem() == 1]
    dropped = {id(f) for f in v1[1::4]}  # every 4th frame of vehicle 1 lost on the link
    kept = [f for f in frames if id(f) not in dropped]
    with FlightLogger(tmp_path / "lossy.mcap", ORIGIN) as logger:
        for msg, raw, t_s in kept:
            logger.on_frame(msg, raw, t_s)
    flight = read_flight(tmp_path / "lossy.mcap")
    t1, loss1 = flight.link_loss(1)
    t2, loss2 = flight.link_loss(2)
    assert len(t1) == 8 and np.all(loss2 == 0.0)
    assert 0.2 < float(np.mean(loss1)) < 0.3


def test_bad_data_keeps_its_raw_frame_but_gets_no_json_channel(tmp_path):
    msg, raw, t_s = flight_frames([4], samples=1)[0]
    bad = mavlink.MAVLink_bad_data(bytearray(raw), "test")
    with FlightLogger(tmp_path / "bad.mcap", ORIGIN) as logger:
        logger.on_frame(bad, raw, t_s)
        logger.on_frame(msg, raw, t_s + 0.1)
    flight = read_flight(tmp_path / "bad.mcap")
    assert [f.data for f in flight.frames] == [raw, raw]
    assert flight.message_types() == {msg.get_type()}
