"""Interop with MAVProxy 1.8.75 (ArduPilot's command-line GCS) over real UDP on 127.0.0.1.

Both ways through a mock ArduPilot vehicle (sitl_mock), for missions, fences and rally points:

1. MAVProxy ``wp load`` / ``fence load`` / ``rally load`` FILE into the mock; the vehicle then holds
   what MAVProxy sent (MAVProxy's own loader and MISSION_ITEM_INT conversion applied to FILE); our
   ``gcs-planner download`` writes a file that holds, row for row, what the vehicle serves.
2. ``gcs-planner upload`` FILE to the mock; the vehicle then holds FILE as the autopilot stores it;
   MAVProxy ``wp save`` / ``fence save`` / ``rally save`` OUT writes what the vehicle serves.

Files: a handful of real ones from ../shared/corpus (ArduPilot autotest missions with DO_* rows,
a DO_JUMP, relative / absolute / terrain frames, comments and 8-decimal coordinates; pymavlink's
and ArduPilot's fence and rally files, including MAVProxy's legacy formats; MANIFEST.tsv there
names their sources), and files written by our own exporter (`gcs-planner export --format wpl`).

Every file is read with pymavlink's mavwp (MAVProxy's reader). Rows are compared as the autopilot
stores them: latitude / longitude as degE7 integers, params and altitude as float32, the home row
(seq 0) as the vehicle reports it (ArduPilot serves its own home there), ``current`` not at all
(it marks the vehicle's current item). Where MAVProxy itself loses information the expectation
says so explicitly (``mavproxy_sent``: degE7 truncated, not rounded; ``as_mavproxy_saves``:
``%f``, 6 decimals), and ``test_mavproxy_and_we_send_a_file_alike`` checks that against what
MAVProxy and we really send for the same file.

``test_a_command_mavproxys_dialect_lacks``: where MAVProxy and we read a file differently, off
the vehicle (the mock refuses the command). PX4 is not covered: MAVProxy is ArduPilot's GCS and
sends a WPL file's row 0 as an item, where PX4 takes no home item (see test_cli_mission).

MAVProxy is driven as a subprocess, one transfer per process: ``--cmd`` runs the command at start
(with --target-system/--target-component, so it needs no HEARTBEAT first), ``--non-interactive``
(stdin is not read), ``--no-state`` (no logs, no state files), only the wp/fence/rally modules,
HOME and cwd in tmp_path. Completion is read from its stdout (the MISSION_ACK it got; "Saved N
..."), and the process is always terminated. Several clients may talk to one mock vehicle (it
answers every peer it has heard); MAVProxy and gcs-planner take turns.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import signal
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, replace
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path
from types import SimpleNamespace

import pytest

os.environ.setdefault("MAVLINK20", "1")  # mavwp builds MAVLink 2 items (with mission_type) only then
_mip = pytest.importorskip(
    "MAVProxy.modules.lib.mission_item_protocol",
    reason="MAVProxy cannot be imported (pip install MAVProxy==1.8.75, the test extra)",
    exc_type=ImportError,
)
MissionItemProtocolModule = _mip.MissionItemProtocolModule
from pymavlink import mavwp  # noqa: E402

from gcs_planner.cli import main  # noqa: E402
from gcs_planner.core.geo import Origin  # noqa: E402
from gcs_planner.wire.types import MissionItem  # noqa: E402

CORPUS = Path(os.environ.get("GCS_PLANNER_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))
AUTOTEST = "ardupilot/Tools/autotest"
HOME = Origin(-35.363262, 149.165237, 584.0)  # the mock vehicle's home (ArduPilot SITL's CMAC)
TRANSFER_TIMEOUT_S = 30.0

MISSION, FENCE, RALLY = 0, 1, 2
KINDS = {MISSION: "wp", FENCE: "fence", RALLY: "rally"}
LOADERS = {
    MISSION: mavwp.MAVWPLoader,
    FENCE: mavwp.MissionItemProtocol_Fence,
    RALLY: mavwp.MissionItemProtocol_Rally,
}
SAVED = {MISSION: "waypoints", FENCE: "fence items", RALLY: "rally items"}  # MAVProxy's itemstype()


# ------------------------------------------------------------------------------------ the files


@dataclass(frozen=True)
class Case:
    name: str
    path: str  # under CORPUS; "export:<plan>": written by our exporter; "text:<name>": TEXTS[name]
    mission_type: int = MISSION
    vehicle_type: str = "multirotor"
    wpl: bool = True  # QGC WPL 110 (else one of MAVProxy's legacy fence / rally formats)

    @property
    def legacy_rally(self) -> bool:
        return self.mission_type == RALLY and not self.wpl


MISSIONS = [
    # DO_JUMP, CONDITION_YAW, LOITER_TIME without a position, a positionless WAYPOINT, RTL
    Case("jump", f"{AUTOTEST}/ArduCopter_Tests/CANGPSCopterMission/copter_mission.txt"),
    # take-off without a position, DO_DIGICAM_CONTROL, LAND; frame 3 (relative altitude)
    Case("digicam", f"{AUTOTEST}/AVC2013.txt"),
    # frame 10 (terrain) next to frames 0 and 3
    Case("terrain", f"{AUTOTEST}/ArduCopter_Tests/copter_terrain_mission.txt"),
    # frame 0 (absolute altitude) throughout, 8-decimal coordinates, DO_CHANGE_SPEED, LOITER_TO_ALT
    Case("absolute", f"{AUTOTEST}/ArduPlane_Tests/KalaupapaCanyonRun/mission.txt", vehicle_type="fixed_wing"),
    # comment lines, every kind of plane item, 8-decimal coordinates
    Case("plane-items", f"{AUTOTEST}/ArduPlane_Tests/MissionItemTypes/items.txt", vehicle_type="fixed_wing"),
    # DO_LAND_START, an absolute-altitude LAND
    Case(
        "deepstall",
        f"{AUTOTEST}/ArduPlane_Tests/DeepStall/plane-deepstall-mission.txt",
        vehicle_type="fixed_wing",
    ),
    # our own exporter: 7-decimal coordinates, NAV_DELAY / DO_CHANGE_SPEED rows, RTL
    Case("export-copter", "export:copter"),
    Case("export-plane", "export:plane", vehicle_type="fixed_wing"),
]
FENCES = [
    Case("fence-110", "pymavlink/tests/fence-110.txt", FENCE),
    # inclusion and exclusion polygons and circles
    Case(
        "fence-polys-circles",
        f"{AUTOTEST}/ArduRover_Tests/PolyFenceObjectAvoidance/rover-path-planning-fence-inclusion.txt",
        FENCE,
    ),
    # MAVProxy's legacy "lat lon" list: return point + one inclusion polygon
    Case(
        "fence-legacy", f"{AUTOTEST}/ArduPlane_Tests/ThrottleFailsafeFence/CMAC-fence.txt", FENCE, wpl=False
    ),
]
# RTL (no position) with a latitude / longitude in x / y: both send the plain number, truncated or rounded
RTL_AT = Case("rtl-at", f"{AUTOTEST}/ap1.txt")
RALLIES = [
    Case("rally-110", "pymavlink/tests/rally-110.txt", RALLY),
    # MAVProxy's legacy "RALLY lat lon alt break_alt land_dir flags" lines
    Case("rally-legacy", f"{AUTOTEST}/ArduRover_Tests/Rally/rover-test-rally.txt", RALLY, wpl=False),
    # the same format with altitudes other than 0 (mavwp's loader multiplies them by 1000)
    Case("rally-legacy-alt", "text:rally-legacy-alt", RALLY, wpl=False),
]
TEXTS = {  # as MAVRallyLoader.save writes them ("RALLY %f\t%f\t%f\t%f\t%f\t%d")
    "rally-legacy-alt": "RALLY -35.362100\t149.164500\t40.000000\t80.000000\t0.000000\t0\n"
    "RALLY -35.364450\t149.166250\t55.500000\t70.000000\t90.000000\t0\n",
}


def case_file(case: Case, tmp_path: Path) -> Path:
    """The case's file: from the corpus (skip if it is not there), or written by `gcs-planner export`."""
    if case.path.startswith("export:"):
        return exported_wpl(case.path.split(":", 1)[1], tmp_path)
    if case.path.startswith("text:"):
        path = tmp_path / f"{case.name}.txt"
        path.write_text(TEXTS[case.path.split(":", 1)[1]])
        return path
    path = CORPUS / case.path
    if not path.is_file():
        pytest.skip(f"corpus file {path} is not there (../shared/corpus)")
    return path


