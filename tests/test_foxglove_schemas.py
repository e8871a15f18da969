"""The schema'd JSON channels of our logs are Foxglove's messages: every LocationFix and GeoJSON
message builds a foxglove-sdk message (foxglove.messages, Foxglove's published schemas) from its
fields, unknown or mistyped fields fail, and it encodes."""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import pytest
from mcap.reader import make_reader
from telemetry_frames import ORIGIN, SCENARIO_TEXT, flight_frames, make_plan

from gcs_planner.telemetry import FlightLogger
from gcs_planner.telemetry.log_import import import_log

with warnings.catch_warnings():
    warnings.simplefilter("ignore", DeprecationWarning)
    fm = pytest.importorskip("foxglove.messages", reason="foxglove-sdk (the test extra) is not installed")

LOGS = (
    Path(os.environ.get("GCS_PLANNER_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))
    / "logs"
)
NESTED = {"timestamp": fm.Timestamp, "color": fm.Color}
ENUMS = {"position_covariance_type": fm.LocationFixPositionCovarianceType}


def foxglove_message(cls, fields: dict):
    """Build ``cls`` from a JSON message's fields as Foxglove's schema names and types them."""
    kwargs = {}
    for key, value in fields.items():
        if key in NESTED:
            value = NESTED[key](**value)
        elif key in ENUMS:
            (value,) = [v for v in vars(ENUMS[key]).values() if getattr(v, "value", None) == value]
        kwargs[key] = value
    return cls(**kwargs)


def check_channels(path: Path) -> dict[str, int]:
    """Validate every foxglove.* message of a log; returns messages checked per schema."""
    checked: dict[str, int] = {}
    with open(path, "rb") as f:
        for schema, _, message in make_reader(f).iter_messages():
            if schema is None or not schema.name.startswith("foxglove."):
                continue
            cls = {"foxglove.LocationFix": fm.LocationFix, "foxglove.GeoJSON": fm.GeoJson}[schema.name]
            fields = json.loads(message.data)
            assert foxglove_message(cls, fields).encode()
            if cls is fm.GeoJson:
                assert json.loads(fields["geojson"])["type"] == "FeatureCollection"
            checked[schema.name] = checked.get(schema.name, 0) + 1
    return checked


def test_a_flown_log_has_foxglove_channels(tmp_path):
    path = tmp_path / "flight.mcap"
    with FlightLogger(path, ORIGIN, plan=make_plan([1, 2]), scenario_text=SCENARIO_TEXT) as logger:
        for msg, raw, t_s in flight_frames([1, 2], samples=10):
            logger.on_frame(msg, raw, t_s)
    checked = check_channels(path)
    assert checked["foxglove.LocationFix"] == 20 and checked["foxglove.GeoJSON"] == 2  # routes, obstacles


@pytest.mark.skipif(not LOGS.is_dir(), reason=f"no corpus logs at {LOGS}")
@pytest.mark.parametrize(
    "name", ["pymavlink/test.BIN", "pyulog/sample_log_small.ulg", "UAVLogViewer/vtol.tlog"]
)
def test_imported_logs_have_foxglove_location_fixes(tmp_path, name):
    import_log(LOGS / name, tmp_path / "i.mcap")
    assert check_channels(tmp_path / "i.mcap")["foxglove.LocationFix"] > 0
