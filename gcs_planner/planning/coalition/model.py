"""Coalition model (seed 003, eqs. 1-6, 13): UAVs, targets with their revealed needs, threats, parameters.

Read from a scenario: the common ``[[vehicles]]`` table gives id, sysid, start, speed and turn radius;
extra keys on each vehicle row carry the payload (``capabilities = "RSE"``, ``range_m``,
``munitions``, ``heading_deg``). ``[planner]`` holds the link and planner parameters
(CoalitionParams), ``[[coalition.targets]]`` the targets and ``[[coalition.threats]]`` the threats (see
missions/coalition_paper.toml).

Choices where the paper is open (documented here, used everywhere):
- Angles: attack / start angles are bearings *from the target* [deg], 0 = east, counter-clockwise.
  A strike ends at the stand-off point at that bearing, heading towards the target.
- Needs are counts and slots (eq. 6): one strike task per angle (munition consumed), one
  assessment task per angle (E payload). A UAV takes at most one task per coalition, since
  simultaneous strikes from different angles, 5 s sequential strikes and 20 s assessments cannot be
  flown by one vehicle.
- Resources are strict (the paper's examples are not): munitions decrease on each strike and a
  UAV without munitions never bids for a strike; the range used is speed x time flown.
- r_min, C^r, C^e, rewards F, decay beta, weights and ACO parameters are not in the paper;
  defaults below, all overridable in ``[planner]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from msgspec import Meta

from gcs_planner.core.config import (
    MAX_FACTOR,
    Count,
    Distance,
    DistanceStep,
    Duration,
    Fraction,
    NonNegative,
    Positive,
    PositiveDistance,
    parse,
)
from gcs_planner.core.validation import (
    MAX_DURATION_S,
    MAX_RADIUS_M,
    MAX_RANGE_M,
    InputError,
    items_of,
    number,
    table,
)
from gcs_planner.model.scenario import Scenario, ScenarioError
from gcs_planner.planning import PlannerConfig

__all__ = ["CoalitionParams", "Target", "Threat", "UavSpec", "World", "load_world"]

MAX_UAV_RANGE_M = 40_075_000.0  # once around the Earth: no UAV flies further on one charge or tank

STRIKE, ASSESS = 0, 1


@dataclass(frozen=True)
class UavSpec:
    """One UAV's fixed properties (Table 1): payload, speed [m/s], range [m], turn radius [m]."""

    index: int
    id: str
    sysid: int
    xy0: tuple[float, float]
    heading0_rad: float
    altitude_m: float
    speed_mps: float
    r_min_m: float
    range_max_m: float
    munitions: int
    recon: bool
    strike: bool
    assess: bool