def exported_wpl(kind: str, tmp_path: Path) -> Path:
    import numpy as np

    from gcs_planner.model.plan import Plan, VehiclePlan

    n = 7
    wps = np.c_[
        np.linspace(0, 90 * (n - 1), n),
        np.linspace(0, -35 * (n - 1), n),
        np.r_[0.0, np.linspace(25.0, 40.0, n - 1)],
    ]
    speeds = np.r_[0.0, np.where(np.arange(1, n) % 2, 8.0, 12.5)]
    times = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(wps, axis=0), axis=1) / speeds[1:])]
    extra = {"vehicle_type": "fixed_wing", "turn_radius_m": 60.0} if kind == "plane" else {}
    vp = VehiclePlan(
        kind,
        1,
        wps,
        times,
        speeds,
        wps,
        times,
        takeoff_delay_s=3.0,
        final_action="rtl",
        acceptance_radius_m=3.0,
        **extra,
    )
    plan = tmp_path / f"{kind}.json"
    Plan(Origin(HOME.lat_deg + 0.00123, HOME.lon_deg - 0.00456, HOME.alt_m), "mavproxy", [vp]).save(plan)
    out = tmp_path / "export"
    assert main(["export", str(plan), "--format", "wpl", "--autopilot", "ardupilot", "-o", str(out)]) == 0
    (path,) = out.glob(f"{kind}.*")
    return path


