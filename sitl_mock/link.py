"""One vehicle's MAVLink endpoint: pymavlink v2 codec, GCS peers, link faults.

Three transports (``TRANSPORTS``), each what a real autopilot offers:
- ``udpin`` (default): like ArduPilot's ``udpin`` (SITL ``--serial0 udp:...``/MAVProxy's
  ``udpout`` to it): the vehicle binds its own port and sends to every address it has heard from
  (up to ``MAX_PEERS``, oldest forgotten first), so a GCS must send first (its heartbeat).
- ``udpclient``: the vehicle binds an ephemeral port and sends to one GCS address from the start,
  and hears only that address (a connected socket), as ArduPilot's ``--serial0
  udpclient:127.0.0.1:14550`` and PX4 SITL (which streams to the GCS port 14550 unasked): several
  vehicles can share one GCS ``udpin`` port. Its GCS stays a peer across reboots.
- ``tcp``: the vehicle listens on a TCP port and serves one GCS connection at a time (ArduPilot
  SITL's default ``tcp:5760`` on SERIAL0; a further connection is closed while one is served); a
  byte stream, framed by gcs_planner/wire/framing.py's StreamFramer. Link faults act on whole
  frames out and on the received chunks in (meant for UDP).
Frames are MAVLink 2 with srcSystem = the vehicle's system id, srcComponent = 1.
Outgoing and incoming datagrams each pass through their own `FaultyChannel`; a datagram lost
on the way in teaches the vehicle nothing (not even the peer's address).

Receiving: each datagram is framed on its own (gcs_planner/wire/framing.py; no bytes carried
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

from gcs_planner.wire.framing import StreamFramer, frames  # noqa: E402
from gcs_planner.wire.signing import LinkSigning  # noqa: E402
from gcs_planner.wire.wire import attach_extensions  # noqa: E402
from sitl_mock.faults import FaultyChannel, LinkFaults  # noqa: E402

__all__ = ["MAX_PEERS", "TRANSPORTS", "VehicleLink"]

log = logging.getLogger(__name__)

MAX_PEERS = 8
MAX_DATAGRAM_BYTES = 1400  # a batch of frames stays within one Ethernet MTU
TRANSPORTS = ("udpin", "udpclient", "tcp")
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
        self.transport: asyncio.DatagramTransport | None = None  # udpin / udpclient socket
        self.sent = 0
        self.kind = "udpin"
        self._fixed_peers: list[tuple] = []  # udpclient: the GCS, a peer from the start
        self._server: asyncio.AbstractServer | None = None  # tcp: the listening socket
        self._conn: _TcpConnection | None = None  # tcp: the GCS connection served
        self.batching = False  # hold frames until flush() (the fleet flushes every tick)
        self._held: list[bytes] = []
        self._held_bytes = 0

    async def open(
        self, host: str, port: int, kind: str = "udpin", gcs: tuple[str, int] | None = None
    ) -> None:
        """Bind ``host:port`` (udpin, tcp) or an ephemeral port of ``host`` sending to ``gcs`` (udpclient)."""
        if kind not in TRANSPORTS:
            raise ValueError(f"vehicle transport must be one of {TRANSPORTS}, got {kind!r}")
        loop = asyncio.get_running_loop()
        self.kind = kind
        if kind == "tcp":
            self._server = await loop.create_server(lambda: _TcpConnection(self), host, port)
        elif kind == "udpclient":
            if gcs is None:
                raise ValueError("a udpclient vehicle needs the GCS address it sends to (gcs=(host, port))")
            await loop.create_datagram_endpoint(lambda: self, local_addr=(host, 0), remote_addr=tuple(gcs))
            self._fixed_peers = [self.transport.get_extra_info("peername")[:2]]
            self.peers[:] = self._fixed_peers
        else:
            await loop.create_datagram_endpoint(lambda: self, local_addr=(host, port))

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()
            self.transport = None
        if self._conn is not None:
            self._conn.transport.close()
            self._conn = None
        if self._server is not None:
            self._server.close()
            self._server = None

    @property
    def address(self) -> tuple[str, int]:
        """The vehicle's own address: its UDP port (udpclient: the ephemeral one), or its TCP port."""
        if self._server is not None:
            return self._server.sockets[0].getsockname()[:2]
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
        its clock 60 s past the stored timestamp (``load_signing_key``), closing the same window.
        A udpclient keeps sending to its GCS; a TCP connection is dropped (the GCS reconnects).
        What was said before (the reboot's COMMAND_ACK) leaves first."""
        self.flush()
        self.peers[:] = self._fixed_peers
        if self._conn is not None:
            self._conn.transport.close()
            self._conn = None

    # --- asyncio protocol ----------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple) -> None:
        self.inbound.send(data, addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("vehicle %d: UDP error %s", self.sysid, exc)

    # --- send / receive ------------------------------------------------------------------------
    def send(self, msg: mavlink.MAVLink_message) -> None:
        """Encode ``msg`` (one sequence number) and send it to every peer, at once or, while
        ``batching``, with the other frames of this tick (``flush``)."""
        if not self.peers:
            return
        data = self.signing.pack(msg)
        self._mav.seq = (self._mav.seq + 1) % 256
        if not self.batching:
            for peer in self.peers:
                self.out.send(data, peer)
            return
        if self._held_bytes + len(data) > MAX_DATAGRAM_BYTES:
            self.flush()
        self._held.append(data)
        self._held_bytes += len(data)

    def flush(self) -> None:
        """Send the frames held while batching, as one datagram to each peer (ArduPilot's and PX4's
        UDP drivers send what their MAVLink buffer holds when they run, several frames a datagram)."""
        if not self._held:
            return
        data = b"".join(self._held)
        self._held.clear()
        self._held_bytes = 0
        for peer in self.peers:
            self.out.send(data, peer)

    def _sendto(self, data: bytes, addr: tuple) -> None:
        if self._conn is not None:
            if addr == self._conn.peer:
                self.sent += 1
                self._conn.transport.write(data)
        elif self.transport is not None:
            self.sent += 1
            self.transport.sendto(data, None if self._fixed_peers else addr)  # udpclient: connected

    def _receive(self, data: bytes, addr: tuple) -> None:
        conn = self._conn
        if conn is not None and addr == conn.peer:
            found, junk = conn.framer.feed(data)
        else:
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
        self.flush()  # the replies leave now, not at the next tick

    def _decode(self, frame: bytes) -> mavlink.MAVLink_message | None:
        if frame[0] == 0xFD and frame[2] & ~mavlink.MAVLINK_IFLAG_SIGNED:
            return None
        try:
            return self._decoder.decode(bytearray(frame))
        except mavlink.MAVError as exc:
            log.debug("vehicle %d: undecodable frame: %s", self.sysid, exc)
            return None

    # --- tcp -------------------------------------------------------------------------------------
    def _tcp_connected(self, conn: _TcpConnection) -> bool:
        """Serve ``conn`` unless one is served already (then False: it is closed)."""
        if self._conn is not None or self._server is None:
            return False
        self._conn = conn
        log.info("vehicle %d: GCS connected over TCP from %s:%d", self.sysid, *conn.peer[:2])
        self.peers[:] = [conn.peer]  # a TCP server talks to its client at once (ArduPilot SITL)
        if self._on_new_peer is not None:
            self._on_new_peer(conn.peer)
        return True

    def _tcp_lost(self, conn: _TcpConnection) -> None:
        if self._conn is conn:
            self._conn = None
            if conn.peer in self.peers:
                self.peers.remove(conn.peer)

    def _add_peer(self, addr: tuple) -> None:
        if len(self.peers) >= MAX_PEERS:
            self.peers.pop(0)
        self.peers.append(addr)
        log.info("vehicle %d: GCS peer %s:%d", self.sysid, *addr[:2])


class _TcpConnection(asyncio.Protocol):
    """One GCS connection to a tcp vehicle: its bytes go through the vehicle's inbound channel."""

    def __init__(self, link: VehicleLink) -> None:
        self.link = link
        self.framer = StreamFramer()
        self.transport: asyncio.Transport | None = None
        self.peer: tuple = ()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        self.peer = tuple(transport.get_extra_info("peername")[:2])
        if not self.link._tcp_connected(self):
            transport.close()

    def data_received(self, data: bytes) -> None:
        if self.link._conn is self:
            self.link.inbound.send(data, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        self.link._tcp_lost(self)
