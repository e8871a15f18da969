"""The client's read-back model (gcs_planner/autopilots/readback.py) and the mock autopilot's own
storage (sitl_mock/storage.py) are two implementations of the same autopilot sources: they must
agree on every item, in float32 / C-integer arithmetic, and ``--verify`` must pass exactly on what
the autopilot returns (ArduPilot's cm altitudes, PX4's float32 yaw) and never raise on extremes."""

from __future__ import annotations

import ast
import asyncio
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.autopilots import readback
from gcs_planner.mavlink.errors import MissionError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient, compare_items
from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType
from sitl_mock import storage
from sitl_mock.fleet import MockFleet

ROOT = Path(__file__).resolve().parents[1]
PAIRS = {
    "arducopter": (readback.ARDUCOPTER, storage.ARDUCOPTER),
    "arduplane": (readback.ARDUPLANE, storage.ARDUPLANE),
    "px4": (readback.PX4, storage.PX4),
}
# every command either table knows, plus some both keep as sent
AP_COMMANDS = sorted(set(storage._AP_SLOTS) | {16, 30, 92, 94, 188, 191, 195, 113, 114, 176, 207, 211})
PX4_POSITIONAL = [16, 17, 19, 21, 22, 31, 84, 85, 179, 189, 195, 201]
PX4_POSITIONLESS = [177, 178, 20, 93, 112, 203, 206, 2000, 2500, 3000]
F32_MAX = float(np.finfo(np.float32).max)


def _value(rng: np.random.Generator) -> float:
    """A param: whole-degree yaws, 2-decimal values, small integers, negatives and extremes."""
    kind = rng.integers(10)
    if kind < 3:
        return float(rng.integers(-360, 720))
    if kind < 6:
        return round(float(rng.uniform(-500, 70000)), 2)
    if kind < 8:
        return float(rng.integers(0, 300))
    extremes = [0.0, -0.0, 0.5, -0.5, 65535.7, 1e6, -1e6, 3e38, -3e38, F32_MAX, math.inf, -math.inf]
    return float(rng.choice([*extremes, math.nan, 1e-40, 359.999, 2.5]))


def _z(rng: np.random.Generator) -> float:
    kind = rng.integers(8)
    if kind < 5:
        return round(float(rng.uniform(-100, 5000)), 2)
    if kind < 6:
        return round(float(rng.uniform(82000, 84000)), 2)
    return float(rng.choice([0.0, 65.38, 83.13, 25.34567, -0.01, 82999.99, 83000.0, 3e38, -3e38, math.inf,
                             math.nan, 1e-7]))  # fmt: skip


def _item(rng: np.random.Generator, autopilot: str, seq: int) -> MissionItem:
    mission_type = MissionType(rng.choice([0, 0, 0, 0, 1, 2]))
    if autopilot == "px4":
        if mission_type == MissionType.FENCE:
            command, frame = int(rng.choice([5000, 5001, 5002, 5003, 5004])), int(rng.choice([0, 3, 5, 6]))
        elif mission_type == MissionType.RALLY:
            command, frame = 5100, int(rng.choice([0, 3, 5, 6]))
        elif rng.integers(2):
            command, frame = int(rng.choice(PX4_POSITIONAL)), int(rng.choice([0, 3, 5, 6]))
        else:
            command, frame = int(rng.choice(PX4_POSITIONLESS)), 2
    else:
        command = {1: 5001, 2: 5100}.get(int(mission_type), int(rng.choice(AP_COMMANDS)))
        frame = int(rng.choice([0, 2, 3, 5, 6, 10, 11]))
    x, y = int(rng.integers(-900_000_000, 900_000_000)), int(rng.integers(-1_800_000_000, 1_800_000_000))
    if rng.integers(3) == 0:
        x, y = int(rng.integers(0, 300)), int(rng.integers(-5, 300))
    return MissionItem(
        seq, frame, command, 0, int(rng.integers(0, 2)), *(_value(rng) for _ in range(4)), x, y, _z(rng),
        mission_type,
    )  # fmt: skip


def _same(a: MissionItem, b: MissionItem) -> bool:
    """Field for field, NaN equal to NaN (``==`` on the dataclass would not say so)."""
    return all(
        (isinstance(u, float) and math.isnan(u) and isinstance(v, float) and math.isnan(v)) or u == v
        for u, v in zip(a.fields(), b.fields(), strict=True)
    )