# ------------------------------------------------------------------------ rows, as stored


def f32(v: float) -> float:
    return struct.unpack("<f", struct.pack("<f", v))[0]


def has_location(command: int) -> bool:
    """MAVProxy's rule (MAVLink hasLocation): x/y are degrees x 1e7 on the wire, else plain numbers."""
    return MissionItemProtocolModule.has_location(None, command)


_MAVPROXY = SimpleNamespace(has_location=has_location)


def read_mavwp(path: Path, mission_type: int) -> list:
    """FILE as MAVProxy reads it: MISSION_ITEM messages (x/y in degrees, floats)."""
    loader = LOADERS[mission_type](1, 1)
    loader.load(str(path))
    return [loader.item(i) for i in range(loader.count())]


def mavproxy_sent(path: Path, mission_type: int) -> list[MissionItem]:
    """What MAVProxy's ``load`` sends for FILE: its loader, then its MISSION_ITEM_INT conversion
    (``int(x * 1e7)``: truncated toward zero), then float32 on the wire."""
    convert = MissionItemProtocolModule.wp_to_mission_item_int
    return [
        wire(MissionItem.from_message(convert(_MAVPROXY, w), mission_type))
        for w in read_mavwp(path, mission_type)
    ]


def e7(text: str, command: int) -> int:
    """A file's x/y as the wire carries it: the decimal text x 1e7 rounded to nearest, ties away
    from zero (a plain number for a command without a position). From the text, not mavwp's float:
    an 8-decimal coordinate can sit exactly on a tie, which a float cannot tell."""
    scale = 10**7 if has_location(command) else 1
    return int((Decimal(text) * scale).to_integral_value(ROUND_HALF_UP))


