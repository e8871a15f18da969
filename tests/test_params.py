"""`gcs-planner params get / set / diff` end to end against mock ArduPilot and PX4 vehicles over UDP
on 127.0.0.1, the parameter client against a scripted vehicle, the file formats, and interop with
MAVProxy's parameter files (pymavlink's mavparm.MAVParmDict: what `param save` writes and `param
load` reads)."""

from __future__ import annotations

import asyncio
import random
import socket
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from ports import frames_from_a_gcs
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from pymavlink.mavparm import MAVParmDict

from gcs_planner.cli import main
from gcs_planner.core.errors import UserError
from gcs_planner.core.lockstep import run
from gcs_planner.mavlink import params as client
from gcs_planner.mavlink.params import REAL32, Param, download_params, float32
from gcs_planner.missions.param_files import ParamEntry, format_value, parse_params, read_param_file

sitl_mock = pytest.importorskip("sitl_mock")
from sitl_mock.faults import LinkFaults  # noqa: E402


@pytest.fixture(scope="module")
def fleet():
    vehicles = [
        {"profile": "ardupilot"},
        {"profile": "px4"},
        {"profile": "ardupilot", "vehicle_type": "fixed_wing"},
    ]
    with sitl_mock.MockFleet(vehicles=vehicles, speedup=20.0) as f:
        yield f


def connect(fleet, sysid: int) -> list[str]:
    host, port = fleet.vehicle(sysid).address
    return ["--connect", f"udpout:{host}:{port}", "--sysid", str(sysid)]


def held(fleet, sysid: int) -> tuple[dict[str, float], dict[str, int]]:
    """The mock's parameter values and MAV_PARAM_TYPEs (REAL32 where it keeps none)."""

    def read():
        v = fleet.vehicle(sysid)
        return dict(v.params), {n: v.param_types.get(n, REAL32) for n in v.params}

    return fleet.call(read)


def sets(fleet, sysid: int) -> list[str]:
    """The names of every PARAM_SET the mock received."""
    return fleet.call(lambda: list(fleet.vehicle(sysid).param_server.sets))


def as_held(value: float, param_type: int) -> int | float:
    """A mock value (or a file's) as the vehicle holds it: an int for integer types, else the float32."""
    return int(value) if param_type != REAL32 else float32(value)


def edit(path: Path, edits: dict[str, str]) -> None:
    """Give the parameters named in ``edits`` new value texts in a .param or .params file."""
    lines = []
    for line in path.read_text().splitlines():
        sep = "\t" if line.count("\t") == 4 else ","
        fields = line.split(sep)
        at = 2 if sep == "\t" else 0
        if not line.startswith("#") and fields[at] in edits:
            fields[at + 1] = edits[fields[at]]
        lines.append(sep.join(fields))
    path.write_text("\n".join(lines) + "\n")


# ----------------------------------------------------------------- get / set / diff against the mock


@pytest.mark.parametrize("sysid", [1, 2, 3], ids=["arducopter", "px4", "arduplane"])
def test_get_writes_both_formats_with_the_vehicles_values(fleet, tmp_path, capsys, sysid):
    values, types = held(fleet, sysid)
    assert len(values) >= 15  # the flight rules' parameters and a handful of stock ones
    for name in ("mp.param", "qgc.params"):
        assert main(["params", "get", *connect(fleet, sysid), "-o", str(tmp_path / name)]) == 0
        assert f"{len(values)} parameters written" in capsys.readouterr().out
        entries = read_param_file(tmp_path / name)
        read = {e.name: as_held(e.value, types[e.name]) for e in entries}
        assert read == {n: as_held(v, types[n]) for n, v in values.items()}
        ints = [e for e in entries if types[e.name] != REAL32]
        assert ints and all(isinstance(e.value, int) for e in ints)  # integers written as integers
    qgc = read_param_file(tmp_path / "qgc.params")
    assert {e.name: e.param_type for e in qgc} == types  # the MAV_PARAM_TYPE of each PARAM_VALUE
    assert {e.compid for e in qgc} == {1}
    text = (tmp_path / "qgc.params").read_text()
    assert text.startswith(f"# Onboard parameters for Vehicle {sysid}\n")
    assert f"\n{sysid}\t1\t" in text and "# Vehicle-Id Component-Id Name Value Type" in text