@pytest.mark.parametrize("autopilot", sorted(PAIRS))
def test_client_model_and_mock_storage_agree_on_random_items(autopilot):
    client, mock = PAIRS[autopilot]
    rng = np.random.default_rng(20240611 + len(autopilot))
    refused = 0
    for seq in range(4000):
        item = _item(rng, autopilot, seq)
        verdict = readback.refusal(client, item)
        assert verdict == storage.refuses(mock, item), item
        if verdict is not None:
            refused += 1
            continue
        want, got = client(item), mock(item)
        assert _same(want, got), (item, want, got)
        # and the verify of the mock's answer passes (with NaN's "anything goes" the same)
        assert compare_items([item], [got], client) is None, item
    assert 50 < refused < 2000  # the extremes are exercised


@pytest.mark.parametrize("autopilot", sorted(PAIRS))
def test_whole_degree_yaws_and_two_decimal_altitudes_agree(autopilot):
    client, mock = PAIRS[autopilot]
    for deg in range(-360, 720):
        for z in (round(deg * 0.37 + 10, 2), deg / 100):
            item = MissionItem(
                1, 6, 16, param1=2.0, param2=3.0, param4=float(deg), x=473977420, y=85455940, z=z
            )
            assert _same(client(item), mock(item)), item
            assert compare_items([item], [mock(item)], client) is None


def test_the_cross_check_fails_when_one_side_changes(monkeypatch):
    """A double-precision altitude on the client side (the old model) disagrees with the mock."""
    item = MissionItem(1, 3, 16, z=65.38, x=473977420, y=85455940)
    assert _same(readback.ARDUCOPTER(item), storage.ARDUCOPTER(item))
    monkeypatch.setattr(readback, "_ap_alt_back", lambda z: np.float32(math.trunc(float(z) * 100) / 100))
    assert not _same(readback.ARDUCOPTER(item), storage.ARDUCOPTER(item))
    monkeypatch.undo()
    monkeypatch.setattr(storage, "_DEG_TO_RAD", math.pi / 180)  # double radians on the mock side
    yaws = [MissionItem(1, 6, 16, param4=float(d)) for d in range(360)]
    assert any(not _same(readback.PX4(it), storage.PX4(it)) for it in yaws)


def test_ardupilot_altitude_is_truncated_cm_times_0_01f():
    item = MissionItem(7, 3, 16, z=65.38, x=473977420, y=85455940)
    for model in (readback.ARDUCOPTER, storage.ARDUCOPTER, readback.ARDUPLANE, storage.ARDUPLANE):
        assert model(item).z == float(np.float32(65.369995)) == 65.3699951171875
    # 83.13f * 100.0f rounds to 8313.0f in float32 (8312.99972 in double): 8313 cm
    assert storage.ARDUCOPTER(replace(item, z=83.13)).z == float(np.float32(8313) * np.float32(0.01))
    # the double-truncation of the old model: what comes back verifies, 65.37 does not
    back = storage.ARDUCOPTER(item)
    assert compare_items([item], [back], readback.ARDUCOPTER) is None
    wrong = compare_items([item], [replace(back, z=65.37)], readback.ARDUCOPTER)
    assert wrong == "item 7: z is 65.37000274658203, expected 65.36999511718750 (sent 65.38)"


def test_px4_whole_degree_yaws_verify():
    """The 4 of 360 whole-degree yaws the double-precision model failed (param4 is 234, sent 234)."""
    items = [MissionItem(i, 6, 16, param4=float(i), x=473977420, y=85455940, z=20.0) for i in range(360)]
    back = [storage.PX4(it) for it in items]
    assert compare_items(items, back, readback.PX4) is None
    assert back[234].param4 == float(np.float32(233.99997))  # float32 degrees(wrap_2pi(radians(234)))
    assert [it.param4 for it in back] != [float(i) for i in range(360)]


def test_mismatch_names_item_field_and_both_values():
    item = MissionItem(3, 2, 178, param1=1.0, param2=7.3)
    back = replace(storage.PX4(item), param2=7.0)
    assert compare_items([item], [back], readback.PX4) == (
        "item 3: param2 is 7.00000000000000, expected 7.30000019073486 (sent 7.3)"
    )
    assert compare_items([item], [replace(back, frame=0)], readback.PX4).startswith(
        "item 3: frame is 0, expected 2"
    )


@pytest.mark.parametrize("z", [3e38, -3e38, math.inf, -math.inf, math.nan, 83000.0, F32_MAX])
def test_extreme_altitudes_never_raise(z):
    item = MissionItem(1, 3, 16, z=z, x=473977420, y=85455940)
    for name, (client, mock) in PAIRS.items():
        verdict = readback.refusal(client, item)
        assert verdict == storage.refuses(mock, item), name
        client(item)  # no OverflowError
        compare_items([item], [readback.wire(item)], client)
    assert readback.refusal(readback.ARDUCOPTER, item) == MissionResult.INVALID_PARAM7
    # a positionless ArduPilot item drops z: stored, reported 0
    jump = MissionItem(2, 2, 177, param1=1.0, param2=2.0, z=z)
    assert storage.ARDUCOPTER(jump).z == readback.ARDUCOPTER(jump).z == 0.0


