"""An asyncio MAVLink 2 link over several endpoints at once: many vehicles, routed by system id.

``await MavlinkLink.open("udpout:127.0.0.1:14550")`` talks to a vehicle that listens (ArduPilot SITL
``udpin``, our sitl-mock); several ``udpout`` URLs share one socket, so one link reaches a whole mock
fleet (one port per vehicle); ``udpout:HOST:FIRST-LAST`` names one remote per port of a range.
``udpin:0.0.0.0:14550`` listens and answers every peer heard from (several SITLs may all send to
it); each further ``udpin`` URL binds one more socket. ``tcp:HOST:PORT`` (alias ``tcpout:``)
connects to a vehicle that listens on TCP (ArduPilot SITL's default ``tcp:5760``).
``serial:/dev/ttyUSB0:57600`` (baud optional, default 57600) opens a telemetry radio or an
autopilot's USB port (serial_port.py). Any mix of these makes one link (transports.py); everything
above the transport is the same.

Choices:
- Each UDP datagram is framed on its own (framing.py): no bytes are carried from one datagram to
  the next, so a malformed datagram costs only itself. A serial port is a byte stream and keeps its
  incomplete tail. Frames are decoded without pymavlink's byte-wise parser: unsigned frames of plain
  numeric messages by codec.py (about two thirds of pymavlink's time), the rest by one keyless
  pymavlink decoder. Frames carry a sequence number that advances per frame sent.
- Frames are dispatched synchronously in ``datagram_received``: a transfer's reply goes out in the
  same callback that received the request (no task hop, no sleep) - the hot path of an upload.
  What the subscribers send while one datagram's (or stream read's) frames are dispatched leaves
  when they all were, in one datagram per address (up to MAX_DATAGRAM_BYTES, frames in order), as
  ArduPilot's and PX4's UDP drivers send what their buffer holds: a vehicle that answers several
  items with one datagram of requests gets the next items in one datagram, one system call and one
  wake-up for all of them (``corked()``: mission.py sends a push's window the same way).
  Autopilots and routers parse a UDP datagram as a byte stream, so several frames in one are read
  as if they came one by one.
- Routing: every peer address belongs to the endpoint it was heard on (addresses are
  endpoint-qualified, transports.py, so two endpoints never collide). A message with
  ``target_system`` goes out of the endpoint and address that system was last heard from;
  broadcasts (target 0, HEARTBEAT) go to every peer of every endpoint. A system id heard from two
  addresses within DUPLICATE_WINDOW_S is ambiguous: ``vehicles`` reports it and sending to it
  raises DuplicateSysidError (QGC merges such vehicles silently, #14812; we refuse).
- Vehicles: a system id becomes a ``VehicleInfo`` only once its autopilot's HEARTBEAT was heard
  (``is_autopilot_heartbeat``: autopilot not INVALID and a vehicle MAV_TYPE); its other frames then
  keep its addresses fresh. The info latches the autopilot's component (MAV_COMP_ID_AUTOPILOT1
  preferred): mode, armed state and type come only from that component's HEARTBEATs, so a camera
  or gimbal of the same system (its own HEARTBEAT, often with the autopilot field set) changes none.
- Frames of message ids the pinned dialect does not know (PX4 streams development / newer common
  messages) are delivered as pymavlink's ``MAVLink_unknown`` with the frame header's system and
  component ids (pymavlink leaves them 0), so they count for their own vehicle, never for system 0.
- ``subscribe(callback, sysid=N)`` delivers only that vehicle's frames: a fleet upload's transfers
  each see their own vehicle, so dispatch stays O(frames), not O(frames x transfers).
- ``take(sysid, msgids, callback, owner)``: those frames of that vehicle go to ``callback(frame,
  t_s)`` undecoded, once their length, CRC (codec.intact) and signature are checked, instead of as
  messages to ``owner``; every other subscriber still gets them decoded. ``send_payload`` sends a
  payload packed once (codec.packer) with only the header, CRC and signature made per frame. With
  both a mission upload answers a request without a message object either way (mission.py).
- Subscribers get ``(msg, raw, t_s)``: the exact received frame and the receive time as Unix
  seconds (telemetry logging); MISSION_COUNT/ACK/CURRENT carry their opaque ids (wire.py).
- The GCS sends HEARTBEAT (MAV_TYPE_GCS) at 1 Hz from open until close: autopilots use it for
  GCS failsafe and udpin-style endpoints only talk to peers they have heard from.
- ``signing_key`` (signing.py, signing_streams.py): every frame sent is signed with a timestamp
  that follows the clock; every frame received must carry a valid signature and a timestamp newer
  than the last of its (link id, sysid, compid) stream, whichever address it came from (one replay
  table per link, so a captured frame replayed from a new port is refused). The signature is
  checked before anything is learnt from a frame (peer address, stream timestamp, vehicle table).
  The rest are dropped and counted in ``frames_dropped``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from operator import methodcaller
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.core.errors import UserError  # noqa: E402
from gcs_planner.core.lockstep import LockstepLoop, now_s, unix_s  # noqa: E402
from gcs_planner.mavlink.errors import DuplicateSysidError  # noqa: E402
from gcs_planner.mavlink.serial_port import DEFAULT_BAUD  # noqa: E402
from gcs_planner.mavlink.transports import UdpProtocol, open_serial, open_tcp  # noqa: E402
from gcs_planner.wire import codec  # noqa: E402
from gcs_planner.wire.signing import LinkSigning  # noqa: E402
from gcs_planner.wire.wire import attach_extensions  # noqa: E402

__all__ = [
    "DUPLICATE_WINDOW_S", "FLEET_RCVBUF_BYTES", "GCS_COMPID", "GCS_SYSID", "VEHICLE_TYPES", "MavlinkLink",
    "VehicleInfo", "check_signing", "expand_ranges", "first_message", "is_autopilot_heartbeat", "parse_url",
    "signing_problem",
]  # fmt: skip

log = logging.getLogger(__name__)

GCS_SYSID = 255
GCS_COMPID = mavlink.MAV_COMP_ID_MISSIONPLANNER  # 190
DUPLICATE_WINDOW_S = 5.0  # two addresses heard within this time with one sysid = duplicate [s]
MAX_DATAGRAM_BYTES = 1400  # frames sent together stay within one Ethernet MTU
FLEET_RCVBUF_BYTES = 4 << 20  # a fleet link's socket receive buffer (Linux caps it at net.core.rmem_max)
HEARTBEAT_PERIOD_S = 1.0
_NOT_AUTOPILOT = mavlink.MAV_AUTOPILOT_INVALID  # HEARTBEAT of a camera, gimbal, companion or GCS
_AUTOPILOT1 = mavlink.MAV_COMP_ID_AUTOPILOT1
# MAV_TYPEs of vehicles (an autopilot's HEARTBEAT); not: GCS, antenna tracker, onboard controller,
# gimbal, ADSB, camera, charging station, FLARM, servo, ODID, battery, parachute, log, OSD, IMU,
# GPS, winch, illuminator, gripper - components, peripherals or ground equipment
VEHICLE_TYPES = frozenset({
    mavlink.MAV_TYPE_GENERIC, mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_TYPE_QUADROTOR,
    mavlink.MAV_TYPE_COAXIAL, mavlink.MAV_TYPE_HELICOPTER, mavlink.MAV_TYPE_AIRSHIP,
    mavlink.MAV_TYPE_FREE_BALLOON, mavlink.MAV_TYPE_ROCKET, mavlink.MAV_TYPE_GROUND_ROVER,
    mavlink.MAV_TYPE_SURFACE_BOAT, mavlink.MAV_TYPE_SUBMARINE, mavlink.MAV_TYPE_HEXAROTOR,
    mavlink.MAV_TYPE_OCTOROTOR, mavlink.MAV_TYPE_TRICOPTER, mavlink.MAV_TYPE_FLAPPING_WING,
    mavlink.MAV_TYPE_KITE, mavlink.MAV_TYPE_VTOL_DUOROTOR, mavlink.MAV_TYPE_VTOL_QUADROTOR,
    mavlink.MAV_TYPE_VTOL_TILTROTOR, mavlink.MAV_TYPE_VTOL_RESERVED2, mavlink.MAV_TYPE_VTOL_RESERVED3,
    mavlink.MAV_TYPE_VTOL_RESERVED4, mavlink.MAV_TYPE_VTOL_RESERVED5, mavlink.MAV_TYPE_PARAFOIL,
    mavlink.MAV_TYPE_DODECAROTOR, mavlink.MAV_TYPE_DECAROTOR, mavlink.MAV_TYPE_GENERIC_MULTIROTOR,
    mavlink.MAV_TYPE_SPACECRAFT_ORBITER, mavlink.MAV_TYPE_GROUND_QUADRUPED, mavlink.MAV_TYPE_VTOL_GYRODYNE,
})  # fmt: skip
_UNKNOWN = mavlink.MAVLink_unknown
_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_is_closing = methodcaller("is_closing")

Address = tuple[str, int]
Callback = Callable[[mavlink.MAVLink_message, bytes, float], None]
FrameCallback = Callable[[bytes, float], None]


@dataclass
class VehicleInfo:
    """What the link knows about one vehicle: created by its autopilot's first HEARTBEAT; addresses
    from any of its messages; the type, mode and armed fields only from HEARTBEATs of the latched
    autopilot component ``compid`` (module docstring)."""

    sysid: int
    address: Address
    addresses: dict[Address, float] = field(default_factory=dict)  # address -> last heard [monotonic s]
    compid: int | None = None  # the autopilot's component id (latched)
    autopilot: int | None = None  # HEARTBEAT.autopilot (MAV_AUTOPILOT)
    mav_type: int | None = None  # HEARTBEAT.type (MAV_TYPE)
    custom_mode: int | None = None
    base_mode: int | None = None

    @property
    def armed(self) -> bool:
        return bool((self.base_mode or 0) & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    def live_addresses(self, now_s: float) -> list[Address]:
        return sorted(a for a, t in self.addresses.items() if now_s - t <= DUPLICATE_WINDOW_S)

    @property
    def duplicate(self) -> bool:
        """True when the system id answers from more than one address (ambiguous target)."""
        return len(self.live_addresses(now_s())) > 1


def is_autopilot_heartbeat(msg: mavlink.MAVLink_message) -> bool:
    """A HEARTBEAT of a flight controller: autopilot not MAV_AUTOPILOT_INVALID and a vehicle
    MAV_TYPE (VEHICLE_TYPES): not a GCS, camera, gimbal, companion computer, ADSB receiver, ..."""
    return msg.get_type() == "HEARTBEAT" and msg.autopilot != _NOT_AUTOPILOT and msg.type in VEHICLE_TYPES


def parse_url(url: str) -> tuple[str, Address]:
    """'udpout:host:port' / 'udpin:host:port' (also 'udp:' = udpin) / 'tcp:host:port' (also
    'tcpout:') -> (kind, (host, port)); 'serial:PATH[:BAUD]' -> ('serial', (PATH, BAUD))."""
    if url.startswith("serial:"):
        rest = url.removeprefix("serial:")
        head, sep, tail = rest.rpartition(":")  # by-path device names contain colons
        path, baud = (head, int(tail)) if sep and tail.isdigit() else (rest, DEFAULT_BAUD)
        if not path:
            raise ValueError(f"connection URL {url!r}: expected serial:PATH or serial:PATH:BAUD")
        return "serial", (path, baud)
    try:
        kind, host, port_text = url.split(":")
        port = int(port_text)
    except ValueError:
        raise ValueError(
            f"connection URL {url!r}: expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT"
            " or serial:PATH"
        ) from None
    kind = {"udp": "udpin", "tcpout": "tcp"}.get(kind, kind)
    if kind not in ("udpin", "udpout", "tcp"):
        raise ValueError(
            f"connection URL {url!r}: scheme {kind!r} not supported (udpin, udpout, tcp, serial)"
        )
    if not 0 <= port <= 65535:
        raise ValueError(f"connection URL {url!r}: port {port} out of range")
    return kind, (host, port)


MAX_PORT_RANGE = 4096  # ports one udpout range may name


def expand_ranges(urls) -> list[str]:
    """The URLs with each ``udpout:HOST:FIRST-LAST`` replaced by one udpout URL per port."""
    out = []
    for url in urls:
        kind, _, rest = url.partition(":")
        host, _, ports = rest.rpartition(":")
        first, dash, last = ports.partition("-")
        if kind != "udpout" or not dash:
            out.append(url)
            continue
        if not (first.isdigit() and last.isdigit() and 0 < int(first) <= int(last) <= 65535):
            raise ValueError(f"connection URL {url!r}: expected a port range FIRST-LAST within 1..65535")
        if int(last) - int(first) >= MAX_PORT_RANGE:
            raise ValueError(f"connection URL {url!r}: a range names at most {MAX_PORT_RANGE} ports")
        out += [f"udpout:{host}:{port}" for port in range(int(first), int(last) + 1)]
    return out


class MavlinkLink:
    """See module docstring. Create with :meth:`open`; close with :meth:`close`."""

    def __init__(
        self, sysid: int = GCS_SYSID, compid: int = GCS_COMPID, signing_key: bytes | None = None
    ) -> None:
        self.sysid = sysid
        self.compid = compid
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.signing = LinkSigning(self._mav, signing_key)
        self._decoder = mavlink.MAVLink(None)  # keyless: signatures are checked by self.signing
        # every peer, in the order first heard or named: its endpoint-qualified address ->
        # (the endpoint's transport, the address as that transport sends to it)
        self._peers: dict[Address, tuple[object, Address]] = {}
        self._subscribers: list[Callback] = []  # every frame
        self._by_sysid: dict[int, list[Callback]] = {}  # one vehicle's frames
        # (sysid, msgid) -> the frame callbacks of take() and the subscribers they replace
        self._takers: dict[tuple[int, int], tuple[tuple[FrameCallback, ...], frozenset[Callback]]] = {}
        self.vehicles: dict[int, VehicleInfo] = {}
        self._transport = None  # the first endpoint: the UDP socket udpout remotes share, else the first
        self._endpoints: list = []  # every transport (UDP sockets, TCP connections, serial ports)
        self._udp = None  # the first UDP socket: it carries the udpout remotes
        self._closed = False
        self._heartbeat_task: asyncio.Task | None = None
        self.frames_received = 0
        self.frames_sent = 0
        self.frames_dropped = 0  # undecodable, bad CRC, or (signing) unsigned / badly signed
        self.unverified: dict[int, int] = {}  # header sysid -> signed frames dropped (not our key)
        # frames held while a datagram's frames are dispatched: (transport, address, frame)
        self._corked: list[tuple[Any, Address, bytes]] | None = None
        self._now_s: Callable[[], float] = now_s  # the clocks; open() binds them to its loop
        self._unix_s: Callable[[], float] = unix_s

    @classmethod
    async def open(
        cls,
        url: str,
        *more_urls: str,
        sysid: int = GCS_SYSID,
        compid: int = GCS_COMPID,
        heartbeat_period_s: float = HEARTBEAT_PERIOD_S,
        signing_key: bytes | None = None,
        receive_buffer_bytes: int | None = None,
    ) -> MavlinkLink:
        """Open every endpoint of the URLs: one UDP socket per udpin URL (the first one also carries
        the udpout remotes; with none, an ephemeral socket does), one TCP connection per tcp URL,
        one serial port per serial URL. ``signing_key``: sign and verify. ``receive_buffer_bytes``:
        the UDP sockets' SO_RCVBUF, for bursts from large fleets (the kernel may cap it at
        net.core.rmem_max). Whatever fails (a bind, a refused TCP connection: ConnectionError naming
        the URL) closes what was opened."""
        urls = expand_ranges((url, *more_urls))
        parsed = [parse_url(u) for u in urls]
        link = cls(sysid, compid, signing_key)
        link._bind_clocks(asyncio.get_running_loop())
        try:
            await link._open_endpoints(urls, parsed, receive_buffer_bytes)
        except BaseException:
            link._close_endpoints()
            raise
        link._start_heartbeat(heartbeat_period_s)
        return link

    async def _open_endpoints(
        self, urls: list[str], parsed: list[tuple[str, Address]], rcvbuf: int | None
    ) -> None:
        loop = asyncio.get_running_loop()
        binds = [addr for kind, addr in parsed if kind == "udpin"]
        remotes = [addr for kind, addr in parsed if kind == "udpout"]
        udp = [*binds] or ([("0.0.0.0", 0)] if remotes else [])
        for k, local in enumerate(udp):
            transport, _ = await loop.create_datagram_endpoint(  # the first socket keeps plain addresses
                lambda k=k: UdpProtocol(self._on_frames, qualified=k > 0), local_addr=local
            )
            self._add_endpoint(transport)
            self._udp = self._udp or transport
            if rcvbuf is not None:
                transport.get_extra_info("socket").setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        for remote in remotes:
            self.add_peer(remote)
        for url, (kind, addr) in zip(urls, parsed, strict=True):
            if kind == "tcp":
                client = await open_tcp(url, addr[0], addr[1], self._on_frames)
                self._add_endpoint(client)
                self._peers[client.key] = (client, client.key)
            elif kind == "serial":
                port = open_serial(*addr, self._on_frames)
                self._add_endpoint(port)
                self._peers[addr] = (port, addr)

    def _bind_clocks(self, loop: asyncio.AbstractEventLoop) -> None:
        """Read the clocks of ``loop`` (the one the transports live on) directly: each received
        datagram reads both, and asking asyncio for the running loop costs a system call (getpid)."""
        self._now_s = loop.time
        self._unix_s = loop.unix_time if isinstance(loop, LockstepLoop) else time.time

    def _add_endpoint(self, transport) -> None:
        self._endpoints.append(transport)
        if self._transport is None:
            self._transport = transport

    def _start_heartbeat(self, period_s: float) -> None:
        if period_s > 0:
            self._heartbeat_task = asyncio.create_task(self._heartbeat_loop(period_s))

    @property
    def local_address(self) -> Address:
        """The first endpoint's own address: the (first) udpin bind or the udpout socket."""
        assert self._transport is not None
        return self._transport.get_extra_info("sockname")[:2]

    @property
    def reconnects(self) -> int:
        """How often a TCP connection to a vehicle was made again after the vehicle closed it."""
        return sum(max(0, getattr(t, "connections", 1) - 1) for t in self._endpoints)

    @property
    def local_addresses(self) -> list[Address]:
        """Every endpoint's own address, in the order opened."""
        return [t.get_extra_info("sockname")[:2] for t in self._endpoints]

    def add_peer(self, url_or_address: str | Address) -> None:
        """Start talking to one more udpout remote (heartbeats included), from the first UDP socket."""
        if isinstance(url_or_address, str):
            kind, addr = parse_url(url_or_address)
            if kind != "udpout":
                raise ValueError(f"add_peer needs a udpout URL, got {url_or_address!r}")
        else:
            addr = url_or_address
        if self._udp is None:
            raise ValueError("add_peer needs a link with a UDP socket (a udpin or udpout URL)")
        key = (_resolve(addr[0]), addr[1])
        self._peers[key] = (self._udp, key)

    # ----------------------------------------------------------------- sending
    def send(self, msg: mavlink.MAVLink_message) -> None:
        """Pack and send now; to the target system's address, or to every peer for broadcasts."""
        self._check_open()
        raw = codec.encode(msg, self._mav) or self.signing.pack(msg)
        self._mav.seq = (self._mav.seq + 1) % 256
        self._route(getattr(msg, "target_system", 0), raw)

    def send_payload(self, target: int, packer: codec.Packer, payload: bytes) -> None:
        """Send the message ``packer`` packed into ``payload`` to system ``target`` (0: broadcast) as
        ``send`` sends it: the next sequence number, signed when there is a key."""
        self._check_open()
        mav = self._mav
        key = self.signing.key
        flags = 0 if key is None else _SIGNED
        raw = codec.frame(
            packer.msgid, packer.crc_extra, payload, mav.seq, mav.srcSystem, mav.srcComponent, flags
        )
        if key is not None:
            raw = self.signing.sign(raw)
        mav.seq = (mav.seq + 1) % 256
        self._route(target, raw)

    def _check_open(self) -> None:
        if self._closed or all(map(_is_closing, self._endpoints)):
            raise ConnectionError("MAVLink link is closed")

    def _route(self, target: int, raw: bytes) -> None:
        """Send one frame to the address system ``target`` was heard from, or to every peer."""
        info = self.vehicles.get(target) if target else None
        if info is None:
            for transport, addr in self._peers.values():
                self._sendto(transport, raw, addr)
        else:
            if len(info.addresses) > 1:  # fast path: one address can never be ambiguous
                live = info.live_addresses(self._now_s())
                if len(live) > 1:
                    raise DuplicateSysidError(target, live)
            transport, addr = self._peers[info.address]
            self._sendto(transport, raw, addr)
        self.frames_sent += 1

    def corked(self) -> _Cork:
        """What is sent inside the block leaves at its end, in one datagram per address (module
        docstring); inside another, the outermost one sends."""
        return _Cork(self)

    def flush(self) -> None:
        """Send what a ``corked()`` block holds so far: a datagram boundary inside it."""
        if self._corked:
            corked, self._corked = self._corked, []
            self._uncork(corked)

    def _sendto(self, transport, raw: bytes, addr: Address) -> None:
        """Send ``raw`` now, or hold it while a datagram's frames are dispatched (module docstring)."""
        if self._corked is None:
            transport.sendto(raw, addr)
        else:
            self._corked.append((transport, addr, raw))

    @staticmethod
    def _uncork(corked: list[tuple[Any, Address, bytes]]) -> None:
        """Send the held frames: to each address in order, as few datagrams as MAX_DATAGRAM_BYTES allows."""
        if len(corked) == 1:
            transport, addr, raw = corked[0]
            transport.sendto(raw, addr)
            return
        by_peer: dict[tuple[Any, Address], list[bytes]] = {}
        for transport, addr, raw in corked:
            by_peer.setdefault((transport, addr), []).append(raw)
        for (transport, addr), frames in by_peer.items():
            start, size = 0, 0
            for k, raw in enumerate(frames):
                if size + len(raw) > MAX_DATAGRAM_BYTES and k > start:
                    transport.sendto(b"".join(frames[start:k]), addr)
                    start, size = k, 0
                size += len(raw)
            transport.sendto(b"".join(frames[start:]), addr)

    def check_target(self, sysid: int) -> None:
        """Raise DuplicateSysidError if ``sysid`` answers from more than one address."""
        info = self.vehicles.get(sysid)
        if info is not None:
            live = info.live_addresses(self._now_s())
            if len(live) > 1:
                raise DuplicateSysidError(sysid, live)

    def duplicates(self) -> dict[int, list[Address]]:
        """System ids currently heard from more than one address."""
        now = self._now_s()
        return {s: v.live_addresses(now) for s, v in self.vehicles.items() if len(v.live_addresses(now)) > 1}

    def set_signing_key(self, key: bytes | None) -> None:
        """Sign and verify with ``key`` from now on (None: neither); e.g. after SETUP_SIGNING."""
        self.signing.set_key(key)

    # ----------------------------------------------------------------- receiving
    def subscribe(self, callback: Callback, sysid: int | None = None) -> Callable[[], None]:
        """Call ``callback(msg, raw, t_s)`` for every received frame, or only for those from system
        ``sysid``; returns the unsubscribe function."""
        if sysid is None:
            self._subscribers = [*self._subscribers, callback]
        else:
            self._by_sysid[sysid] = [*self._by_sysid.get(sysid, ()), callback]

        def unsubscribe() -> None:
            if sysid is None:
                self._subscribers = [c for c in self._subscribers if c is not callback]
                return
            rest = [c for c in self._by_sysid.get(sysid, ()) if c is not callback]
            if rest:
                self._by_sysid[sysid] = rest
            else:
                self._by_sysid.pop(sysid, None)

        return unsubscribe

    def take(
        self, sysid: int, msgids: Collection[int], callback: FrameCallback, owner: Callback
    ) -> Callable[[], None]:
        """Frames of ``msgids`` from system ``sysid`` go to ``callback(frame, t_s)`` undecoded (once
        intact and verified) instead of to the subscriber ``owner`` as messages; the other
        subscribers still get them (module docstring). Returns the function that ends it."""
        keys = [(sysid, msgid) for msgid in msgids]
        for key in keys:
            takers, owners = self._takers.get(key, ((), frozenset()))
            self._takers[key] = ((*takers, callback), owners | {owner})

        def release() -> None:
            for key in keys:
                takers, owners = self._takers.get(key, ((), frozenset()))
                rest = tuple(t for t in takers if t is not callback)
                if rest:
                    self._takers[key] = (rest, owners - {owner})
                else:
                    self._takers.pop(key, None)

        return release

    async def wait_for(
        self, predicate: Callable[[mavlink.MAVLink_message], bool], timeout_s: float
    ) -> mavlink.MAVLink_message:
        """The first message for which ``predicate`` is true; TimeoutError after ``timeout_s``."""
        return await first_message(self.subscribe, predicate, timeout_s)

    def _on_frames(self, found: list[bytes], junk: int, addr: Address, transport, raw_addr: Address) -> None:
        """The frames of one datagram (or stream read) from ``addr`` (endpoint-qualified; answered
        by ``transport.sendto(data, raw_addr)``): each decoded, verified, then delivered."""
        if junk:
            self.frames_dropped += junk
        t_s = self._unix_s()
        now = self._now_s()
        with self.corked():
            for frame in found:
                self._on_frame(frame, addr, transport, raw_addr, t_s, now)

    def _on_frame(
        self, frame: bytes, addr: Address, transport, raw_addr: Address, t_s: float, now: float
    ) -> None:
        """One frame: decoded (taken ones only checked), verified, then delivered."""
        taken = None
        if self._takers and frame[0] == 0xFD:
            taken = self._takers.get((frame[5], frame[7] | frame[8] << 8 | frame[9] << 16))
        msg = None
        if taken is None:
            msg = self._decode(frame, addr)
            if msg is None:
                self.frames_dropped += 1
                return
        elif not codec.intact(frame):
            self.frames_dropped += 1
            return
        signing = self.signing
        accepted = signing.accept(frame)
        verifying = signing.key is not None
        if frame[0] == 0xFD and frame[2] & _SIGNED and not (accepted and verifying):
            self.unverified[frame[5]] = self.unverified.get(frame[5], 0) + 1  # a key we lack
        if not accepted:
            self.frames_dropped += 1
            return
        if addr not in self._peers:  # udpin: answer whoever talks to us (once a frame verified)
            self._peers[addr] = (transport, raw_addr)
        sysid = frame[5] if msg is None else msg.get_srcSystem()
        self._note_source(msg, sysid, addr, now)
        self.frames_received += 1
        # the vehicle's own subscribers (transfers) first: their replies leave before logging
        own = self._by_sysid.get(sysid)  # lists are replaced, never changed: safe to iterate
        callbacks = own + self._subscribers if own else self._subscribers
        if taken is not None:
            takers, owners = taken
            for taker in takers:
                _call(taker, frame, t_s)
            callbacks = [c for c in callbacks if c not in owners]
            msg = self._decode(frame, addr) if callbacks else None  # intact: it decodes
            if msg is None:
                return
        msg._signed = verifying  # verified above
        attach_extensions(msg, frame)
        for callback in callbacks:
            _call(callback, msg, frame, t_s)

    def _decode(self, frame: bytes, addr: Address) -> mavlink.MAVLink_message | None:
        """The message of one whole frame; None when its CRC, length or flags are bad."""
        if frame[0] == 0xFD and frame[2] & ~mavlink.MAVLINK_IFLAG_SIGNED:
            return None  # an incompatibility flag we do not know: the spec says drop
        try:
            msg = codec.decode(frame) or self._decoder.decode(bytearray(frame))
        except mavlink.MAVError as exc:
            log.debug("bad frame from %s: %s", addr, exc)
            return None
        if msg.__class__ is _UNKNOWN:  # pymavlink leaves its header empty (system 0)
            msg._header = _frame_header(frame)
        return msg

    def _note_source(
        self, msg: mavlink.MAVLink_message | None, sysid: int, addr: Address, now: float
    ) -> None:
        """A verified frame from ``sysid`` at ``addr`` (``msg`` None: a taken frame, no HEARTBEAT)."""
        heartbeat = msg is not None and is_autopilot_heartbeat(msg)
        info = self.vehicles.get(sysid)
        if info is None:
            if not heartbeat:
                return  # a vehicle exists once its autopilot was heard
            info = self.vehicles[sysid] = VehicleInfo(sysid, addr)
        elif addr != info.address or len(info.addresses) > 1:
            live = info.live_addresses(now)
            if not live:  # the old address went quiet: the vehicle moved (e.g. rebooted)
                info.address, info.addresses = addr, {}
            elif addr not in live and addr not in info.addresses:
                log.warning("system id %d heard from %s and %s: ambiguous", sysid, info.address, addr)
        info.addresses[addr] = now
        if addr == info.address and heartbeat:
            compid = msg.get_srcComponent()
            if compid != info.compid:
                if info.compid is not None and (info.compid == _AUTOPILOT1 or compid != _AUTOPILOT1):
                    return  # another component's HEARTBEAT (a camera, a second autopilot-like one)
                info.compid = compid  # the first autopilot heard, or MAV_COMP_ID_AUTOPILOT1 over it
            info.autopilot, info.mav_type = msg.autopilot, msg.type
            info.custom_mode, info.base_mode = msg.custom_mode, msg.base_mode

    # ----------------------------------------------------------------- lifecycle
    async def _heartbeat_loop(self, period_s: float) -> None:
        beat = mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
        )
        while True:
            with contextlib.suppress(ConnectionError):
                self.send(beat)
            await asyncio.sleep(period_s)

    async def close(self) -> None:
        """Stop heartbeats and close the socket (idempotent)."""
        if self._heartbeat_task is not None:
            self._heartbeat_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._heartbeat_task
            self._heartbeat_task = None
        self._closed = True
        self._close_endpoints()

    def _close_endpoints(self) -> None:
        for transport in self._endpoints:
            transport.close()

    async def __aenter__(self) -> MavlinkLink:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


