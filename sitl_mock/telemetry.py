"""Telemetry messages of the mock autopilot, and the schedule that streams them.

Builders take SI values in the project's frames (ENU, heading CCW from east [rad]) and do the
MAVLink unit conversions in one place: degE7, mm, cm/s, NED velocity, compass headings in
centidegrees, yaw clockwise from north.

Stream rates are wall-clock rates (what the GCS sees), independent of the simulation speed-up,
so a fleet at speed-up 10 loads the GCS like one at speed-up 1; the time fields (time_boot_ms)
carry simulated time. Each vehicle's phase is staggered by its index so a fleet's datagrams are
spread over the period instead of bursting at once.

Altitudes: GLOBAL_POSITION_INT.alt and VFR_HUD.alt are AMSL (the vehicle reports home's AMSL
altitude plus its ENU up); relative_alt is above home; HOME_POSITION.altitude is AMSL.
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = [
    "StreamSchedule",
    "attitude",
    "battery_status",
    "global_position_int",
    "heartbeat",
    "home_position",
    "statustext",
    "sys_status",
    "vfr_hud",
]

# Sensors a simple multirotor/plane reports present, enabled and healthy in SYS_STATUS:
# 3D gyro, accel, mag, abs pressure, GPS, motor outputs, AHRS, battery.
_SENSORS = 1 | 2 | 4 | 8 | 32 | 0x8000 | 0x200000 | 0x2000000
_CELLS = 4
_CELL_FULL_V, _CELL_EMPTY_V = 4.2, 3.5


class StreamSchedule:
    """Wall-clock due times of one stream group for ``n`` vehicles, staggered by index."""

    def __init__(self, n: int, rate_hz: float, now_s: float) -> None:
        if not (math.isfinite(rate_hz) and rate_hz >= 0.0):
            raise ValueError(f"stream rate_hz must be finite and >= 0, got {rate_hz!r}")
        self.period_s = 1.0 / rate_hz if rate_hz > 0 else math.inf
        self.next_due = (
            now_s + self.period_s * (np.arange(n) / max(n, 1)) if rate_hz > 0 else np.full(n, np.inf)
        )

    def due(self, now_s: float) -> np.ndarray:
        """Indices of vehicles due now; each due time moves one period on.

        A late tick is made up for at the following ticks (one message per tick), but never more
        than one period's worth, so a stalled loop does not burst afterwards.
        """
        idx = np.flatnonzero(self.next_due <= now_s)
        if idx.size:
            self.next_due[idx] = np.maximum(self.next_due[idx] + self.period_s, now_s - self.period_s)
        return idx


def global_position_int(
    time_boot_ms: int, lat_deg: float, lon_deg: float, alt_amsl_m: float, rel_alt_m: float,
    vel_enu_mps: tuple[float, float, float], psi_rad: float,
) -> mavlink.MAVLink_message:  # fmt: skip
    ve, vn, vu = vel_enu_mps
    return mavlink.MAVLink_global_position_int_message(
        time_boot_ms, round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_amsl_m * 1000.0),
        round(rel_alt_m * 1000.0), _i16(vn * 100.0), _i16(ve * 100.0), _i16(-vu * 100.0),
        round(compass_deg(psi_rad) * 100.0) % 36000,
    )  # fmt: skip


def attitude(
    time_boot_ms: int, roll_rad: float, pitch_rad: float, psi_rad: float, turn_rate_rps: float
) -> mavlink.MAVLink_message:
    """ATTITUDE; roll positive right wing down, yaw clockwise from north, yawspeed clockwise."""
    yaw = math.remainder(math.pi / 2 - psi_rad, 2 * math.pi)
    return mavlink.MAVLink_attitude_message(time_boot_ms, roll_rad, pitch_rad, yaw, 0.0, 0.0, -turn_rate_rps)


def vfr_hud(
    airspeed_mps: float, groundspeed_mps: float, psi_rad: float, throttle_pct: int, alt_amsl_m: float,
    climb_mps: float,
) -> mavlink.MAVLink_message:  # fmt: skip
    return mavlink.MAVLink_vfr_hud_message(
        airspeed_mps, groundspeed_mps, int(compass_deg(psi_rad)) % 360, throttle_pct, alt_amsl_m, climb_mps
    )


def sys_status(
    battery_remaining_pct: float, current_a: float, load_pct: float = 10.0, prearm_ok: bool = True
) -> mavlink.MAVLink_message:
    """SYS_STATUS; the PREARM_CHECK sensor bit is present and healthy once pre-arm checks pass
    (ArduPilot GCS_MAVLINK::update_sensor_status_flags, PX4 alike)."""
    voltage_mv = round(_pack_voltage_v(battery_remaining_pct) * 1000.0)
    present = _SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK
    health = present if prearm_ok else _SENSORS
    return mavlink.MAVLink_sys_status_message(
        present, present, health, round(load_pct * 10.0), voltage_mv, round(current_a * 100.0),
        round(battery_remaining_pct), 0, 0, 0, 0, 0, 0,
    )  # fmt: skip


def battery_status(
    battery_remaining_pct: float, current_a: float, consumed_mah: float
) -> mavlink.MAVLink_message:
    cell_mv = round(_pack_voltage_v(battery_remaining_pct) / _CELLS * 1000.0)
    voltages = [cell_mv] * _CELLS + [65535] * (10 - _CELLS)
    return mavlink.MAVLink_battery_status_message(
        0,
        1,
        2,
        2500,
        voltages,
        round(current_a * 100.0),
        round(consumed_mah),
        -1,
        round(battery_remaining_pct),
    )  # function ALL, type LIPO, 25.00 degC, energy unknown


def home_position(lat_deg: float, lon_deg: float, alt_amsl_m: float) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_home_position_message(
        round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_amsl_m * 1000.0), 0.0, 0.0, 0.0,
        [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
    )  # fmt: skip


def heartbeat(
    mav_type: int, autopilot: int, armed: bool, custom_mode: int, active: bool
) -> mavlink.MAVLink_message:
    base_mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
        mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
    )
    status = mavlink.MAV_STATE_ACTIVE if active else mavlink.MAV_STATE_STANDBY
    return mavlink.MAVLink_heartbeat_message(mav_type, autopilot, base_mode, custom_mode, status, 3)


def statustext(severity: int, text: str) -> mavlink.MAVLink_message:
    """STATUSTEXT (at most 50 characters; longer text is cut, as autopilots do)."""
    return mavlink.MAVLink_statustext_message(severity, text[:50].encode())


def compass_deg(psi_rad: float) -> float:
    """Heading CCW from east [rad] -> compass heading clockwise from north [deg, 0..360)."""
    return math.degrees(math.pi / 2 - psi_rad) % 360.0


def _pack_voltage_v(remaining_pct: float) -> float:
    return _CELLS * (_CELL_EMPTY_V + (_CELL_FULL_V - _CELL_EMPTY_V) * max(remaining_pct, 0.0) / 100.0)


def _i16(value: float) -> int:
    return max(-32768, min(32767, round(value)))