def test_the_mock_storage_does_not_import_the_client_model():
    for path in (ROOT / "sitl_mock").glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import | ast.ImportFrom) else []
            module = node.module if isinstance(node, ast.ImportFrom) else ""
            assert "readback" not in module and not any("readback" in n for n in names), path


# ----------------------------------------------------------------- over UDP, through --verify
UNGATED = {"arm_ready_s": 0.0}
HOME = (473977420, 85455940)


def mixed_mission(n: int, px4: bool) -> list[MissionItem]:
    """Waypoints with 2-decimal altitudes and whole-degree yaws, loiters, speed changes, jumps."""
    rng = np.random.default_rng(7)
    items = [MissionItem(0, 3 if not px4 else 6, 22, z=10.0, x=HOME[0], y=HOME[1])]  # take-off
    while len(items) < n:
        seq = len(items)
        x, y = HOME[0] + int(rng.integers(-20000, 20000)), HOME[1] + int(rng.integers(-20000, 20000))
        z = round(float(rng.uniform(5, 150)), 2)
        kind = seq % 7
        if kind in (0, 1, 2):
            item = MissionItem(seq, 6, 16, param1=float(rng.integers(0, 5)), param2=2.0,
                               param4=float(rng.integers(0, 360)), x=x, y=y, z=z)  # fmt: skip
        elif kind == 3:
            radius = float(rng.choice([-25, 25]))
            item = MissionItem(seq, 6, 19, param1=float(rng.integers(1, 30)), param3=radius, x=x, y=y, z=z)
        elif kind == 4:
            item = MissionItem(
                seq, 2, 178, param1=1.0, param2=round(float(rng.uniform(2, 15)), 2), param3=-1.0
            )
        elif kind == 5:
            item = MissionItem(seq, 2, 177, param1=float(max(1, seq - 3)), param2=1.0)
        else:
            item = MissionItem(seq, 6, 17, param3=30.0, param4=float(rng.integers(0, 360)), x=x, y=y, z=z)
            item = item if px4 else replace(item, command=16)  # a loiter-forever would end the mission
        if not px4 and item.frame == 2:
            item = replace(item, frame=0)
        items.append(item)
    if not px4:
        items[0] = MissionItem(0, 0, 16, x=HOME[0], y=HOME[1], z=488.0)  # the home slot
    return items


async def _connected(fleet: MockFleet) -> MavlinkLink:
    link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
    await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5)
    return link


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_verify_passes_on_a_300_item_mixed_mission_over_udp(profile):
    items = mixed_mission(300, px4=profile == "px4")
    assert any(round(it.z, 2) != float(np.float32(it.z)) for it in items)  # values float32 cannot hold

    async def main():
        async with MockFleet(count=1, profile=profile, flight=UNGATED) as fleet:
            link = await _connected(fleet)
            result = await MissionClient(link, 1).upload(items, verify=True)
            assert result.verified and result.count == 300
            back = await MissionClient(link, 1).download()
            model = readback.PX4 if profile == "px4" else readback.ARDUCOPTER
            assert compare_items(items, back, model, skip_home=profile == "ardupilot") is None
            if profile == "ardupilot":
                z = [it.z for it in back[1:] if it.command == 16]
                assert any(v != round(v, 2) for v in z)  # float32 cm altitudes came back
            await link.close()

    asyncio.run(asyncio.wait_for(main(), 120))


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_altitude_3e38_gets_the_autopilots_answer_and_no_traceback(profile, caplog):
    items = mixed_mission(6, px4=profile == "px4")
    items[2] = replace(items[2], z=3e38)  # a waypoint: a valid float32

    async def main():
        async with MockFleet(count=1, profile=profile, flight=UNGATED) as fleet:
            link = await _connected(fleet)
            client = MissionClient(link, 1)
            if profile == "ardupilot":
                with pytest.raises(MissionError) as refused:
                    await client.upload(items, verify=True)
                assert refused.value.result == MissionResult.INVALID_PARAM7
            else:  # PX4 keeps a float altitude: stored, returned, verified
                result = await client.upload(items, verify=True)
                assert result.verified
                assert (await client.download())[2].z == float(np.float32(3e38))
            # the vehicle's upload session is usable afterwards
            good = mixed_mission(6, px4=profile == "px4")
            assert (await client.upload(good, verify=True)).verified
            await link.close()

    asyncio.run(asyncio.wait_for(main(), 60))
    assert "Traceback" not in caplog.text and not [r for r in caplog.records if r.exc_info]


def test_positionless_commands_are_the_ones_the_generator_thinks():
    assert all(has_position(c) for c in PX4_POSITIONAL) and not any(has_position(c) for c in PX4_POSITIONLESS)