def numbers(path: Path) -> list[tuple[str, str, str | None]]:
    """(x, y, altitude) as written, for every item mavwp makes of the file (lines skipped as it
    does). The altitude only where the file's own value is wanted: a legacy rally line's (mavwp
    multiplies it by 1000); None elsewhere (mavwp's float is what the file says)."""
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    if lines and lines[0].strip().startswith("QGC WPL"):
        return [(*ln.split()[8:10], None) for ln in lines[1:]]
    if lines and lines[0].split()[0].upper() == "RALLY":
        return [tuple(ln.split()[1:4]) for ln in lines if ln.split()[0].upper() == "RALLY"]
    return [(*ln.split()[:2], None) for ln in lines[:-1]]  # legacy fence: the closing point is dropped


def file_items(path: Path, mission_type: int) -> list[MissionItem]:
    """FILE as it says, item for item: mavwp's reading, x/y as degE7 from the text (``e7``); a
    legacy file's items as mavwp builds them (frames, commands, vertex counts, autocontinue 0)."""
    items, texts = read_mavwp(path, mission_type), numbers(path)
    assert len(items) == len(texts), f"{path}: mavwp reads {len(items)} items, the text has {len(texts)}"
    out = []
    for i, (w, (xt, yt, zt)) in enumerate(zip(items, texts)):
        it = MissionItem(
            i, w.frame, w.command, w.current, w.autocontinue, w.param1, w.param2, w.param3, w.param4
        )
        x, y, z = e7(xt, w.command), e7(yt, w.command), w.z if zt is None else float(zt)
        out.append(wire(replace(it, x=x, y=y, z=z, mission_type=mission_type)))
    return out


def wire(it: MissionItem) -> MissionItem:
    """Params and z as float32, as MISSION_ITEM_INT carries them."""
    p1, p2, p3, p4, z = (f32(v) for v in (it.param1, it.param2, it.param3, it.param4, it.z))
    return replace(it, param1=p1, param2=p2, param3=p3, param4=p4, z=z)


def as_mavproxy_saves(it: MissionItem) -> MissionItem:
    """What ``wp save`` keeps of an item it downloaded: x/y of a positional command times 1e-7
    (``wp_from_mission_item_int``), every number written with ``%f`` (6 decimals: 1e-6 deg is
    10 degE7; mavwp's ``save``), then read back as a file says (``e7``)."""

    def q(v: float) -> str:
        return f"{v:f}"  # mavwp's save: "%f"

    scale = 1.0e-7 if has_location(it.command) else 1.0
    x, y = (e7(q(v * scale), it.command) for v in (it.x, it.y))
    p1, p2, p3, p4, z = (float(q(v)) for v in (it.param1, it.param2, it.param3, it.param4, it.z))
    return wire(replace(it, param1=p1, param2=p2, param3=p3, param4=p4, x=x, y=y, z=z))


def rows(items: list[MissionItem]) -> list[tuple]:
    """The compared fields of each row (no seq: the position in the list; no current)."""
    return [
        (it.frame, it.command, it.autocontinue, it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z)
        for it in items
    ]


def first_difference(got: list[MissionItem], want: list[MissionItem]) -> str | None:
    """The first differing row and field, in words (None when equal)."""
    names = ("frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z")
    if len(got) != len(want):
        return f"{len(got)} rows, expected {len(want)}"
    for i, (a, b) in enumerate(zip(rows(got), rows(want))):
        for name, va, vb in zip(names, a, b):
            if va != vb and not (isinstance(va, float) and math.isnan(va) and math.isnan(vb)):
                return f"row {i}: {name} is {va!r}, expected {vb!r}"
    return None


# ------------------------------------------------------------------------- driving MAVProxy


