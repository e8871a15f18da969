"""A serial port (telemetry radio, USB autopilot) as a datagram-style transport for MavlinkLink.

Field links are serial: a SiK radio or an autopilot's USB port at 57600 / 115200 baud. The link
code is written against asyncio's DatagramTransport (``sendto``, ``is_closing``, ``close``,
``get_extra_info``); this class offers the same four calls over a POSIX tty, so routing, parsing
and every client above stay one code path.

Choices:
- Standard library only (``termios`` / ``tty``, ``loop.add_reader``): raw mode, 8N1, no flow
  control, the requested speed. POSIX only (Linux, macOS); pyserial would add Windows but not
  behaviour, so it is not a dependency.
- Bytes arrive in arbitrary chunks, not frames: each chunk goes to the link as one "datagram"
  from the port's address ``(path, baud)``, where the per-address parser reassembles frames.
- Writes never block the event loop: what the driver does not take at once is queued and written
  when the fd is writable, in order. At 57600 baud (about 5.7 kB/s) a 1000-item upload is bound
  by the radio, not by us.
"""

from __future__ import annotations

import asyncio
import os
import termios
import tty
from collections.abc import Callable

__all__ = ["DEFAULT_BAUD", "SerialPort"]

DEFAULT_BAUD = 57600  # SiK radio default
READ_CHUNK = 4096


def _speed(baud: int) -> int:
    speed = getattr(termios, f"B{baud}", None)
    if speed is None:
        raise ValueError(f"serial baud rate {baud}: not supported by this system's termios")
    return speed


class SerialPort:
    """An open tty feeding ``on_bytes(chunk, address)``; create with :meth:`open`."""

    def __init__(self, fd: int, address: tuple[str, int], loop: asyncio.AbstractEventLoop) -> None:
        self._fd = fd
        self._address = address
        self._loop = loop
        self._pending = bytearray()
        self._closing = False

    @classmethod
    def open(cls, path: str, baud: int, on_bytes: Callable[[bytes, tuple[str, int]], None]) -> SerialPort:
        """Open ``path`` raw at ``baud``; OSError (named by path) if the device cannot be opened."""
        speed = _speed(baud)
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as exc:
            raise OSError(exc.errno, f"serial port {path}: {exc.strerror}") from None
        try:
            tty.setraw(fd)
            attrs = termios.tcgetattr(fd)
            attrs[2] = (attrs[2] & ~termios.CRTSCTS) | termios.CLOCAL | termios.CREAD  # no flow control
            attrs[4] = attrs[5] = speed  # ispeed, ospeed
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
        except termios.error as exc:
            os.close(fd)
            raise OSError(f"serial port {path}: not a terminal device ({exc})") from None
        port = cls(fd, (path, baud), asyncio.get_running_loop())
        port._loop.add_reader(fd, port._read, on_bytes)
        return port

    def _read(self, on_bytes: Callable[[bytes, tuple[str, int]], None]) -> None:
        try:
            chunk = os.read(self._fd, READ_CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # device unplugged, pty peer closed
            self.close()
            return
        if chunk:
            on_bytes(chunk, self._address)

    # ----------------------------------------------------------------- the DatagramTransport subset
    def sendto(self, data: bytes, addr: object = None) -> None:
        """Write ``data`` (``addr`` is ignored: a serial line has one peer)."""
        if self._closing:
            return
        if self._pending:
            self._pending += data
            return
        try:
            written = os.write(self._fd, data)
        except (BlockingIOError, InterruptedError):
            written = 0
        if written < len(data):
            self._pending += data[written:]
            self._loop.add_writer(self._fd, self._flush)

    def _flush(self) -> None:
        try:
            written = os.write(self._fd, self._pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self.close()
            return
        del self._pending[:written]
        if not self._pending:
            self._loop.remove_writer(self._fd)

    def is_closing(self) -> bool:
        return self._closing

    def get_extra_info(self, name: str, default: object = None) -> object:
        return self._address if name == "sockname" else default

    def close(self) -> None:
        if self._closing:
            return
        self._closing = True
        self._loop.remove_reader(self._fd)
        self._loop.remove_writer(self._fd)
        os.close(self._fd)
