"""One vehicle's UDP endpoint: pymavlink v2 codec, GCS peers learnt from traffic, link faults.

Behaves like ArduPilot's ``udpin``: the vehicle binds its own port and sends to every address it
has heard from (up to ``MAX_PEERS``, oldest forgotten first), so a GCS must send first (its
heartbeat). Frames are MAVLink 2 with srcSystem = the vehicle's system id, srcComponent = 1.
Outgoing and incoming datagrams each pass through their own `FaultyChannel`; a datagram lost
on the way in teaches the vehicle nothing (not even the peer's address).

Receiving: each datagram is framed on its own (gcs_planner/mavlink/framing.py; no bytes carried
to the next datagram), each frame decoded by one keyless pymavlink decoder. An address becomes a
peer only once a frame from it decoded and, with signing on, verified: junk or forged frames from
any number of ports cannot push the GCS out of the peer table. That is a choice, not a claim:
ArduPilot's UDP drivers learn a peer address below the MAVLink parser, from whatever arrives; a
mock whose peer table junk can flush would make every GCS test behind it depend on its neighbours.

Signing (signing.py, signing_streams.py): with a key the vehicle signs every frame with a
timestamp that follows the wall clock and drops unsigned, badly signed and replayed frames, as
ArduPilot does with signing on (``GCS_Signing.cpp``: one ``signing_streams`` replay table for all
channels, here for all peer addresses; ``mavlink_signature_check`` checks the signature before it
looks at or stores the timestamp).
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.mavlink.framing import frames  # noqa: E402
from gcs_planner.mavlink.signing import LinkSigning  # noqa: E402
from gcs_planner.mavlink.wire import attach_extensions  # noqa: E402
from sitl_mock.faults import FaultyChannel, LinkFaults  # noqa: E402

__all__ = ["MAX_PEERS", "VehicleLink"]

log = logging.getLogger(__name__)

MAX_PEERS = 8
OnMessage = Callable[[mavlink.MAVLink_message, tuple], None]


class VehicleLink(asyncio.DatagramProtocol):
    """UDP endpoint of one vehicle; `send(msg)` encodes once and sends to all known peers."""

    def __init__(
        self,
        sysid: int,
        on_message: OnMessage,
        faults: LinkFaults,
        compid: int = 1,
        on_new_peer: Callable[[tuple], None] | None = None,
        signing_key: bytes | None = None,
    ) -> None:
        self.sysid = sysid
        self._on_message = on_message
        self._on_new_peer = on_new_peer
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.signing = LinkSigning(self._mav, signing_key)
        self._decoder = mavlink.MAVLink(None)  # keyless: signatures are checked by self.signing
        self.rejected = 0  # frames dropped: undecodable, or unsigned / badly signed / replayed
        self.peers: list[tuple] = []
        self.out = FaultyChannel(self._sendto, faults, (sysid, 0))
        self.inbound = FaultyChannel(self._receive, faults, (sysid, 1))
        self.transport: asyncio.DatagramTransport | None = None
        self.sent = 0

    async def open(self, host: str, port: int) -> None:
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: self, local_addr=(host, port))

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()
            self.transport = None

    @property
    def address(self) -> tuple[str, int]:
        if self.transport is None:
            raise RuntimeError(f"vehicle {self.sysid}: link not open")
        return self.transport.get_extra_info("sockname")[:2]

    def set_faults(self, faults: LinkFaults) -> None:
        self.out.set_faults(faults)
        self.inbound.set_faults(faults)

    @property
    def signing_key(self) -> bytes | None:
        return self.signing.key

    def set_signing_key(self, key: bytes | None, initial_timestamp: int = 0) -> None:
        """Sign and verify with ``key`` from now on (None: neither). ``initial_timestamp`` (from
        SETUP_SIGNING) is a floor for the timestamps sent, as ArduPilot's ``load_signing_key``."""
        self.signing.set_key(key)
        self.signing.clock.observe(initial_timestamp)

    def forget_peers(self) -> None:
        """Reboot: peers forgotten. The replay table is kept: ArduPilot loses it with RAM but restarts
        its clock 60 s past the stored timestamp (``load_signing_key``), closing the same window."""
        self.peers.clear()

    # --- asyncio protocol ----------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple) -> None:
        self.inbound.send(data, addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("vehicle %d: UDP error %s", self.sysid, exc)

    # --- send / receive ------------------------------------------------------------------------
    def send(self, msg: mavlink.MAVLink_message) -> None:
        """Encode ``msg`` (one sequence number) and send it to every peer."""
        if not self.peers:
            return
        data = self.signing.pack(msg)
        self._mav.seq = (self._mav.seq + 1) % 256
        for peer in self.peers:
            self.out.send(data, peer)

    def _sendto(self, data: bytes, addr: tuple) -> None:
        if self.transport is not None:
            self.sent += 1
            self.transport.sendto(data, addr)

    def _receive(self, data: bytes, addr: tuple) -> None:
        found, junk = frames(data)
        self.rejected += junk
        for frame in found:
            msg = self._decode(frame)
            if msg is None or not self.signing.accept(frame):
                self.rejected += 1
                continue
            if addr not in self.peers:
                self._add_peer(addr)
                if self._on_new_peer is not None:
                    self._on_new_peer(addr)
            msg._signed = self.signing.key is not None  # verified above
            attach_extensions(msg, frame)
            self._on_message(msg, addr)

    def _decode(self, frame: bytes) -> mavlink.MAVLink_message | None:
        if frame[0] == 0xFD and frame[2] & ~mavlink.MAVLINK_IFLAG_SIGNED:
            return None
        try:
            return self._decoder.decode(bytearray(frame))
        except mavlink.MAVError as exc:
            log.debug("vehicle %d: undecodable frame: %s", self.sysid, exc)
            return None

    def _add_peer(self, addr: tuple) -> None:
        if len(self.peers) >= MAX_PEERS:
            self.peers.pop(0)
        self.peers.append(addr)
        log.info("vehicle %d: GCS peer %s:%d", self.sysid, *addr[:2])
