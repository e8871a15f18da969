"""One vehicle's UDP endpoint: pymavlink v2 codec, GCS peers learnt from traffic, link faults.

Behaves like ArduPilot's ``udpin``: the vehicle binds its own port and sends to every address it
has heard from (up to ``MAX_PEERS``, oldest forgotten first), so a GCS must send first (its
heartbeat). Frames are MAVLink 2 with srcSystem = the vehicle's system id, srcComponent = 1.
Outgoing and incoming datagrams each pass through their own `FaultyChannel`; a datagram lost
on the way in teaches the vehicle nothing (not even the peer's address). With a signing key the
vehicle signs every frame and drops unsigned or badly signed ones, as ArduPilot does with signing on.
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.mavlink.signing import enable_signing, set_link_key  # noqa: E402
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
        self._signing_key = signing_key
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        if signing_key is not None:
            enable_signing(self._mav, signing_key, sign_outgoing=True)
        self.rejected = 0  # frames dropped: undecodable, or unsigned / badly signed
        self._parsers: dict[tuple, mavlink.MAVLink] = {}
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

    def set_signing_key(self, key: bytes | None) -> None:
        """Sign and verify with ``key`` from now on (None: neither), on every peer's parser too."""
        self._signing_key = key
        set_link_key(self._mav, self._parsers.values(), key)

    def forget_peers(self) -> None:
        self.peers.clear()
        self._parsers.clear()

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
        data = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        for peer in self.peers:
            self.out.send(data, peer)

    def _sendto(self, data: bytes, addr: tuple) -> None:
        if self.transport is not None:
            self.sent += 1
            self.transport.sendto(data, addr)

    def _receive(self, data: bytes, addr: tuple) -> None:
        parser = self._parsers.get(addr)
        if parser is None:
            parser = self._add_peer(addr)
            if self._on_new_peer is not None:
                self._on_new_peer(addr)
        try:
            msgs = parser.parse_buffer(data) or []
        except mavlink.MAVError as exc:
            log.debug("vehicle %d: undecodable datagram from %s: %s", self.sysid, addr, exc)
            self.rejected += 1
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self.rejected += 1
                continue
            attach_extensions(msg, msg.get_msgbuf())
            self._on_message(msg, addr)

    def _add_peer(self, addr: tuple) -> mavlink.MAVLink:
        if len(self.peers) >= MAX_PEERS:
            oldest = self.peers.pop(0)
            self._parsers.pop(oldest, None)
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        if self._signing_key is not None:
            enable_signing(parser, self._signing_key, sign_outgoing=False)
        self._parsers[addr] = parser
        self.peers.append(addr)
        log.info("vehicle %d: GCS peer %s:%d", self.sysid, *addr[:2])
        return parser
