"""MavlinkLink over a serial line: a real pseudo-terminal, bridged byte for byte to a mock vehicle's UDP port.

The bridge plays the telemetry radio: whatever the GCS writes to the tty goes to the vehicle, and the
vehicle's frames come back split into small pieces, so frames cross read boundaries as on a radio.
"""

from __future__ import annotations

import asyncio
import os

import pytest

from gcs_planner.mavlink.link import MavlinkLink, parse_url
from gcs_planner.mavlink.mission import MissionClient
from sitl_mock.fleet import MockFleet

PIECE = 7  # bytes per write towards the GCS: every frame arrives in several reads


class _Radio(asyncio.DatagramProtocol):
    """UDP side of the bridge: vehicle datagrams -> the pty master, in PIECE-byte writes."""

    def __init__(self, master_fd: int) -> None:
        self.master_fd = master_fd
        self.pieces = 0

    def datagram_received(self, data: bytes, addr: tuple) -> None:
        for k in range(0, len(data), PIECE):
            os.write(self.master_fd, data[k : k + PIECE])
            self.pieces += 1


async def _bridge(master_fd: int, vehicle: tuple[str, int]) -> tuple[asyncio.DatagramTransport, _Radio]:
    loop = asyncio.get_running_loop()
    transport, radio = await loop.create_datagram_endpoint(lambda: _Radio(master_fd), remote_addr=vehicle)
    loop.add_reader(master_fd, lambda: transport.sendto(os.read(master_fd, 4096)))
    return transport, radio


def test_upload_and_verify_over_a_serial_line(mission_of):
    async def main():
        master, slave = os.openpty()
        path = os.ttyname(slave)
        async with MockFleet(count=1, profile="ardupilot") as fleet:
            bridge, radio = await _bridge(master, fleet.addresses[0])
            link = await MavlinkLink.open(f"serial:{path}:115200")
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1, 10)
                items = mission_of(30)
                result = await MissionClient(link, 1).upload(items, verify=True)
                assert result.verified and not result.ack_lost
                assert fleet.vehicle(1).mission_server.items()[1:] == items[1:]  # seq 0: ArduPilot's home
                assert radio.pieces > 3 * link.frames_received  # frames really arrived in pieces
            finally:
                await link.close()
                asyncio.get_running_loop().remove_reader(master)
                bridge.close()
        os.close(master)
        os.close(slave)

    asyncio.run(asyncio.wait_for(main(), 60))


def test_serial_urls_parse_and_bad_ports_name_the_path():
    assert parse_url("serial:/dev/ttyUSB0") == ("serial", ("/dev/ttyUSB0", 57600))
    assert parse_url("serial:/dev/ttyACM0:115200") == ("serial", ("/dev/ttyACM0", 115200))
    by_path = "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0"
    assert parse_url(f"serial:{by_path}") == ("serial", (by_path, 57600))

    async def main():
        with pytest.raises(OSError, match="/dev/no-such-radio"):
            await MavlinkLink.open("serial:/dev/no-such-radio")
        with pytest.raises(ValueError, match="baud rate 12345"):
            await MavlinkLink.open("serial:/dev/null:12345")
        with pytest.raises(OSError, match="/dev/null: not a terminal"):
            await MavlinkLink.open("serial:/dev/null")
        with pytest.raises(OSError, match="/dev/no-such-radio"):  # serial mixes with UDP; all closed
            await MavlinkLink.open("udpout:127.0.0.1:14550", "serial:/dev/no-such-radio")

    asyncio.run(main())