@pytest.mark.parametrize(
    ("sysid", "edits"),
    [
        (1, {"FENCE_ENABLE": "1", "WP_SPD": "12.5"}),  # ArduPilot: INT8 cast to float, a REAL32
        (2, {"NAV_RCL_ACT": "3", "MPC_XY_CRUISE": "7.3"}),  # PX4: INT32 bytewise (type-checked), a REAL32
    ],
    ids=["ardupilot", "px4"],
)
def test_edit_set_diff_round_trip(fleet, tmp_path, capsys, sysid, edits):
    path = tmp_path / ("p.params" if sysid == 2 else "p.param")
    argv = connect(fleet, sysid)
    assert main(["params", "get", *argv, "-o", str(path)]) == 0
    assert main(["params", "diff", str(path), *argv]) == 0  # what was just read is what the vehicle holds
    assert "0 of" in capsys.readouterr().out
    edit(path, edits)

    assert main(["params", "diff", str(path), *argv]) == 1
    out = capsys.readouterr().out.splitlines()
    assert sorted(line.split()[0] for line in out[:-1]) == sorted(edits)
    assert all(line.split()[1] == edits[line.split()[0]] for line in out[:-1])
    assert out[-1].startswith(f"{len(edits)} of ")

    before = sets(fleet, sysid)
    assert main(["params", "set", str(path), *argv]) == 0
    out = capsys.readouterr().out
    values, types = held(fleet, sysid)
    assert f"{len(edits)} set, {len(values) - len(edits)} unchanged" in out
    assert sorted(sets(fleet, sysid)[len(before) :]) == sorted(edits)  # only the edited ones were sent
    for name, value in edits.items():
        assert as_held(values[name], types[name]) == as_held(float(value), types[name])
    assert main(["params", "diff", str(path), *argv]) == 0
    assert main(["params", "set", str(path), *argv]) == 0  # nothing differs: nothing is sent
    assert f"0 set, {len(values)} unchanged" in capsys.readouterr().out
    assert len(sets(fleet, sysid)) == len(before) + len(edits)


def test_a_bytewise_int32_keeps_all_its_bits(fleet, tmp_path, capsys):
    """-5000000's bytes are a signalling NaN as a float32: PX4 gets and gives back exactly that int."""
    path = tmp_path / "one.param"
    path.write_text("NAV_DLL_ACT,-5000000\n")
    argv = connect(fleet, 2)
    try:
        assert main(["params", "set", str(path), *argv]) == 0
        assert held(fleet, 2)[0]["NAV_DLL_ACT"] == -5000000.0
        assert main(["params", "get", *argv, "-o", str(tmp_path / "back.param")]) == 0
        assert {e.name: e.value for e in read_param_file(tmp_path / "back.param")}["NAV_DLL_ACT"] == -5000000
    finally:
        path.write_text("NAV_DLL_ACT,0\n")
        assert main(["params", "set", str(path), *argv]) == 0
    capsys.readouterr()