@dataclass(frozen=True)
class Target:
    """A target: approximate and true position [m], recon need, needs revealed by recon (eq. 5)."""

    id: str
    approx_xy: tuple[float, float]
    xy: tuple[float, float]
    appear_s: float
    recon_s: float
    recon_angle_rad: float
    recon_uav: str | None
    strike_angles_rad: tuple[float, ...]
    strike_interval_s: float  # 0 = simultaneous, > 0 = sequential slots this far apart
    assess_angles_rad: tuple[float, ...]
    assess_delay_s: float  # after the last strike
    assess_duration_s: float
    reward: float  # F_jk of every task of this target
    decay_per_s: float  # beta_j

    def tasks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Task arrays (kind STRIKE/ASSESS, angle [rad], slot offset [s]) in slot order."""
        ns, ne = len(self.strike_angles_rad), len(self.assess_angles_rad)
        kind = np.r_[np.full(ns, STRIKE), np.full(ne, ASSESS)]
        angle = np.r_[self.strike_angles_rad, self.assess_angles_rad]
        offset = np.r_[np.arange(ns) * self.strike_interval_s, np.zeros(ne)]
        return kind, angle, offset


@dataclass(frozen=True)
class Threat:
    """Vertical cylinder threat (eq. 13): centre [m], radius r_T [m]; known from appear_s (0 = static)."""

    x: float
    y: float
    radius_m: float
    appear_s: float = 0.0


class CoalitionParams(PlannerConfig, tag="coalition"):
    """The [planner] table: link (section 3), path and optimiser parameters. Times [s], distances [m]."""

    link_range_m: Distance = 1500.0
    delay_s: Duration = 0.2
    t_ta_s: Duration = 0.5
    margin_s: Duration = 0.3
    delay_jitter_s: Duration = 0.0  # extra uniform one-way delay in [0, jitter]
    standoff_m: Distance = 200.0
    kappa: Annotated[float, Meta(ge=1.0, le=10.0)] = 1.3  # r_D = kappa r_T: outside the threat, near it
    detect_radius_m: Annotated[float, Meta(ge=1.0, le=MAX_RADIUS_M)] = 400.0
    assess_radius_m: Annotated[float, Meta(ge=1.0, le=MAX_RADIUS_M)] = 500.0
    loiter_radius_m: PositiveDistance = 300.0
    station_radius_m: PositiveDistance = 1000.0  # idle UAVs loiter on this ring about the nearest target
    retender_s: Duration = 10.0
    t_end_s: Annotated[float, Meta(gt=0.0, le=MAX_DURATION_S)] = 400.0
    method: Literal["aco", "polynomial", "global"] = "aco"
    w1: NonNegative = 1.0
    w2: NonNegative = 0.3
    w3: NonNegative = 0.5
    time_scale_s: Annotated[float, Meta(gt=0.0, le=MAX_DURATION_S)] = 60.0  # J3 normaliser, eq. 31 window
    ants: Count = 30  # clusters (choice: 30 x 6 instead of 10 x 15, see docs/coalition.md)
    iterations: Count = 6
    alpha: NonNegative = 1.0
    beta: NonNegative = 2.0
    q0: Fraction = 0.9
    rho: Fraction = 0.1
    tau0: Positive = 1.0
    sample_ds_m: DistanceStep = 10.0

    @property
    def delta_max_s(self) -> float:
        """Eq. 20: three one-way messages, formation compute and margin."""
        return 3.0 * self.delay_s + self.t_ta_s + self.margin_s


@dataclass
class World:
    uavs: list[UavSpec]
    targets: list[Target]
    threats: list[Threat]
    params: CoalitionParams
    extra_delay_s: dict[str, float] = field(default_factory=dict)  # per-UAV added delay (tests)


def load_world(scenario: Scenario) -> World:
    """Build the coalition model from a scenario; errors name the field and value."""
    raw = scenario.raw
    where = str(scenario.path or scenario.name)
    try:  # the numbers' errors (InputError) get the scenario's name here, once
        section = table(raw.get("coalition", {}), "[coalition]")
        params = parse(CoalitionParams, scenario.planner, "planner")
        targets_rows = items_of(section.get("targets", []), "coalition.targets")
        threat_rows = items_of(section.get("threats", []), "coalition.threats")
        rows = raw.get("vehicles", [])
        uavs = [_uav(i, v, rows[i] if i < len(rows) else {}) for i, v in enumerate(scenario.vehicles)]
        targets = [_target(t, f"coalition.targets[{i}]") for i, t in enumerate(targets_rows)]
        threats = [_threat(d, f"coalition.threats[{i}]") for i, d in enumerate(threat_rows)]
    except InputError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    ids = {u.id for u in uavs}
    for t in targets:
        if t.recon_uav is not None and t.recon_uav not in ids:
            raise ScenarioError(f"{where}: target {t.id}: recon_uav {t.recon_uav!r} is not a vehicle id")
    return World(uavs=uavs, targets=targets, threats=threats, params=params)


def _threat(d: dict[str, Any], where: str) -> Threat:
    return Threat(
        x=_num(d, "x", where, None, -MAX_RANGE_M, MAX_RANGE_M),
        y=_num(d, "y", where, None, -MAX_RANGE_M, MAX_RANGE_M),
        radius_m=_num(d, "radius_m", where, None, 0.0, MAX_RADIUS_M, True),
        appear_s=_num(d, "appear_s", where, 0.0, -MAX_DURATION_S),
    )


def _uav(index: int, v, row: dict[str, Any]) -> UavSpec:
    at = f"vehicle {v.id}"
    caps = str(row.get("capabilities", "RSE")).upper()
    if not caps or set(caps) - set("RSE"):
        raise InputError(f"{at}: capabilities must be letters of 'RSE', got {caps!r}")
    munitions = row.get("munitions", 0)
    if not isinstance(munitions, int) or munitions < 0:
        raise InputError(f"{at}: munitions must be an integer >= 0, got {munitions!r}")
    if v.turn_radius_m <= 0:
        raise InputError(f"{at}: turn_radius_m must be > 0, got {v.turn_radius_m!r}")
    return UavSpec(
        index=index,
        id=v.id,
        sysid=v.sysid,
        xy0=(v.start[0], v.start[1]),
        heading0_rad=np.radians(_num(row, "heading_deg", at, 90.0, -360.0, 360.0)),
        altitude_m=v.start[2],
        speed_mps=v.speed_mps,
        r_min_m=v.turn_radius_m,
        range_max_m=_num(row, "range_m", at, 20000.0, 0.0, MAX_UAV_RANGE_M, True),
        munitions=munitions if "S" in caps else 0,
        recon="R" in caps,
        strike="S" in caps and munitions > 0,
        assess="E" in caps,
    )


def _target(d: dict[str, Any], where: str) -> Target:
    timing = d.get("strike_timing", "simultaneous")
    if timing not in ("simultaneous", "sequential"):
        raise InputError(f"{where}: strike_timing must be simultaneous|sequential, got {timing!r}")
    interval = _num(d, "strike_interval_s", where, 5.0, 0.0, lo_open=True) if timing == "sequential" else 0.0
    return Target(
        id=str(d.get("id", "T?")),
        approx_xy=_xy(d, "approx", where, _xy(d, "position", where)),
        xy=_xy(d, "position", where),
        appear_s=_num(d, "appear_s", where, 0.0),
        recon_s=_num(d, "recon_s", where, 20.0),
        recon_angle_rad=np.radians(_num(d, "recon_angle_deg", where, 90.0, -360.0, 360.0)),
        recon_uav=d.get("recon_uav"),
        strike_angles_rad=tuple(np.radians(_angles(d, "strike_angles_deg", where))),
        strike_interval_s=interval,
        assess_angles_rad=tuple(np.radians(_angles(d, "assess_angles_deg", where))),
        assess_delay_s=_num(d, "assess_delay_s", where, 10.0),
        assess_duration_s=_num(d, "assess_duration_s", where, 20.0),
        reward=_num(d, "reward", where, 10.0, 0.0, MAX_FACTOR, True),
        decay_per_s=_num(d, "decay_per_s", where, 0.002, 0.0, MAX_FACTOR),
    )


def _angles(d: dict[str, Any], key: str, where: str) -> list[float]:
    value = d.get(key, [])
    if not isinstance(value, list):
        raise InputError(f"{where}: {key} must be a list of degrees, got {value!r}")
    return [number(a, f"{where}: {key}[{k}]", -360.0, 360.0) for k, a in enumerate(value)]


def _xy(d: dict[str, Any], key: str, where: str, default=None) -> tuple[float, float]:
    value = d.get(key)
    if value is None and default is not None:
        return default
    if not (isinstance(value, list) and len(value) == 2):
        raise InputError(f"{where}: {key} must be [x, y] in metres, got {value!r}")
    x, y = (number(a, f"{where}: {key}[{k}]", -MAX_RANGE_M, MAX_RANGE_M) for k, a in enumerate(value))
    return x, y


def _num(
    d: dict[str, Any],
    key: str,
    where: str,
    default: float | None = None,
    lo: float = 0.0,
    hi: float = MAX_DURATION_S,
    lo_open: bool = False,
) -> float:
    """``d[key]`` (or ``default``) within [lo, hi] (lo excluded when ``lo_open``); the defaults
    bound a time. InputError naming the field and value otherwise."""
    value = d.get(key, default)
    if value is None:
        raise InputError(f"{where}: missing {key}")
    return number(value, f"{where}: {key}", lo, hi, lo_open=lo_open)