class Mavproxy:
    """One MAVProxy process running ``command`` at start against the vehicle at 127.0.0.1:``port``."""

    def __init__(self, port: int, command: str, workdir: Path) -> None:
        workdir.mkdir(parents=True, exist_ok=True)
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        env.update(HOME=str(workdir), CI="true", PYTHONUNBUFFERED="1", MAVLINK20="1")
        argv = [
            sys.executable,
            "-m",
            "MAVProxy.mavproxy",
            f"--master=udpout:127.0.0.1:{port}",
            "--non-interactive",
            "--no-state",
            "--default-modules=wp,fence,rally",
            "--target-system=1",
            "--target-component=1",
            "--source-system=255",
            f"--cmd={command}",
        ]
        self.command = command
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self.proc = subprocess.Popen(
            argv,
            cwd=workdir,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        self._reader = threading.Thread(target=self._read, name="mavproxy-stdout", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    def wait_for(self, pattern: str, timeout_s: float = TRANSFER_TIMEOUT_S, skip=lambda m: False) -> re.Match:
        """The first stdout line matching ``pattern`` (and not ``skip``); fails the test on timeout
        or exit, with MAVProxy's output."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout_s
        with self._changed:
            seen = 0
            while True:
                for line in self.lines[seen:]:
                    if (m := regex.search(line)) and not skip(m):
                        return m
                seen = len(self.lines)
                left = deadline - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    break
                self._changed.wait(min(left, 0.5))
        state = "timed out" if self.proc.poll() is None else f"exited {self.proc.returncode}"
        pytest.fail(
            f"MAVProxy {self.command!r} {state} before printing /{pattern}/; its output:\n"
            + "\n".join(self.lines)
        )

    def close(self) -> None:
        """SIGTERM (MAVProxy shuts down cleanly), SIGKILL if that takes over 5 s; to its own
        session only (start_new_session), so just MAVProxy and what it started."""
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if self.proc.poll() is not None:
                break
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, sig)
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=5.0)
        self._reader.join(timeout=5.0)
        self.proc.stdout.close()

    def __enter__(self) -> Mavproxy:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def mavproxy_load(port: int, path: Path, mission_type: int, workdir: Path) -> None:
    """MAVProxy uploads FILE; returns once the vehicle's final MISSION_ACK came, which must be
    ACCEPTED. An INVALID_SEQUENCE ack on the way is no verdict: ArduPilot sends one for an item
    that arrives twice (its re-request crossed MAVProxy's answer) and the upload goes on."""
    kind = KINDS[mission_type]
    with Mavproxy(port, f"{kind} load {path}", workdir) as mp:
        ack = mp.wait_for(
            r"Got MISSION_ACK: TYPE_(MISSION|FENCE|RALLY): (\w+)|Unable to load",
            skip=lambda m: m.group(2) == "INVALID_SEQUENCE",
        )
        assert ack.groups() == (["MISSION", "FENCE", "RALLY"][mission_type], "ACCEPTED"), "\n".join(mp.lines)


def mavproxy_save(port: int, out: Path, mission_type: int, workdir: Path) -> int:
    """MAVProxy downloads into OUT; the number of items it saved."""
    with Mavproxy(port, f"{KINDS[mission_type]} save {out}", workdir) as mp:
        saved = mp.wait_for(rf"Saved (\d+) {SAVED[mission_type]} to|Failed to save")
        assert saved.group(1) is not None, "\n".join(mp.lines)
        return int(saved.group(1))


# ------------------------------------------------------------------------------ the vehicle


@pytest.fixture
def vehicle(request):
    """A fresh mock ArduPilot vehicle (sysid 1) of the case's vehicle type; its UDP port."""
    sitl_mock = pytest.importorskip("sitl_mock")
    case: Case = request.param
    with sitl_mock.MockFleet(
        vehicles=[{"profile": "ardupilot", "vehicle_type": case.vehicle_type}], home=HOME
    ) as fleet:
        yield SimpleNamespace(fleet=fleet, port=fleet.vehicle(1).address[1], case=case)


def stored(fleet, mission_type: int) -> list[MissionItem]:
    return fleet.call(lambda: list(fleet.vehicle(1).mission_server.items(mission_type)))


def storage(fleet):
    """The vehicle's model of what the autopilot keeps of an item (readback.py via the profile)."""
    return fleet.vehicle(1).mission_server.storage


def served(fleet, mission_type: int) -> list[MissionItem]:
    """What a download gets: the stored list, with ArduPilot's own home at seq 0 of a mission."""
    items = stored(fleet, mission_type)
    home = fleet.call(lambda: fleet.vehicle(1).mission_server.home)
    if mission_type == MISSION and items and home is not None:
        items[0] = home
    return items


def url(v) -> list[str]:
    return ["--connect", f"udpout:127.0.0.1:{v.port}", "--sysid", "1"]


def download_args(mission_type: int) -> list[str]:
    return ["--type", ["mission", "fence", "rally"][mission_type]]


def ids(case: Case) -> str:
    return case.name


# ------------------------------------------------------------------------------------ tests


@pytest.mark.parametrize("vehicle", MISSIONS + FENCES + RALLIES, ids=ids, indirect=True)
def test_mavproxy_load_then_our_download(vehicle, tmp_path):
    """MAVProxy uploads FILE; the vehicle holds what MAVProxy sent; our download of it holds, row
    for row, what the vehicle serves (and so what MAVProxy sent), and MAVProxy can read it."""
    case, fleet = vehicle.case, vehicle.fleet
    path = case_file(case, tmp_path)
    sent = mavproxy_sent(path, case.mission_type)
    assert sent, f"MAVProxy reads no items from {path}"
    mavproxy_load(vehicle.port, path, case.mission_type, tmp_path / "mavproxy")
    keep = storage(fleet)
    assert first_difference(stored(fleet, case.mission_type), [keep(it) for it in sent]) is None

    out = tmp_path / "download.txt"
    assert main(["download", *url(vehicle), *download_args(case.mission_type), str(out)]) == 0
    got = file_items(out, case.mission_type)
    want = served(fleet, case.mission_type)
    assert first_difference(got, want) is None, out.read_text()


@pytest.mark.parametrize("vehicle", MISSIONS + FENCES + RALLIES, ids=ids, indirect=True)
def test_our_upload_then_mavproxy_save(vehicle, tmp_path):
    """We upload FILE; the vehicle holds FILE as the autopilot stores it; MAVProxy's save of it is
    FILE (to MAVProxy's 6 decimals), with the vehicle's own home at row 0 of a mission."""
    case, fleet = vehicle.case, vehicle.fleet
    path = case_file(case, tmp_path)
    if case.mission_type != MISSION:  # MAVProxy's fence / rally load leaves the mission alone
        assert main(["upload", *url(vehicle), str(exported_wpl("copter", tmp_path))]) == 0
    mission = stored(fleet, MISSION)
    assert main(["upload", *url(vehicle), str(path)]) == 0
    if case.mission_type != MISSION:
        assert stored(fleet, MISSION) == mission, "a fence / rally upload changed the mission"
    keep = storage(fleet)
    want = [keep(it) for it in file_items(path, case.mission_type)]
    assert first_difference(stored(fleet, case.mission_type), want) is None

    out = tmp_path / "saved.txt"
    count = mavproxy_save(vehicle.port, out, case.mission_type, tmp_path / "mavproxy")
    assert count == len(want)
    got = file_items(out, case.mission_type)
    if case.mission_type == MISSION:
        want[0] = served(fleet, MISSION)[0]
    assert first_difference(got, [as_mavproxy_saves(it) for it in want]) is None, out.read_text()


def record_the_wire(fleet) -> None:
    """Make the vehicle store items exactly as they arrive (no autopilot rounding or dropping)."""
    server = fleet.vehicle(1).mission_server
    fleet.call(lambda: setattr(server, "storage", lambda item: item))


@pytest.mark.parametrize("vehicle", [*MISSIONS, *FENCES, *RALLIES, RTL_AT], ids=ids, indirect=True)
def test_mavproxy_and_we_send_a_file_alike(vehicle, tmp_path):
    """The same FILE uploaded by MAVProxy and by us, as it arrives on the wire (a vehicle storing
    every field as received): the same rows, frames, commands, params, altitudes and autocontinue
    (``current`` aside: the flag of the row to start at, which we set on row 0 only).

    Ours: x/y as the file says (the decimal value x 1e7, rounded). MAVProxy's: ``int(deg * 1e7)``,
    so a coordinate whose float product falls just below an integer (or on an 8-decimal tie) goes
    out 1 degE7 (about 1 cm) short, toward zero. A legacy rally file's altitudes go out x 1000
    from MAVProxy (mavwp's MissionItemProtocol_Rally.load), as written from us. That is all that
    differs; it also confirms ``mavproxy_sent``, the reference of the download test, against
    what MAVProxy really sends."""
    case, fleet = vehicle.case, vehicle.fleet
    path = case_file(case, tmp_path)
    record_the_wire(fleet)
    mavproxy_load(vehicle.port, path, case.mission_type, tmp_path / "mavproxy")
    theirs = stored(fleet, case.mission_type)
    assert first_difference(theirs, mavproxy_sent(path, case.mission_type)) is None
    assert main(["upload", *url(vehicle), str(path)]) == 0
    ours = stored(fleet, case.mission_type)
    assert first_difference(ours, file_items(path, case.mission_type)) is None

    assert len(theirs) == len(ours)
    for a, b, (xt, yt, zt) in zip(theirs, ours, numbers(path)):
        assert rows([a])[0][:7] == rows([b])[0][:7], f"row {a.seq}"
        # mavwp's legacy rally loader sends z = alt * 1e3 (as if MISSION_ITEM_INT z were mm); ours: alt
        assert a.z == (f32(float(zt) * 1e3) if case.legacy_rally else b.z), f"row {a.seq}"
        scale = 1e7 if has_location(a.command) else 1.0
        for text, mavproxy, we in ((xt, a.x, b.x), (yt, a.y, b.y)):
            assert mavproxy == math.trunc(float(text) * scale), f"row {a.seq}: {text}"
            assert mavproxy == we or (abs(mavproxy - we) == 1 and abs(mavproxy) < abs(we)), f"row {a.seq}"


def test_a_command_mavproxys_dialect_lacks(tmp_path):
    """ArduPilot's ConditionLocation autotest mission has command 116 with a latitude / longitude in
    x / y. pymavlink 2.4.50 has no command 116, so MAVProxy takes x / y for plain numbers and
    sends int(-35.362364) = -35, int(149.165237) = 149 (read as degE7: a point 2 m from 0 N 0 E);
    we send the file's latitude / longitude as degE7 (a command our dialect lacks keeps
    MISSION_ITEM_INT's default meaning of x / y). Not against the mock: it refuses command ids its
    dialect lacks (MAV_MISSION_UNSUPPORTED)."""
    from gcs_planner.missions.files import load_mission_file

    path = case_file(
        Case(
            "condition-location",
            f"{AUTOTEST}/ArduCopter_Tests/ConditionLocation/copter_condition_location.txt",
        ),
        tmp_path,
    )
    sent = {it.seq: it for it in mavproxy_sent(path, MISSION)}
    ours = {it.seq: it for it in load_mission_file(path).items("ardupilot")}
    assert (sent[3].command, sent[3].x, sent[3].y) == (116, -35, 149)
    assert (ours[3].command, ours[3].x, ours[3].y) == (116, -353623640, 1491652370)
    assert rows([ours[i] for i in sorted(ours) if i != 3]) == rows(
        [file_items(path, MISSION)[i] for i in sorted(sent) if i != 3]
    )
