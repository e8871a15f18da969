"""MAVLink 2 signing end to end over real UDP: GCS link and mock vehicle with the same, no or a wrong key."""

from __future__ import annotations

import asyncio
import socket

import pytest

from gcs_planner.cli import main
from gcs_planner.mavlink import errors
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.wire.signing import key_from_passphrase
from sitl_mock.fleet import MockFleet

KEY = key_from_passphrase("correct horse battery staple")
SIGNED = 0x01  # MAVLink 2 incompat flag: a signature block follows


async def _link(fleet: MockFleet, key: bytes | None) -> tuple[MavlinkLink, list[bytes]]:
    link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses), signing_key=key)
    frames: list[bytes] = []
    link.subscribe(lambda msg, raw, t: frames.append(raw))
    return link, frames


def test_signed_gcs_uploads_to_a_signed_vehicle_and_every_frame_is_signed(mission_of):
    async def main():
        async with MockFleet(count=1, profile="px4", signing_key=KEY) as fleet:
            link, frames = await _link(fleet, KEY)
            await link.wait_for(lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1, 10)
            items = mission_of(12)
            assert (await MissionClient(link, 1).upload(items, verify=True)).verified
            vehicle = fleet.vehicle(1)
            kept = [vehicle.mission_server.storage(i) for i in items]
            assert vehicle.mission_server.items() == kept and vehicle.link.rejected == 0
            assert frames and all(raw[2] & SIGNED for raw in frames)
            await link.close()

    asyncio.run(asyncio.wait_for(main(), 60))


def test_signed_vehicle_ignores_an_unsigned_gcs_and_keeps_its_mission(mission_of):
    async def main():
        async with MockFleet(count=1, profile="ardupilot", signing_key=KEY) as fleet:
            vehicle = fleet.vehicle(1)
            signed, _ = await _link(fleet, KEY)
            await signed.wait_for(lambda m: m.get_type() == "HEARTBEAT", 10)
            await MissionClient(signed, 1).upload(mission_of(5))
            before = vehicle.mission_server.items()
            await signed.close()

            unsigned, frames = await _link(fleet, None)
            fast = Timing(count_retry_s=0.2, count_retries=2)
            with pytest.raises(errors.MissionTimeoutError, match="no answer to MISSION_COUNT"):
                await MissionClient(unsigned, 1, timing=fast).upload(mission_of(7, lat=400_000_000))
            assert vehicle.mission_server.items() == before  # it cannot command the vehicle ...
            assert vehicle.link.rejected >= 3
            assert not frames and len(vehicle.link.peers) == 1  # ... nor become a peer that hears it
            await unsigned.close()

    asyncio.run(asyncio.wait_for(main(), 60))


def test_wrong_key_is_dropped_and_never_answered():
    async def main():
        async with MockFleet(count=1, profile="px4", signing_key=KEY) as fleet:
            link, frames = await _link(fleet, key_from_passphrase("wrong"))
            while fleet.vehicle(1).link.rejected < 2:  # two of our heartbeats (the test has a timeout)
                await asyncio.sleep(0.05)
            assert not fleet.vehicle(1).link.peers  # a wrongly signed sender is no peer ...
            assert not link.vehicles and not frames  # ... so nothing is streamed to it
            await link.close()

    asyncio.run(asyncio.wait_for(main(), 60))


def test_signing_key_checks():
    with pytest.raises(ValueError, match="must not be empty"):
        key_from_passphrase("")
    with pytest.raises(ValueError, match="32 bytes, got 5"):
        MavlinkLink(signing_key=b"short")


def test_signing_setup_gives_a_vehicle_its_key_then_takes_it_away(capsys, mission_of):
    """`gcs-planner signing-setup` over UDP: afterwards only a GCS with the key can upload, a wrong
    current key is refused in one line, and --disable lets an unsigned GCS in again."""
    from gcs_planner.cli import main

    def upload(fleet: MockFleet, key: bytes | None) -> bool:
        async def attempt() -> bool:
            link, _ = await _link(fleet, key)
            try:
                fast = Timing(count_retry_s=0.2, count_retries=2)
                await MissionClient(link, 1, timing=fast).upload(mission_of(3))
                return True
            except errors.MissionTimeoutError:
                return False
            finally:
                await link.close()

        return asyncio.run(asyncio.wait_for(attempt(), 30))

    with MockFleet(count=1, profile="ardupilot") as fleet:
        host, port = fleet.addresses[0]
        base = ["signing-setup", "--connect", f"udpout:{host}:{port}", "--sysid", "1"]
        assert main([*base, "--new-passphrase", "correct horse battery staple"]) == 0
        out = capsys.readouterr().out
        assert "signs with the new key" in out and "unsigned messages on its first serial port" in out
        assert upload(fleet, KEY) and not upload(fleet, None)
        wrong = [*base, "--signing-passphrase", "wrong", "--heartbeat-timeout", "1", "--disable"]
        assert main(wrong) == 2 and "no HEARTBEAT" in capsys.readouterr().err
        assert main([*base, "--signing-passphrase", "correct horse battery staple", "--disable"]) == 0
        assert "signing off" in capsys.readouterr().out
        assert upload(fleet, None)
        assert main(base) == 2 and "--new-passphrase" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("passphrase", "words"), [(None, "give --signing-passphrase"), ("wrong", "not its key")]
)
def test_a_signing_vehicle_heard_without_its_key_is_named_as_signing(passphrase, words, capsys):
    """A vehicle that sends to the GCS (as SITL with --serial0 udpclient does) signs every frame: a
    GCS without its key hears only frames it cannot verify, and says so instead of "no HEARTBEAT"."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        gcs = s.getsockname()
    vehicle = {"transport": "udpclient", "gcs": gcs}
    with MockFleet(vehicles=[vehicle], signing_key=KEY):
        argv = ["clear", "--connect", f"udpin:{gcs[0]}:{gcs[1]}", "--sysid", "1", "--heartbeat-timeout", "3"]
        if passphrase:
            argv += ["--signing-passphrase", passphrase]
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert "sysid 1 signs its frames" in err and words in err and err.count("\n") == 1, err
