"""Mission execution and guided actions of one mock vehicle, on top of the batch kinematics.

The navigator turns the current mission item (or a guided action: takeoff, hold, RTL, land) into
a guidance command for its row of `Kinematics`, then waits for one event: arrival (the fleet
calls `on_arrived`) or a simulated-time timer (`on_timer`). Continuations are stored as the
next callable, so each action reads top to bottom.

Supported items: NAV_WAYPOINT (param1 hold [s], param2 acceptance radius [m], 0 = airframe
default), NAV_TAKEOFF (climbs vertically where it is, like ArduCopter), DO_CHANGE_SPEED (param2
[m/s], clamped to the airframe's limits), NAV_LOITER_TIME (param1 [s], param3 radius [m]),
NAV_LOITER_UNLIM, NAV_LAND (lat/lon 0 = here), NAV_RETURN_TO_LAUNCH, NAV_DELAY (param1 [s]; waits
on the ground or holds in the air; the UTC time-of-day form counts as no delay). Others are
skipped with a STATUSTEXT, as ArduPilot skips commands it cannot run.

Choices where the spec or the autopilots differ:
- MISSION_ITEM_REACHED is sent for every item: for a nav item when its position or altitude is
  reached (before any hold or loiter time, as the MAVLink spec describes), at touchdown for
  LAND and for RTL on a multirotor, and when a DO item has been executed.
- A multirotor passes through a waypoint without braking when the next nav item is also a
  waypoint and there is no hold time; otherwise it stops at the waypoint. A fixed wing never
  stops, and counts a waypoint reached inside its radius or once past it (ArduPlane).
- After the last item the vehicle holds (hover / loiter circle) in AUTO; mission_state COMPLETE.
- Per autopilot (profiles.FlightRules): ArduCopter's final NAV_LAND ends in a disarm that resets
  the mission (no ITEM_REACHED, no COMPLETE); ArduPlane runs NAV_RETURN_TO_LAUNCH by switching
  to mode RTL; ArduPlane reads DO_CHANGE_SPEED type 1 as a minimum ground speed and ignores an
  airspeed outside its AIRSPEED_MIN..AIRSPEED_MAX.
- RTL: to home at max(current altitude, ``RTL_ALT_M`` above home), then a multirotor lands and
  disarms, a fixed wing circles home.
- Item altitudes: frames GLOBAL(_INT) are AMSL, GLOBAL_RELATIVE_ALT(_INT) and the terrain frames
  are above home (flat terrain at home altitude).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from gcs_planner.wire.enums import MissionState
from gcs_planner.wire.types import MissionItem
from sitl_mock.flight import Airframe, Arrival, Guidance
from sitl_mock.geodesy import to_enu
from sitl_mock.profiles import FlightRules
from sitl_mock.world import World

__all__ = ["RTL_ALT_M", "Navigator"]

log = logging.getLogger(__name__)

NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME = 16, 17, 19
NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF, NAV_DELAY = 20, 21, 22, 93
DO_CHANGE_SPEED = 178
ARC_LEG_FACTOR = 4.0  # legs shorter than this x acceptance radius are samples of an arc
STOP_LEG_M = 0.5  # a next leg shorter than this means: stop at this waypoint
NAV_COMMANDS = {
    NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF, NAV_DELAY,
}  # fmt: skip
AMSL_FRAMES = {0, 5}  # MAV_FRAME_GLOBAL, GLOBAL_INT
RTL_ALT_M = 15.0


class Navigator:
    """What one vehicle flies: mission items in AUTO, or a guided action."""

    def __init__(
        self,
        world: World,
        index: int,
        airframe: Airframe,
        home_enu_m: np.ndarray,
        first_seq: int,
        emit_reached: Callable[[int], None],
        emit_progress: Callable[[], None],
        emit_text: Callable[[str], None],
        landed: Callable[[], None],
        flight: FlightRules,
        enter_mode: Callable[[str], bool],
        airspeed_allowed: Callable[[float], bool] = lambda speed_mps: True,
    ) -> None:
        self.world, self.i, self.airframe = world, index, airframe
        self.home_enu_m = np.asarray(home_enu_m, dtype=float)
        self.first_seq = first_seq
        self._emit_reached, self._emit_progress = emit_reached, emit_progress
        self._emit_text, self._landed = emit_text, landed
        self.flight, self._enter_mode = flight, enter_mode
        self._airspeed_allowed = airspeed_allowed
        self.items: list[MissionItem] = []
        self._targets = np.zeros((0, 3))
        self.seq = 0
        self.last_seq = -1
        self.state = MissionState.NO_MISSION
        self.running = False
        self.reached: list[tuple[int, float]] = []  # (seq, sim time [s]) in order
        self._next_arrival: Callable[[], None] | None = None
        self._next_timer: Callable[[], None] | None = None

    # --- mission list ------------------------------------------------------------------------
    @property
    def has_mission(self) -> bool:
        return len(self.items) > self.first_seq

    @property
    def total(self) -> int:
        """MISSION_CURRENT.total: executable items (home excluded), 65535 without a mission."""
        return len(self.items) - self.first_seq if self.has_mission else 65535

    def load(self, items: list[MissionItem]) -> None:
        """Take a new mission list; a running mission continues at the same seq with the new items."""
        self.items = list(items)
        self._targets = self._item_targets(self.items)
        self.last_seq = len(self.items) - 1
        if not self.has_mission:
            self.running = False
            self.state = MissionState.NO_MISSION
            self.seq = 0
            self.hold()
        elif self.running:
            self.seq = min(max(self.seq, self.first_seq), self.last_seq)
            self._execute()
        else:
            self.seq = self.first_seq
            self.state = MissionState.NOT_STARTED
        self._emit_progress()

    def set_current(self, seq: int) -> bool:
        """Jump to item ``seq``; False (nothing changed) when it is out of range."""
        if not (0 <= seq < len(self.items)) or not self.has_mission:
            return False
        self.seq = max(seq, self.first_seq)
        if self.running:
            self._execute()
        elif self.state == MissionState.COMPLETE:
            self.state = MissionState.PAUSED
        self._emit_progress()
        return True

    def start(self, first: int | None = None, last: int | None = None) -> None:
        """Run the mission (AUTO and armed): from ``first`` (default: current) to ``last`` (default: end)."""
        if not self.has_mission:
            return
        if first is not None:
            self.seq = max(first, self.first_seq)
        elif self.state == MissionState.COMPLETE:
            self.seq = self.first_seq
        self.last_seq = len(self.items) - 1 if last is None else last
        self.running = True
        self.state = MissionState.ACTIVE
        self._execute()
        self._emit_progress()

    def reset(self) -> None:
        """Back to the first item, never started (ArduCopter's disarm: AP_Mission::reset)."""
        self.running = False
        self.seq = self.first_seq
        self.state = MissionState.NOT_STARTED if self.has_mission else MissionState.NO_MISSION

    def pause(self) -> None:
        """Leave the mission (mode changed away from AUTO): PAUSED if it was running."""
        if self.running:
            self.running = False
            self.state = MissionState.PAUSED
            self._emit_progress()

    # --- guided actions ----------------------------------------------------------------------
    def idle(self) -> None:
        self._wait(None)
        self.world.kin.command(self.i, Guidance.IDLE)

    def hold(self) -> None:
        """Hover here, or circle here at the default loiter radius; on the ground: stay idle."""
        kin = self.world.kin
        if not kin.airborne()[self.i]:
            self.idle()
            return
        self._wait(None)
        kin.loiter_r[self.i] = max(self.airframe.loiter_radius_m, 1.0)
        kin.command(self.i, Guidance.HOLD, kin.pos[self.i].copy())

    def takeoff(self, alt_m: float, done: Callable[[], None] | None = None, run_m: float = math.inf) -> None:
        """Climb to ``alt_m`` above home, then hold (or call ``done``). With ``run_m`` (ArduPlane's
        TAKEOFF mode, TKOFF_DIST) the straight climb ends that far from its start, flown at cruise,
        and the plane climbs on to ``alt_m`` circling there (ModeTakeoff::update: the take-off stage
        ends at TKOFF_ALT - 2 m or TKOFF_DIST from the start, whichever first, then it loiters at the
        point TKOFF_DIST along its climb-out at TKOFF_ALT; TKOFF_DIST 0 ends the stage at once)."""
        kin, i = self.world.kin, self.i
        start = kin.pos[i].copy()
        target = start.copy()
        target[2] = self.home_enu_m[2] + alt_m
        end = done or self.hold

        def arrived() -> None:
            self.world.timers[i], self._next_timer = np.inf, None  # the run no longer ends it
            end()

        self._wait(arrived)
        kin.command(i, Guidance.CLIMB, target, Arrival.ALTITUDE)
        if math.isfinite(run_m):
            self._after(max(run_m, 0.0) / max(self.airframe.cruise_speed_mps, 1e-3),
                        lambda: self._loiter_climb(start, max(run_m, 0.0), float(target[2])))  # fmt: skip

    def _loiter_climb(self, start: np.ndarray, run_m: float, z_m: float) -> None:
        """Circle the point ``run_m`` from ``start`` along the climb-out, climbing to ``z_m``."""
        kin, i = self.world.kin, self.i
        away = kin.pos[i, :2] - start[:2]
        along = (
            away / np.hypot(*away)
            if np.hypot(*away) > 1e-3
            else np.array([np.cos(kin.psi[i]), np.sin(kin.psi[i])])
        )
        self._wait(None)
        kin.loiter_r[i] = max(self.airframe.loiter_radius_m, 1.0)
        kin.command(i, Guidance.HOLD, np.array([*(start[:2] + run_m * along), z_m]))

    def land(self, target_m: np.ndarray | None = None, done: Callable[[], None] | None = None) -> None:
        """Land at ``target_m``'s horizontal position (default: here); disarm on touchdown."""
        kin = self.world.kin
        target = kin.pos[self.i].copy() if target_m is None else np.asarray(target_m, dtype=float).copy()
        target[2] = kin.ground_z[self.i]
        kin.loiter_r[self.i] = max(self.airframe.loiter_radius_m, 1.0)

        def touchdown() -> None:
            self.idle()
            if done is not None:
                done()
            self._landed()

        self._wait(touchdown)
        kin.command(self.i, Guidance.LAND, target, Arrival.LANDED, max(self.airframe.accept_radius_m, 1.0))

    def rtl(self, done: Callable[[], None] | None = None) -> None:
        """Return home at RTL altitude; a multirotor lands there, a fixed wing circles it."""
        kin = self.world.kin
        target = self.home_enu_m.copy()
        target[2] = max(kin.pos[self.i, 2], self.home_enu_m[2] + RTL_ALT_M)
        fixed_wing = self.airframe.kind == "fixed_wing"

        def at_home() -> None:
            if fixed_wing:
                self.hold()
                if done is not None:
                    done()
            else:
                self.land(self.home_enu_m, done)

        self._wait(at_home)
        radius = self.airframe.loiter_radius_m if fixed_wing else self.airframe.accept_radius_m
        kin.command(self.i, Guidance.GOTO, target, Arrival.RADIUS_2D, max(radius, 1.0))

    # --- events from the fleet loop ----------------------------------------------------------
    def on_arrived(self) -> None:
        step, self._next_arrival = self._next_arrival, None
        self.world.kin.arrival[self.i] = Arrival.NONE
        if step is not None:
            step()

    def on_timer(self) -> None:
        step, self._next_timer = self._next_timer, None
        if step is not None:
            step()

    def _wait(self, on_arrival: Callable[[], None] | None) -> None:
        self._next_arrival = on_arrival
        self._next_timer = None
        self.world.timers[self.i] = np.inf
        self.world.kin.arrival[self.i] = Arrival.NONE

    def _after(self, delay_s: float, step: Callable[[], None]) -> None:
        self._next_timer = step
        self.world.timers[self.i] = self.world.sim_time_s + delay_s

    # --- mission items -----------------------------------------------------------------------
    def _execute(self) -> None:
        item = self.items[self.seq]
        seq = self.seq
        kin, i, af = self.world.kin, self.i, self.airframe
        target = self._target(seq)
        cmd = item.command
        if cmd == NAV_WAYPOINT:
            radius = item.param2 if item.param2 > 0 else af.accept_radius_m
            hold_s = max(item.param1, 0.0)
            passing = af.kind == "fixed_wing" or (hold_s == 0 and self._next_nav_is_waypoint(seq))
            arrival = Arrival.RADIUS_2D if af.kind == "fixed_wing" else Arrival.RADIUS_3D
            self._wait(lambda: self._reached_then(seq, hold_s))
            if i in kin.wpnav:
                self._track(seq, target, passing)
            else:
                corner = self._corner_speed(seq, target, radius) if passing else np.inf
                kin.command(i, Guidance.PASS if passing else Guidance.GOTO, target, arrival, radius, corner)
        elif cmd == NAV_DELAY:
            self.hold()
            self._after(max(item.param1, 0.0), lambda: self._item_done(seq))
        elif cmd == NAV_TAKEOFF:
            self.takeoff(item.z if item.frame not in AMSL_FRAMES else target[2] - self.home_enu_m[2],
                         done=lambda: self._reached_then(seq, 0.0))  # fmt: skip
        elif cmd in (NAV_LOITER_TIME, NAV_LOITER_UNLIM):
            # ArduPilot keeps only the direction of a LOITER_TIME radius (+-1): its WP_LOITER_RAD flies
            radius = abs(item.param3) if abs(item.param3) > 1.0 else af.loiter_radius_m
            kin.loiter_r[i] = max(radius, 1.0)
            hold_s = max(item.param1, 0.0) if cmd == NAV_LOITER_TIME else np.inf
            arrive_r = max(radius, af.accept_radius_m)
            arrival = Arrival.RADIUS_2D if af.kind == "fixed_wing" else Arrival.RADIUS_3D
            self._wait(lambda: self._reached_then(seq, hold_s))
            kin.command(i, Guidance.GOTO, target, arrival, arrive_r)
        elif cmd == NAV_LAND and self.flight.final_land_disarms and seq == self.last_seq:
            self.land(target, done=self._stop)  # the disarm at touchdown resets the mission
        elif cmd == NAV_LAND:
            self.land(target, done=lambda: self._item_done(seq))
        elif cmd == NAV_RETURN_TO_LAUNCH and self.flight.rtl_item_switches_mode:
            self._enter_mode("RTL")
        elif cmd == NAV_RETURN_TO_LAUNCH:
            self.rtl(done=lambda: self._item_done(seq))
        elif cmd == DO_CHANGE_SPEED:
            if round(item.param1) == 1 and self.flight.groundspeed_is_minimum:
                pass  # a minimum ground speed: the cruise speed stays
            elif round(item.param1) == 0 and not self._airspeed_allowed(item.param2):
                pass  # outside the plane's airspeed range: ignored (FlightRules.airspeed_range)
            elif item.param2 > 0:
                kin.set_speed(i, float(np.clip(item.param2, af.min_speed_mps, af.max_speed_mps)))
            self._item_done(seq)
        else:
            self._emit_text(f"Skipping unsupported mission command {cmd}")
            self._advance()

    def _stop(self) -> None:
        self.running = False

    def _reached_then(self, seq: int, hold_s: float) -> None:
        """Nav item reached: report it, hold/loiter for ``hold_s`` (inf = forever), then advance."""
        self._report(seq)
        if hold_s <= 0:
            self._advance()
            return
        kin = self.world.kin
        self._wait(None)
        kin.command(self.i, Guidance.HOLD, self._target(seq) if self.items[seq].command != NAV_TAKEOFF
                    else kin.pos[self.i].copy())  # fmt: skip
        if np.isfinite(hold_s):
            self._after(hold_s, self._advance)

    def _item_done(self, seq: int) -> None:
        self._report(seq)
        self._advance()

    def _report(self, seq: int) -> None:
        self.reached.append((seq, self.world.sim_time_s))
        self._emit_reached(seq)

    def _advance(self) -> None:
        if not self.running:
            return
        if self.seq >= self.last_seq:
            self.running = False
            self.state = MissionState.COMPLETE
            self._emit_text("Mission complete")
            if self.world.kin.airborne()[self.i]:
                self.hold()
            self._emit_progress()
            return
        self.seq += 1
        self._emit_progress()
        self._execute()

    def _track(self, seq: int, target: np.ndarray, passing: bool) -> None:
        """Fly to waypoint ``seq`` on the vehicle's S-curve navigation (ArduCopter ModeAuto::wp_start
        and set_next_wp): from rest where it is unless it has just reached the last destination,
        and with the next waypoint preloaded when it passes through this one."""
        kin, i = self.world.kin, self.i
        nav = kin.wpnav[i]
        if kin.mode[i] != Guidance.TRACK or not nav.reached_destination:
            nav.init(kin.pos[i], float(kin.speed_cmd[i]))
        nav.set_destination(target)
        if passing:
            nav.set_destination_next(self._target(self._next_nav(seq)))
        kin.command(i, Guidance.TRACK, target, Arrival.TRACKED)

    def _next_nav(self, seq: int) -> int | None:
        """The seq of the first nav item after ``seq`` in the run, None without one."""
        return next(
            (k for k in range(seq + 1, self.last_seq + 1) if self.items[k].command in NAV_COMMANDS), None
        )

    def _next_nav_is_waypoint(self, seq: int) -> bool:
        nxt = self._next_nav(seq)
        return nxt is not None and self.items[nxt].command == NAV_WAYPOINT

    def _corner_speed(self, seq: int, target: np.ndarray, radius_m: float) -> float:
        """Multirotor speed [m/s] at which the turn onto the next leg fits inside the acceptance radius."""
        nxt = self._next_nav(seq)
        if nxt is None or self.airframe.kind == "fixed_wing":
            return np.inf
        here = self.world.kin.pos[self.i, :2]
        a, b = target[:2] - here, self._target(nxt)[:2] - target[:2]
        na, nb = np.hypot(*a), np.hypot(*b)
        if nb < STOP_LEG_M:
            return 0.0  # the next leg has (almost) no length: stop here, as the next target is here
        if na < 1e-6:
            return np.inf
        theta = np.arccos(np.clip(np.dot(a, b) / (na * nb), -1.0, 1.0))  # turn angle [rad]
        if theta < 1e-3:
            return np.inf
        # The turn fits inside the acceptance radius (v^2 / a = r / tan(theta / 2)); where
        # waypoints sample an arc densely (legs shorter than ARC_LEG_FACTOR x r) the vehicle
        # follows the arc they trace instead, radius ~ leg / (2 tan(theta / 2)).
        turn_r = max(radius_m, 1.0) / np.tan(theta / 2)
        if min(na, nb) <= ARC_LEG_FACTOR * max(radius_m, 1.0):
            turn_r = max(turn_r, min(na, nb) / (2.0 * np.tan(theta / 2)))
        return float(np.sqrt(self.airframe.accel_mps2 * turn_r))

    def _target(self, seq: int) -> np.ndarray:
        """Item ``seq``'s target [m ENU]; lat/lon 0 means the vehicle's current position."""
        target = self._targets[seq].copy()
        item = self.items[seq]
        if item.x == 0 and item.y == 0:
            target[:2] = self.world.kin.pos[self.i, :2]
        return target

    def _item_targets(self, items: list[MissionItem]) -> np.ndarray:
        if not items:
            return np.zeros((0, 3))
        lat = np.array([it.x / 1e7 for it in items])
        lon = np.array([it.y / 1e7 for it in items])
        rel = np.array([it.frame not in AMSL_FRAMES for it in items])
        z = np.array([it.z for it in items], dtype=float)
        alt_amsl = np.where(rel, z + self.world.frame.alt_m + self.home_enu_m[2], z)
        e, n, u = to_enu(lat, lon, alt_amsl, self.world.frame)
        return np.column_stack([e, n, u])