def signing_problem(link: MavlinkLink, sysid: int) -> str:
    """'' unless the vehicle signs its frames with a key this link does not have: then why, in
    words (it drops every unsigned or wrongly signed frame this link sends)."""
    if sysid not in getattr(link, "unverified", {}):  # (a link per network keeps no such count)
        return ""
    which = "give --signing-passphrase"
    if link.signing.key:
        which = "the --signing-passphrase given is not its key"
    return f"sysid {sysid} signs its frames (MAVLink 2 signing) with a key this link lacks: {which}"


def check_signing(link: MavlinkLink, sysids) -> None:
    """UserError naming each vehicle of ``sysids`` that signs with a key this link lacks."""
    problems = [p for p in (signing_problem(link, s) for s in sysids) if p]
    if problems:
        raise UserError("; ".join(problems))


async def first_message(
    subscribe: Callable[[Callback], Callable[[], None]],
    predicate: Callable[[mavlink.MAVLink_message], bool],
    timeout_s: float,
) -> mavlink.MAVLink_message:
    """The first message a ``subscribe(callback)`` delivers for which ``predicate`` is true;
    TimeoutError after ``timeout_s``."""
    future: asyncio.Future = asyncio.get_running_loop().create_future()

    def on_frame(msg: mavlink.MAVLink_message, raw: bytes, t_s: float) -> None:
        if not future.done() and predicate(msg):
            future.set_result(msg)

    unsubscribe = subscribe(on_frame)
    try:
        return await asyncio.wait_for(future, timeout_s)
    finally:
        unsubscribe()


