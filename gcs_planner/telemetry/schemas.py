"""JSON Schemas for the MCAP log: one per MAVLink message type, plus Foxglove's map schemas.

MAVLink schemas are generated from pymavlink's message classes (field names in declaration
order, C types, array lengths, units, enums), so any MCAP tool can name and type every field.
They use no ``$ref`` (Foxglove does not resolve it) and only what Foxglove's JSON Schema parser
accepts: one ``type`` string per field (no ``["number", "null"]`` unions), numeric ``oneOf``
constants for enums. Field values are logged as pymavlink
decodes them: integers and floats as JSON numbers, ``char[n]`` as a string, other arrays as
arrays of numbers; non-finite floats become ``null``.

Foxglove schemas keep Foxglove's names exactly (``foxglove.LocationFix``, ``foxglove.GeoJSON``)
with the fields we fill; see https://docs.foxglove.dev/docs/visualization/message-schemas.

Altitude datums (also written to the log's metadata):
- GLOBAL_POSITION_INT.alt: AMSL [mm]; relative_alt: above home [mm].
- foxglove.LocationFix.altitude: we write GLOBAL_POSITION_INT.alt, i.e. AMSL [m], although
  LocationFix is conventionally above the WGS84 ellipsoid (no geoid model is bundled; the
  difference is the local geoid undulation, tens of metres).
"""

from __future__ import annotations

import json
from functools import cache

__all__ = [
    "ALTITUDE_DATUMS",
    "EVENT_SCHEMA",
    "GEOJSON_SCHEMA",
    "LOCATION_FIX_SCHEMA",
    "mavlink_json_schema",
    "schema_bytes",
]

ALTITUDE_DATUMS = {
    "GLOBAL_POSITION_INT.alt": "AMSL [mm]",
    "GLOBAL_POSITION_INT.relative_alt": "above home [mm]",
    "foxglove.LocationFix.altitude": "AMSL [m] (copied from GLOBAL_POSITION_INT.alt; not WGS84 ellipsoid)",
    "Flight.positions.alt_m": "AMSL [m]",
    "Flight.positions.rel_alt_m": "above home [m]",
    "origin.alt_m": "AMSL [m]",
}

_INT_RANGES = {
    "int8_t": (-(2**7), 2**7 - 1),
    "uint8_t": (0, 2**8 - 1),
    "int16_t": (-(2**15), 2**15 - 1),
    "uint16_t": (0, 2**16 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
    "uint8_t_mavlink_version": (0, 2**8 - 1),
}


def _field_schema(ctype: str, length: int, unit: str, enum: str) -> dict:
    if ctype == "char":
        item: dict = {"type": "string"}
        if length:
            item["maxLength"] = length
        return item
    if ctype in ("float", "double"):
        scalar: dict = {"type": "number"}  # non-finite values are written as null
    else:
        lo, hi = _INT_RANGES.get(ctype, (None, None))
        scalar = {"type": "integer"}
        if lo is not None:
            scalar.update(minimum=lo, maximum=hi)
    notes = [ctype + (f"[{length}]" if length else "")]
    if unit:
        notes.append(f"unit {unit}")
    if enum:
        notes.append(f"enum {enum}")
    description = ", ".join(notes)
    if length:
        return {"type": "array", "items": scalar, "maxItems": length, "description": description}
    return {**scalar, "description": description}


@cache
def mavlink_json_schema(msg_class: type) -> dict:
    """JSON Schema (draft 2020-12 subset, no $ref) for one pymavlink message class."""
    lengths = dict(zip(msg_class.ordered_fieldnames, msg_class.array_lengths, strict=True))
    units = msg_class.fieldunits_by_name
    enums = msg_class.fieldenums_by_name
    properties = {
        name: _field_schema(ctype, lengths.get(name, 0), units.get(name, ""), enums.get(name, ""))
        for name, ctype in zip(msg_class.fieldnames, msg_class.fieldtypes, strict=True)
    }
    return {
        "title": f"mavlink.{msg_class.msgname}",
        "description": f"MAVLink message {msg_class.msgname} (id {msg_class.id}) as decoded by pymavlink",
        "type": "object",
        "properties": properties,
        "required": list(msg_class.fieldnames),
    }


def _number(description: str) -> dict:
    return {"type": "number", "description": description}


LOCATION_FIX_SCHEMA = {
    "title": "foxglove.LocationFix",
    "description": "A navigation satellite fix for any Global Navigation Satellite System",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "title": "time",
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
            },
            "description": "Timestamp of the message",
        },
        "frame_id": {"type": "string", "description": "Frame for the sensor"},
        "latitude": _number("Latitude in degrees"),
        "longitude": _number("Longitude in degrees"),
        "altitude": _number("Altitude in meters (here: AMSL, from GLOBAL_POSITION_INT.alt)"),
        "position_covariance": {
            "type": "array",
            "items": {"type": "number"},
            "minItems": 9,
            "maxItems": 9,
            "description": "Position covariance (m^2), ENU, row-major",
        },
        "position_covariance_type": {
            "title": "foxglove.PositionCovarianceType",
            "description": "Type of position_covariance",
            "oneOf": [
                {"title": "UNKNOWN", "const": 0},
                {"title": "APPROXIMATED", "const": 1},
                {"title": "DIAGONAL_KNOWN", "const": 2},
                {"title": "KNOWN", "const": 3},
            ],
        },
        "color": {
            "title": "foxglove.Color",
            "description": "Color used to visualize the location",
            "type": "object",
            "properties": {c: _number(f"{c} in [0, 1]") for c in "rgba"},
            "required": ["r", "g", "b", "a"],
        },
    },
    "required": [
        "timestamp",
        "frame_id",
        "latitude",
        "longitude",
        "altitude",
        "position_covariance",
        "position_covariance_type",
    ],
}

GEOJSON_SCHEMA = {
    "title": "foxglove.GeoJSON",
    "description": "GeoJSON data for annotating maps",
    "type": "object",
    "properties": {"geojson": {"type": "string", "description": "GeoJSON data encoded as a UTF-8 string"}},
    "required": ["geojson"],
}

EVENT_SCHEMA = {
    "title": "gcs_planner.Event",
    "description": "A planner or flight event: free-form JSON object named by a 'type' or 'event' string",
    "type": "object",
    "properties": {"type": {"type": "string"}, "event": {"type": "string"}},
}


def record_json_schema(title: str, fields: dict) -> dict:
    """JSON schema of a log record (DataFlash, ULog) from one record's fields and their types."""

    def kind(value) -> dict:
        if isinstance(value, bool):
            return {"type": "boolean"}
        if isinstance(value, int):
            return {"type": "integer"}
        if isinstance(value, float) or value is None:
            return {"type": ["number", "null"]}
        if isinstance(value, list):
            return {"type": "array"}
        return {"type": "string"}

    properties = {k: kind(v) for k, v in fields.items()}
    return {"title": title, "type": "object", "properties": properties}


def schema_bytes(schema: dict) -> bytes:
    return json.dumps(schema, separators=(",", ":")).encode()
