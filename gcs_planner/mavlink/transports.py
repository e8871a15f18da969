"""The transports under one MavlinkLink: UDP sockets, TCP client connections, serial ports.

Each endpoint hands the link whole frames with the address they came from and the way back:
``on_frames(found, junk, key, sender, raw_address)``. ``key`` is the endpoint-qualified address
the link routes by (peer table, vehicle table, duplicate check); ``sender.sendto(data, raw_address)``
answers it on the endpoint it was heard on. Keys of different endpoints never collide:

- the link's first UDP socket (the first ``udpin`` bind, else an ephemeral socket for the ``udpout``
  remotes): ``(host, port)`` as the kernel reports it, exactly as a one-socket link always did;
- every further ``udpin`` socket: ``("udpin:LOCALPORT<-HOST", port)``, printed as
  ``udpin:14551<-127.0.0.1:40000`` (what was heard on local port 14551 from 127.0.0.1:40000);
- a TCP connection: ``("tcp:HOST", PORT)`` as its URL names it, printed ``tcp:127.0.0.1:5760``;
- a serial port: ``(PATH, BAUD)`` (serial_port.py).

UDP datagrams are framed one by one (framing.frames); TCP and serial are byte streams with one
StreamFramer each, so a frame split across reads is kept for the next.
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Callable

from gcs_planner.mavlink.serial_port import SerialPort
from gcs_planner.wire.framing import StreamFramer, frames

__all__ = ["TcpClient", "UdpProtocol", "open_serial", "open_tcp"]

log = logging.getLogger(__name__)

TCP_CONNECT_TIMEOUT_S = 10.0
TCP_RECONNECT_S = 1.0  # retry period after a vehicle closed its TCP connection

Address = tuple[str, int]
OnFrames = Callable[[list[bytes], int, Address, object, Address], None]


class UdpProtocol(asyncio.DatagramProtocol):
    """One UDP socket of a link. Not ``qualified``: keys are the plain source address (the link's
    first socket); else ``(f"udpin:{local port}<-{host}", port)``."""

    def __init__(self, on_frames: OnFrames, qualified: bool = False) -> None:
        self.on_frames = on_frames
        self.qualified = qualified
        self.tag: str | None = None
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        if self.qualified:  # the bound port (an ephemeral one is known only now)
            self.tag = f"udpin:{transport.get_extra_info('sockname')[1]}"

    def datagram_received(self, data: bytes, addr: Address) -> None:
        addr = addr[:2]
        found, junk = frames(data)
        key = addr if self.tag is None else (f"{self.tag}<-{addr[0]}", addr[1])
        self.on_frames(found, junk, key, self.transport, addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("UDP error: %s", exc)  # ICMP port unreachable while a vehicle is down


class TcpClient(asyncio.Protocol):
    """A TCP connection to a vehicle that listens (ArduPilot SITL's ``tcp:5760``): a byte stream,
    framed by a StreamFramer; ``sendto`` writes whatever the address (one peer). When the vehicle
    closes the connection (SITL restarted, a reboot) it is retried every TCP_RECONNECT_S until the
    link closes; meanwhile frames to it are dropped, as UDP drops them to a vehicle that is down."""

    def __init__(self, url: str, host: str, port: int, on_frames: OnFrames) -> None:
        self.url = url
        self.host, self.port = host, port
        self.key = (f"tcp:{host}", port)
        self.on_frames = on_frames
        self.framer = StreamFramer()
        self.transport: asyncio.Transport | None = None
        self.closed = False  # closed by the link
        self.connections = 0  # 1 once connected, more after each reconnect
        self._retry: asyncio.Task | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        self.framer = StreamFramer()
        self.connections += 1

    def data_received(self, data: bytes) -> None:
        found, junk = self.framer.feed(data)
        self.on_frames(found, junk, self.key, self, self.key)

    def connection_lost(self, exc: Exception | None) -> None:
        self.transport = None
        if not self.closed:  # the vehicle's end
            log.warning(
                "%s: connection closed by the vehicle%s; reconnecting", self.url, f" ({exc})" if exc else ""
            )
            self._retry = asyncio.get_running_loop().create_task(self._reconnect())

    async def _reconnect(self) -> None:
        loop = asyncio.get_running_loop()
        while not self.closed:
            await asyncio.sleep(TCP_RECONNECT_S)
            try:
                await loop.create_connection(lambda: self, self.host, self.port)
            except OSError:
                continue
            log.info("%s: reconnected", self.url)
            return

    # the DatagramTransport subset the link uses
    def sendto(self, data: bytes, addr: object = None) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)

    def is_closing(self) -> bool:
        return self.closed

    def get_extra_info(self, name: str, default: object = None) -> object:
        return default if self.transport is None else self.transport.get_extra_info(name, default)

    def close(self) -> None:
        self.closed = True
        if self._retry is not None:
            self._retry.cancel()
        if self.transport is not None:
            self.transport.close()


async def open_tcp(url: str, host: str, port: int, on_frames: OnFrames) -> TcpClient:
    """Connect to ``host:port``; ConnectionError naming ``url`` in one line when that fails."""
    loop = asyncio.get_running_loop()
    try:
        _, client = await asyncio.wait_for(
            loop.create_connection(lambda: TcpClient(url, host, port, on_frames), host, port),
            TCP_CONNECT_TIMEOUT_S,
        )
    except TimeoutError:
        raise ConnectionError(
            f"connection URL {url!r}: no answer within {TCP_CONNECT_TIMEOUT_S:g} s"
        ) from None
    except OSError as exc:
        reason = os.strerror(exc.errno) if exc.errno else str(exc) or type(exc).__name__
        raise ConnectionError(f"connection URL {url!r}: cannot connect ({reason})") from None
    return client


def open_serial(path: str, baud: int, on_frames: OnFrames) -> SerialPort:
    """Open a serial port whose reads are framed as a byte stream (key ``(path, baud)``)."""
    framer = StreamFramer()
    port: list[SerialPort] = []

    def on_bytes(chunk: bytes, address: Address) -> None:
        found, junk = framer.feed(chunk)
        on_frames(found, junk, address, port[0], address)

    port.append(SerialPort.open(path, baud, on_bytes))
    return port[0]