class _Cork:
    """MavlinkLink.corked's block (a class, not a generator: it is entered for every datagram)."""

    __slots__ = ("link", "outer")

    def __init__(self, link: MavlinkLink) -> None:
        self.link = link

    def __enter__(self) -> None:
        self.outer = self.link._corked is None
        if self.outer:
            self.link._corked = []

    def __exit__(self, *exc: object) -> None:
        if self.outer:
            corked, self.link._corked = self.link._corked, None
            if corked:
                self.link._uncork(corked)


def _call(callback: Callable, *args: object) -> None:
    """A subscriber's callback: what it raises is logged, never raised into the link."""
    try:
        callback(*args)
    except UserError as exc:  # said once more, in one line, by the operation it ends
        log.debug("MAVLink subscriber %r: %s", callback, exc)
    except Exception:
        log.exception("MAVLink subscriber %r failed", callback)


def _frame_header(frame: bytes) -> mavlink.MAVLink_header:
    """The header of a whole MAVLink 2 (0xFD) or 1 (0xFE) frame: ids, sequence, length, flags."""
    if frame[0] == 0xFD:  # magic, len, incompat, compat, seq, sysid, compid, msgid (3 bytes)
        msgid = frame[7] | frame[8] << 8 | frame[9] << 16
        return mavlink.MAVLink_header(msgid, frame[2], frame[3], frame[1], frame[4], frame[5], frame[6])
    return mavlink.MAVLink_header(frame[5], 0, 0, frame[1], frame[2], frame[3], frame[4])  # v1


def _resolve(host: str) -> str:
    """UDP sendto needs an address the socket family understands; 'localhost' -> 127.0.0.1."""
    return "127.0.0.1" if host in ("localhost", "0.0.0.0", "") else host
