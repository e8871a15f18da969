"""Every mission file of the shared corpus (ArduPilot autotest, QGroundControl, PX4, pymavlink;
../shared/corpus/MANIFEST.tsv names each file's repository, path and commit), read where it lies:

- it loads;
- written as .plan and as WPL and read back, it is the same MissionFile, except where the writer
  said what the format cannot carry (files.Loss): each difference must be named by one;
- each list it defines, uploaded to the mock (ArduPilot and PX4 profiles, real UDP on loopback)
  and downloaded, is what that autopilot stores of what was sent, except the refusals listed in
  EXPECTED_REFUSALS (the real autopilot refuses those too).
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import random
from pathlib import Path

import pytest

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient, compare_items
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.missions.files import load_mission_file, save_mission_file
from gcs_planner.missions.mission_file import LIST_NAMES, Loss, MissionFile, default_home_item
from gcs_planner.missions.validate import validate_items
from gcs_planner.wire.types import MissionType

CORPUS = Path(os.environ.get("GCS_PLANNER_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))
pytestmark = pytest.mark.skipif(not (CORPUS / "MANIFEST.tsv").is_file(), reason=f"no corpus at {CORPUS}")


def corpus_files() -> list[str]:
    """Mission files named in MANIFEST.tsv (logs are for the telemetry tests)."""
    if not (CORPUS / "MANIFEST.tsv").is_file():
        return []
    rows = [line.split("\t") for line in (CORPUS / "MANIFEST.tsv").read_text().splitlines() if line]
    return [r[0] for r in rows if not r[0].startswith("logs/")]


FILES = corpus_files()
ITEM_FIELDS = ("frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z")
SETTINGS = ("firmware_type", "vehicle_type", "cruise_speed_mps", "hover_speed_mps")
# (profile, file) -> the vehicle's answer expected, and why the real autopilot answers so too
AUTOTEST = "ardupilot/Tools/autotest"
EXPECTED_REFUSALS = {
    ("px4", "qgroundcontrol/test/MissionManager/OldFileFormat.mission"): (
        "UNSUPPORTED",
        "NAV_TAKEOFF in MAV_FRAME_MISSION: PX4 takes positional items only in a global frame",
    ),
    ("px4", f"{AUTOTEST}/ArduCopter_Tests/ConditionLocation/copter_condition_location.txt"): (
        "UNSUPPORTED",
        "command 116 is ArduPilot's own; PX4's parse_mavlink_mission_item refuses commands it lacks",
    ),
    ("px4", f"{AUTOTEST}/ArduPlane_Tests/DO_CHANGE_RADIUS/mission.txt"): (
        "UNSUPPORTED",
        "command 219: as 116",
    ),
    ("px4", f"{AUTOTEST}/ArduCopter_Tests/HomeCircleInclusionFence/single_home_circle.txt"): (
        "UNSUPPORTED",
        "fence command 5005 (development.xml): PX4's geofence takes 5000-5004 only",
    ),
}


def _same(a, b) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def differences(a: MissionFile, b: MissionFile) -> set[tuple[str, int | None, str]]:
    """(part, item index or None, field) for every field that differs between a and b."""
    out: set[tuple[str, int | None, str]] = set()
    for part in ("mission", "fence", "rally"):
        xs, ys = getattr(a, part), getattr(b, part)
        if len(xs) != len(ys):
            out.add((part, None, "count"))
            continue
        out |= {(part, i, f) for i, (x, y) in enumerate(zip(xs, ys)) for f in ITEM_FIELDS
                if not _same(getattr(x, f), getattr(y, f))}  # fmt: skip
    if a.home != b.home:
        out.add(("home", None, "position"))
    ha, hb = a.home_item or default_home_item(), b.home_item or default_home_item()
    out |= {("home", None, f) for f in ITEM_FIELDS[:7] if not _same(getattr(ha, f), getattr(hb, f))}
    if a.comments != b.comments:
        out.add(("comments", None, "every line"))
    out |= {("settings", None, f) for f in SETTINGS if getattr(a, f) != getattr(b, f)}
    return out


def covered(diff: tuple[str, int | None, str], losses: list[Loss]) -> bool:
    part, index, field = diff
    for loss in losses:
        if loss.part != part:
            continue
        wide = {"every item", "every field", "every line", "order"} & set(loss.fields)
        if (field in loss.fields or wide) and (index is None or not loss.indexes or index in loss.indexes):
            return True
    return False


def written_list(mf: MissionFile) -> str:
    """The list a WPL file of ``mf`` holds (wpl._wpl_list's rule)."""
    return "mission" if mf.mission or not (mf.fence or mf.rally) else "fence" if mf.fence else "rally"


@pytest.mark.parametrize("name", FILES)
def test_corpus_file_loads_and_round_trips(name, tmp_path):
    mf = load_mission_file(CORPUS / name)
    for suffix in (".plan", ".waypoints"):
        out = tmp_path / f"out{suffix}"
        losses = save_mission_file(out, mf)
        back = load_mission_file(out)
        diffs = differences(mf, back)
        if suffix == ".waypoints":  # the lists a WPL file does not hold are named by a loss ("every item")
            assert LIST_NAMES[next(iter(back.lists))] == written_list(mf)
        uncovered = sorted(d for d in diffs if not covered(d, losses))
        assert not uncovered, f"{name} -> {suffix}: unannounced differences {uncovered[:5]}; losses {losses}"
        # what a format keeps it keeps exactly: the reloaded file is written to the same text
        again = tmp_path / f"again{suffix}"
        save_mission_file(again, back)
        assert again.read_text() == out.read_text()


ORIGIN = Origin(-35.363262, 149.165237, 584.0)  # ArduPilot SITL's CMAC home, where most files fly


@pytest.fixture(scope="module")
def mock_fleet():
    sitl_mock = pytest.importorskip("sitl_mock")
    big = {"capacity": 1000}
    vehicles = [{"profile": "ardupilot", **big}, {"profile": "px4", **big}]
    with sitl_mock.MockFleet(vehicles=vehicles, home=ORIGIN) as fleet:
        yield fleet


async def _upload_download_all(fleet, sysid: int, autopilot: str) -> dict[str, str]:
    """file -> the first problem of its upload / download (absent: every list matched)."""
    host, port = fleet.vehicle(sysid).address
    link = await MavlinkLink.open(f"udpout:{host}:{port}")
    model = fleet.vehicle(sysid).mission_server.storage
    problems = {}
    try:
        await link.wait_for(
            lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == sysid, timeout_s=10
        )
        # storage fidelity, not verdicts (tests/test_mission_verdict.py): no post-ACK wait per file
        client = MissionClient(link, sysid, timing=Timing(verdict_s=0.0))
        for name in FILES:
            mf = load_mission_file(CORPUS / name)
            for mission_type in sorted(mf.lists):
                sent = mf.list_items(MissionType(mission_type), autopilot)
                try:
                    await client.upload(sent, mission_type=mission_type)
                    got = await client.download(mission_type)
                except Exception as exc:  # noqa: BLE001 - recorded and compared with the expected refusals
                    problems[name] = f"{type(exc).__name__}: {exc}"
                    break
                problem = compare_items(sent, got, model, skip_home=autopilot == "ardupilot")
                if problem is not None:
                    problems[name] = f"{LIST_NAMES[mission_type]}: {problem}"
                    break
    finally:
        await link.close()
    return problems


@pytest.mark.parametrize(("sysid", "autopilot"), [(1, "ardupilot"), (2, "px4")])
def test_corpus_uploads_and_downloads_match(mock_fleet, sysid, autopilot):
    problems = asyncio.run(_upload_download_all(mock_fleet, sysid, autopilot))
    expected = {name: why for (profile, name), why in EXPECTED_REFUSALS.items() if profile == autopilot}
    assert set(problems) == set(expected), {k: v for k, v in problems.items() if k not in expected}
    for name, (answer, _) in expected.items():
        assert answer in problems[name]


def _mutated(text: str, rng: random.Random) -> str:
    """One field of ``text`` replaced by a bad value: a JSON value, or a WPL / list column."""
    bad = [None, "x", -1, 1e308, [], {}, [1, 2], True, 2**40, "nan", 3.5]
    if text.lstrip().startswith("{"):
        doc = json.loads(text)
        node = doc
        while isinstance(node, dict | list) and node:
            key = rng.choice(list(node)) if isinstance(node, dict) else rng.randrange(len(node))
            if rng.random() < 0.3 or not isinstance(node[key], dict | list) or not node[key]:
                node[key] = rng.choice(bad)
                break
            node = node[key]
        return json.dumps(doc)
    lines = text.splitlines()
    if len(lines) > 1:
        i = rng.randrange(1, len(lines))
        fields = lines[i].split()
        if fields:
            fields[rng.randrange(len(fields))] = rng.choice(
                ["x", "inf", "nan", "1e40", "99999999999", "", "1.5"]
            )
            lines[i] = "\t".join(fields)
    return "\n".join(lines)


@pytest.mark.parametrize("seed", range(3))
def test_damaged_corpus_files_fail_with_one_line_or_load(seed, tmp_path):
    """A file with one bad value is refused with a MissionFileError naming it, or read; never a traceback."""
    rng = random.Random(seed)
    for name in FILES:
        path = tmp_path / f"f{Path(name).suffix}"
        path.write_text(_mutated((CORPUS / name).read_text(), rng))
        try:
            mf = load_mission_file(path)
            for autopilot in ("ardupilot", "px4"):
                for mission_type in (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY):
                    validate_items(mf.list_items(mission_type, autopilot), mission_type=mission_type)
            save_mission_file(tmp_path / "out.plan", mf)
            save_mission_file(tmp_path / "out.waypoints", mf)
        except UserError as exc:
            assert "\n" not in str(exc)