def test_an_unknown_name_refuses_the_whole_file_before_any_param_set(fleet, tmp_path, capsys):
    path = tmp_path / "p.param"
    path.write_text("FENCE_ENABLE,1\nRTL_ALT,3000\nNO_SUCH_PARAM,1\nALSO_MISSING,2\n")
    before, values = sets(fleet, 1), held(fleet, 1)[0]
    assert main(["params", "set", str(path), *connect(fleet, 1)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "line 3" in err and "NO_SUCH_PARAM" in err and "2 of 4" in err and "nothing was set" in err
    assert sets(fleet, 1) == before and held(fleet, 1)[0] == values


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("FENCE_TYPE,300\n", "INT8 (-128..127), got 300"),
        ("FENCE_TYPE,3.5\n", "INT8 (-128..127), got 3.5"),
        ("FENCE_ENABLE,1\nFENCE_TYPE,-129\n", "line 2: parameter FENCE_TYPE is INT8"),
    ],
)
def test_a_value_its_type_cannot_hold_is_refused_before_any_param_set(fleet, tmp_path, capsys, text, message):
    path = tmp_path / "p.param"
    path.write_text(text)
    before = sets(fleet, 1)
    assert main(["params", "set", str(path), *connect(fleet, 1)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "nothing was set" in err
    assert sets(fleet, 1) == before


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("RTL_ALT,1500\nWP_SPD,fast\n", "line 2: value 'fast' is not a number: 'WP_SPD,fast'"),
        ("RTL_ALT 1500 2\n", "line 1: expected NAME,VALUE or NAME VALUE"),
        ("# header\n\nBAD-NAME,1\n", "line 3: parameter name 'BAD-NAME' is not 1-16 letters"),
        ("WP_SPD,nan\n", "line 1: value 'nan' is not a finite float32"),
        ("WP_SPD,1e39\n", "value '1e39' is not a finite float32"),
        ("RTL_ALT,1500\nRTL_ALT,1600\n", "line 2: RTL_ALT is also on line 1"),
        ("1\t1\tRTL_ALT\t1500\t6\n1\t1\tWP_SPD\t10.0\n", "line 2: expected QGC's five fields"),
        ("1\t1\tRTL_ALT\t1500\t99\n", "type '99' is not a MAV_PARAM_TYPE"),
        ("# only comments\n", "no parameter lines"),
        ("A_VERY_LONG_PARAMETER_NAME,1\n", "is not 1-16 letters"),
    ],
)
def test_a_malformed_file_is_one_line_and_sends_nothing(tmp_path, capsys, text, message):
    """Exit 2 naming the file, the line and its text, and not one datagram reaches the vehicle."""
    path = tmp_path / "bad.param"
    path.write_text(text)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
        vehicle.bind(("127.0.0.1", 0))
        argv = ["--connect", f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", "--sysid", "1"]
        for action in ("set", "diff"):
            assert main(["params", action, str(path), *argv]) == 2
            err = capsys.readouterr().err
            assert message in err and str(path) in err and err.count("\n") == 1 and "Traceback" not in err
        assert frames_from_a_gcs(vehicle) == []


def test_get_refuses_a_folder_or_a_missing_folder_before_asking(tmp_path, capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
        vehicle.bind(("127.0.0.1", 0))
        argv = ["--connect", f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", "--sysid", "1"]
        for output, message in ((tmp_path, "is a folder"), (tmp_path / "no" / "p.param", "does not exist")):
            assert main(["params", "get", *argv, "-o", str(output)]) == 2
            err = capsys.readouterr().err
            assert message in err and err.count("\n") == 1
        assert frames_from_a_gcs(vehicle) == []


def test_diff_names_what_the_vehicle_lacks_and_skips_other_components(fleet, tmp_path, capsys):
    """A name the vehicle does not have is a difference ("-"); QGC rows of component 100 get a note."""
    path = tmp_path / "p.params"
    path.write_text("# QGC\n1\t1\tRTL_ALT\t1500\t6\n1\t1\tNO_SUCH_PARAM\t2.5\t9\n1\t100\tCAM_MODE\t1\t6\n")
    assert main(["params", "diff", str(path), *connect(fleet, 1)]) == 1
    out = capsys.readouterr().out
    assert "note: 1 rows" in out and "line 4, component 100" in out
    rows = [line.split() for line in out.splitlines() if not line.startswith("note:")][:-1]
    assert rows == [["NO_SUCH_PARAM", "2.5", "-"]]
    assert out.splitlines()[-1] == f"1 of 2 parameters in {path} differ from vehicle 1"


def test_download_over_a_lossy_link_re_requests_the_missing_ones(fleet, tmp_path, capsys):
    """30 % of the datagrams lost each way: the list still arrives whole, by PARAM_REQUEST_READ."""
    values, types = held(fleet, 3)
    fleet.set_faults(3, LinkFaults(loss=0.3, seed=7))
    try:
        argv = [*connect(fleet, 3), "--heartbeat-timeout", "10", "-o", str(tmp_path / "p.param")]
        assert main(["params", "get", *argv]) == 0
    finally:
        fleet.set_faults(3, LinkFaults())
    entries = read_param_file(tmp_path / "p.param")
    read = {e.name: as_held(e.value, types[e.name]) for e in entries}
    assert read == {n: as_held(v, types[n]) for n, v in values.items()}
    capsys.readouterr()


# ----------------------------------------------------------------- the client against a scripted vehicle


class ScriptedVehicle:
    """A stand-in link: answers PARAM_REQUEST_LIST with the parameters whose index ``answers_list``
    accepts and PARAM_REQUEST_READ by index when ``answers_read``; records what was asked."""

    def __init__(self, count: int, answers_list, answers_read: bool = True) -> None:
        self.params = [Param(f"P{i:02d}", float(i) / 4, REAL32, i) for i in range(count)]
        self.answers_list, self.answers_read = answers_list, answers_read
        self.reads: list[tuple[float, int]] = []  # (loop time, param_index) of each PARAM_REQUEST_READ
        self._callbacks: list = []

    def check_target(self, sysid: int) -> None:
        pass

    def subscribe(self, callback, sysid=None):
        self._callbacks.append(callback)
        return lambda: self._callbacks.remove(callback)

    def send(self, msg) -> None:
        loop = asyncio.get_running_loop()
        if msg.get_type() == "PARAM_REQUEST_LIST":
            loop.call_later(0.01, self._deliver, "_HASH_CHECK", 7.0, 65535)  # PX4's, first: not an entry
            for p in self.params:
                if self.answers_list(p.index):
                    loop.call_later(0.01, self._deliver, p.name, p.value, p.index)
        elif msg.get_type() == "PARAM_REQUEST_READ":
            self.reads.append((loop.time(), msg.param_index))
            if self.answers_read:
                p = self.params[msg.param_index]
                loop.call_later(0.05, self._deliver, p.name, p.value, p.index)

    def _deliver(self, name: str, value: float, index: int) -> None:
        msg = mavlink.MAVLink_param_value_message(name.encode(), value, REAL32, len(self.params), index)
        raw = msg.pack(mavlink.MAVLink(None, 1, 1))  # from system 1, component 1
        for callback in list(self._callbacks):
            callback(msg, raw, 0.0)


def test_the_client_re_requests_exactly_the_missing_indices_in_batches():
    vehicle = ScriptedVehicle(40, answers_list=lambda i: i % 3 != 0)  # 14 of 40 lost
    got = run(download_params(vehicle, 1), lockstep=True)
    assert [p.name for p in got] == [p.name for p in vehicle.params]
    assert [p.value for p in got] == [p.value for p in vehicle.params]
    assert sorted(i for _, i in vehicle.reads) == list(range(0, 40, 3))  # each missing one, once
    batches = [[i for t, i in vehicle.reads if t == when] for when in sorted({t for t, _ in vehicle.reads})]
    assert [len(b) for b in batches] == [client.READ_BATCH, 14 - client.READ_BATCH]  # the next once answered
    assert vehicle.reads[-1][0] - vehicle.reads[0][0] < client.QUIET_S  # ... without waiting for silence


def test_the_client_names_the_vehicle_and_how_many_are_missing():
    vehicle = ScriptedVehicle(25, answers_list=lambda i: i not in (3, 17), answers_read=False)
    missing = r"vehicle 1: 2 of 25 parameters missing \(first: index 3\) after 4 s"
    with pytest.raises(UserError, match=missing):
        run(download_params(vehicle, 1, timeout_s=4.0), lockstep=True)
    silent = ScriptedVehicle(5, answers_list=lambda i: False, answers_read=False)
    silent.send = lambda msg: None
    with pytest.raises(
        UserError, match=r"vehicle 1 component 1: no PARAM_VALUE of its list within 3 s of \S+$"
    ):
        run(download_params(silent, 1, timeout_s=3.0), lockstep=True)
    # a vehicle whose every PARAM_VALUE says param_count 0 answered, but with no list: said so
    empty = ScriptedVehicle(0, answers_list=lambda i: True)
    with pytest.raises(
        UserError, match=r"within 3 s of PARAM_REQUEST_LIST \(\d+ outside any list: param_count 0"
    ):
        run(download_params(empty, 1, timeout_s=3.0), lockstep=True)


# ----------------------------------------------------------------- values and file formats


@pytest.mark.parametrize(
    ("value", "text"),
    [(0.3, "0.3"), (float32(0.1), "0.1"), (10.0, "10.0"), (-25.0, "-25.0"), (2.5e-5, "2.5e-05"),
     (float32(3.4028234e38), "3.4028235e+38"), (176126, "176126"), (-1, "-1"),
     (float32(1 / 3), "0.33333334"), (float32(2.6087282e15), "2608728200000000.0")],
)  # fmt: skip
def test_values_are_written_in_the_shortest_form_that_reads_back_the_same_float32(value, text):
    assert format_value(value) == text


def test_every_float32_reads_back_from_its_text():
    rng = random.Random(5)
    for _ in range(20_000):
        value = struct.unpack("<f", struct.pack("<I", rng.getrandbits(32)))[0]
        if value == value and abs(value) != float("inf"):
            text = format_value(value)
            assert float32(float(text)) == value, (value, text)
            digits = text.lstrip("-").split("e")[0].replace(".", "").strip("0")
            assert len(digits) <= 9, text  # at most float32's 9 significant digits


def test_the_format_is_told_by_content_not_by_name():
    qgc = parse_params("# Onboard parameters for Vehicle 1\n1\t1\tRTL_ALT\t1500\t6\n1\t1\tWP_SPD\t10.0\t9\n")
    assert qgc == [ParamEntry("RTL_ALT", 1500, 2, 6, 1), ParamEntry("WP_SPD", 10.0, 3, 9, 1)]
    mp = parse_params("#NOTE: 01.01.2026\r\nRTL_ALT,1500\r\nWP_SPD,10 # cruise\r\nLOG_BITMASK 0x2AFFE\r\n")
    assert mp == [
        ParamEntry("RTL_ALT", 1500, 2),
        ParamEntry("WP_SPD", 10, 3),
        ParamEntry("LOG_BITMASK", 176126, 4),
    ]


# ----------------------------------------------------------------- MAVProxy (pymavlink mavparm)


def test_mavproxy_loads_what_we_write(fleet, tmp_path, capsys):
    """`param load` (MAVParmDict.load) reads our .param file with the vehicle's values."""
    values, types = held(fleet, 1)
    assert main(["params", "get", *connect(fleet, 1), "-o", str(tmp_path / "ours.param")]) == 0
    loaded = MAVParmDict()
    assert loaded.load(str(tmp_path / "ours.param"), use_excludes=False)
    assert set(loaded) == set(values)
    for name, value in loaded.items():
        assert float32(value) == float32(values[name]), name
    capsys.readouterr()


def test_we_read_what_mavproxy_saves(fleet, tmp_path, capsys):
    """`param save` (MAVParmDict.save: the name padded to 16, floats as %f) is read by ours with the
    values MAVProxy wrote, and against the vehicle it diffs clean."""
    values, _ = held(fleet, 1)
    saved = MAVParmDict()
    saved.update(values)  # what MAVProxy holds after a fetch: PARAM_VALUE's floats
    saved.save(str(tmp_path / "mavproxy.parm"), verbose=False)
    text = (tmp_path / "mavproxy.parm").read_text()
    assert "RTL_ALT          1500.000000\n" in text  # MAVProxy's layout, not ours
    ours = {e.name: e.value for e in read_param_file(tmp_path / "mavproxy.parm")}
    assert ours == {n: float(f"{v:f}") for n, v in values.items()}
    assert main(["params", "diff", str(tmp_path / "mavproxy.parm"), *connect(fleet, 1)]) == 0
    capsys.readouterr()


def test_params_starts_lean():
    """`params` imports neither the planners nor numpy, pyproj or the mock (as `upload`)."""
    heavy = (
        "gcs_planner.planning",
        "gcs_planner.flight.coalition",
        "scipy",
        "rerun",
        "sitl_mock",
        "numpy",
        "pyproj",
    )
    argv = ["params", "set", "/nonexistent.param", "--connect", "udpout:127.0.0.1:9", "--sysid", "1"]
    code = (
        f"import sys; from gcs_planner.cli import main; main({argv!r});"
        f" print(sorted(m for m in sys.modules if m.startswith({heavy!r})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "[]", out.stdout
    assert "no such file" in out.stderr and out.stderr.count("\n") == 1
