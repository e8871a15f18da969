"""An asyncio MAVLink 2 link over UDP: one socket, many vehicles, routed by system id.

``await MavlinkLink.open("udpout:127.0.0.1:14550")`` talks to a vehicle that listens (ArduPilot SITL
``udpin``, our sitl-mock); several ``udpout`` URLs share one socket, so one link reaches a whole mock
fleet (one port per vehicle); ``udpout:HOST:FIRST-LAST`` names one remote per port of a range.
``udpin:0.0.0.0:14550`` listens and answers every peer heard from.
``serial:/dev/ttyUSB0:57600`` (baud optional, default 57600) opens a telemetry radio or an
autopilot's USB port instead (serial_port.py); everything above the transport is the same.

Choices:
- Each UDP datagram is framed on its own (framing.py): no bytes are carried from one datagram to
  the next, so a malformed datagram costs only itself. A serial port is a byte stream and keeps its
  incomplete tail. Frames are decoded without pymavlink's byte-wise parser: unsigned frames of plain
  numeric messages by codec.py (about two thirds of pymavlink's time), the rest by one keyless
  pymavlink decoder. Frames carry a sequence number that advances per frame sent.
- Frames are dispatched synchronously in ``datagram_received``: a transfer's reply goes out in the
  same callback that received the request (no task hop, no sleep) - the hot path of an upload.
- Routing: a message with ``target_system`` goes to the address that system was last heard from;
  broadcasts (target 0, HEARTBEAT) go to every peer. A system id heard from two addresses within
  DUPLICATE_WINDOW_S is ambiguous: ``vehicles`` reports it and sending to it raises
  DuplicateSysidError (QGC merges such vehicles silently, #14812; we refuse).
- ``subscribe(callback, sysid=N)`` delivers only that vehicle's frames: a fleet upload's transfers
  each see their own vehicle, so dispatch stays O(frames), not O(frames x transfers).
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
from collections.abc import Callable
from dataclasses import dataclass, field

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.mavlink import codec  # noqa: E402
from gcs_planner.mavlink.errors import DuplicateSysidError  # noqa: E402
from gcs_planner.mavlink.framing import StreamFramer, frames  # noqa: E402
from gcs_planner.mavlink.serial_port import DEFAULT_BAUD, SerialPort  # noqa: E402
from gcs_planner.mavlink.signing import LinkSigning  # noqa: E402
from gcs_planner.mavlink.wire import attach_extensions  # noqa: E402

__all__ = [
    "DUPLICATE_WINDOW_S", "FLEET_RCVBUF_BYTES", "GCS_COMPID", "GCS_SYSID", "MavlinkLink", "VehicleInfo",
    "expand_ranges", "first_message", "parse_url",
]  # fmt: skip

log = logging.getLogger(__name__)

GCS_SYSID = 255
GCS_COMPID = mavlink.MAV_COMP_ID_MISSIONPLANNER  # 190
DUPLICATE_WINDOW_S = 5.0  # two addresses heard within this time with one sysid = duplicate [s]
FLEET_RCVBUF_BYTES = 4 << 20  # a fleet link's socket receive buffer (Linux caps it at net.core.rmem_max)
HEARTBEAT_PERIOD_S = 1.0
_NOT_AUTOPILOT = mavlink.MAV_AUTOPILOT_INVALID  # HEARTBEAT of a camera, gimbal, companion or GCS

Address = tuple[str, int]
Callback = Callable[[mavlink.MAVLink_message, bytes, float], None]


@dataclass
class VehicleInfo:
    """What the link knows about one system id (from any of its messages; the type fields from the
    autopilot's HEARTBEAT: ``autopilot`` is None until the flight controller itself was heard)."""

    sysid: int
    address: Address
    addresses: dict[Address, float] = field(default_factory=dict)  # address -> last heard [monotonic s]
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
        return len(self.live_addresses(time.monotonic())) > 1


def parse_url(url: str) -> tuple[str, Address]:
    """'udpout:host:port' / 'udpin:host:port' (also 'udp:' = udpin) -> (kind, (host, port));
    'serial:PATH[:BAUD]' -> ('serial', (PATH, BAUD))."""
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
        raise ValueError(f"connection URL {url!r}: expected udpin:HOST:PORT or udpout:HOST:PORT") from None
    kind = {"udp": "udpin"}.get(kind, kind)
    if kind not in ("udpin", "udpout"):
        raise ValueError(f"connection URL {url!r}: scheme {kind!r} not supported (udpin, udpout, serial)")
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


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, link: MavlinkLink) -> None:
        self.link = link

    def datagram_received(self, data: bytes, addr: Address) -> None:
        self.link._on_datagram(data, addr[:2])

    def error_received(self, exc: Exception) -> None:
        log.debug("UDP error: %s", exc)  # ICMP port unreachable while a vehicle is down


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
        self._stream: StreamFramer | None = None  # serial: bytes of a frame split across reads
        self._peers: dict[Address, None] = {}  # ordered set of addresses we send broadcasts to
        self._subscribers: list[Callback] = []  # every frame
        self._by_sysid: dict[int, list[Callback]] = {}  # one vehicle's frames
        self.vehicles: dict[int, VehicleInfo] = {}
        self._transport: asyncio.DatagramTransport | SerialPort | None = None
        self._heartbeat_task: asyncio.Task | None = None
        self.frames_received = 0
        self.frames_sent = 0
        self.frames_dropped = 0  # undecodable, bad CRC, or (signing) unsigned / badly signed

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
        """Bind one UDP socket: at most one udpin URL (the bind address), any number of udpout remotes;
        or open one serial port (a serial URL stands alone). ``signing_key``: sign and verify.
        ``receive_buffer_bytes``: the UDP socket's SO_RCVBUF, for bursts from large fleets (the
        kernel may cap it at net.core.rmem_max)."""
        parsed = [parse_url(u) for u in expand_ranges((url, *more_urls))]
        link = cls(sysid, compid, signing_key)
        if any(kind == "serial" for kind, _ in parsed):
            if len(parsed) > 1:
                raise ValueError("a serial URL cannot share a link with other URLs")
            link._stream = StreamFramer()
            link._transport = SerialPort.open(*parsed[0][1], link._on_datagram)
            link._peers[parsed[0][1]] = None
            link._start_heartbeat(heartbeat_period_s)
            return link
        binds = [addr for kind, addr in parsed if kind == "udpin"]
        if len(binds) > 1:
            raise ValueError(f"only one udpin URL per link, got {len(binds)}")
        remotes = [addr for kind, addr in parsed if kind == "udpout"]
        local = binds[0] if binds else ("0.0.0.0", 0)
        loop = asyncio.get_running_loop()
        link._transport, _ = await loop.create_datagram_endpoint(lambda: _Protocol(link), local_addr=local)
        if receive_buffer_bytes is not None:
            sock = link._transport.get_extra_info("socket")
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer_bytes)
        for remote in remotes:
            link._peers[(_resolve(remote[0]), remote[1])] = None
        link._start_heartbeat(heartbeat_period_s)
        return link

    def _start_heartbeat(self, period_s: float) -> None:
        if period_s > 0:
            self._heartbeat_task = asyncio.create_task(self._heartbeat_loop(period_s))

    @property
    def local_address(self) -> Address:
        assert self._transport is not None
        return self._transport.get_extra_info("sockname")[:2]

    def add_peer(self, url_or_address: str | Address) -> None:
        """Start talking to one more udpout remote (heartbeats included)."""
        if isinstance(url_or_address, str):
            kind, addr = parse_url(url_or_address)
            if kind != "udpout":
                raise ValueError(f"add_peer needs a udpout URL, got {url_or_address!r}")
        else:
            addr = url_or_address
        self._peers[(_resolve(addr[0]), addr[1])] = None

    # ----------------------------------------------------------------- sending
    def send(self, msg: mavlink.MAVLink_message) -> None:
        """Pack and send now; to the target system's address, or to every peer for broadcasts."""
        if self._transport is None or self._transport.is_closing():
            raise ConnectionError("MAVLink link is closed")
        target = getattr(msg, "target_system", 0)
        raw = codec.encode(msg, self._mav) or self.signing.pack(msg)
        self._mav.seq = (self._mav.seq + 1) % 256
        info = self.vehicles.get(target) if target else None
        if info is None:
            for addr in self._peers:
                self._transport.sendto(raw, addr)
        else:
            if len(info.addresses) > 1:  # fast path: one address can never be ambiguous
                live = info.live_addresses(time.monotonic())
                if len(live) > 1:
                    raise DuplicateSysidError(target, live)
            self._transport.sendto(raw, info.address)
        self.frames_sent += 1

    def check_target(self, sysid: int) -> None:
        """Raise DuplicateSysidError if ``sysid`` answers from more than one address."""
        info = self.vehicles.get(sysid)
        if info is not None:
            live = info.live_addresses(time.monotonic())
            if len(live) > 1:
                raise DuplicateSysidError(sysid, live)

    def duplicates(self) -> dict[int, list[Address]]:
        """System ids currently heard from more than one address."""
        now = time.monotonic()
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

    async def wait_for(
        self, predicate: Callable[[mavlink.MAVLink_message], bool], timeout_s: float
    ) -> mavlink.MAVLink_message:
        """The first message for which ``predicate`` is true; TimeoutError after ``timeout_s``."""
        return await first_message(self.subscribe, predicate, timeout_s)

    def _on_datagram(self, data: bytes, addr: Address) -> None:
        """One datagram (or serial read): its frames, each decoded, verified, then delivered."""
        found, junk = frames(data) if self._stream is None else self._stream.feed(data)
        self.frames_dropped += junk
        t_s = time.time()
        now = time.monotonic()
        for frame in found:
            msg = self._decode(frame, addr)
            if msg is None or not self.signing.accept(frame):
                self.frames_dropped += 1
                continue
            raw = frame
            msg._signed = self.signing.key is not None  # verified above
            if addr not in self._peers:
                self._peers[addr] = None  # udpin: answer whoever talks to us (once a frame verified)
            self._note_source(msg, addr, now)
            attach_extensions(msg, raw)
            self.frames_received += 1
            # the vehicle's own subscribers (transfers) first: their replies leave before logging
            for callback in (*self._by_sysid.get(msg.get_srcSystem(), ()), *self._subscribers):
                try:
                    callback(msg, raw, t_s)
                except Exception:
                    log.exception("MAVLink subscriber %r failed", callback)

    def _decode(self, frame: bytes, addr: Address) -> mavlink.MAVLink_message | None:
        """The message of one whole frame; None when its CRC, length or flags are bad."""
        if frame[0] == 0xFD and frame[2] & ~mavlink.MAVLINK_IFLAG_SIGNED:
            return None  # an incompatibility flag we do not know: the spec says drop
        try:
            return codec.decode(frame) or self._decoder.decode(bytearray(frame))
        except mavlink.MAVError as exc:
            log.debug("bad frame from %s: %s", addr, exc)
            return None

    def _note_source(self, msg: mavlink.MAVLink_message, addr: Address, now: float) -> None:
        sysid = msg.get_srcSystem()
        info = self.vehicles.get(sysid)
        if info is None:
            info = self.vehicles[sysid] = VehicleInfo(sysid, addr)
        elif addr != info.address or len(info.addresses) > 1:
            live = info.live_addresses(now)
            if not live:  # the old address went quiet: the vehicle moved (e.g. rebooted)
                info.address, info.addresses = addr, {}
            elif addr not in live and addr not in info.addresses:
                log.warning("system id %d heard from %s and %s: ambiguous", sysid, info.address, addr)
        info.addresses[addr] = now
        if msg.get_type() == "HEARTBEAT" and addr == info.address and msg.autopilot != _NOT_AUTOPILOT:
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
        if self._transport is not None:
            self._transport.close()

    async def __aenter__(self) -> MavlinkLink:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


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


def _resolve(host: str) -> str:
    """UDP sendto needs an address the socket family understands; 'localhost' -> 127.0.0.1."""
    return "127.0.0.1" if host in ("localhost", "0.0.0.0", "") else host
