"""The Rerun viewer from the command line: a live recording (spawned viewer and / or web viewer on
free ports) and the display check that keeps a spawned viewer from hanging a headless machine."""

from __future__ import annotations

import contextlib
import os
import socket
import sys
from urllib.parse import quote

from gcs_planner.core.errors import UserError

__all__ = ["check_display", "free_ports", "live_recording"]


def check_display(flag: str) -> None:
    """UserError on Linux when neither DISPLAY nor WAYLAND_DISPLAY is set: a viewer spawned there
    never shows and the command hangs waiting for it."""
    if not sys.platform.startswith("linux") or os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return
    raise UserError(
        f"{flag} needs a display and neither DISPLAY nor WAYLAND_DISPLAY is set: write the views with"
        " --rrd FILE, then `rerun FILE` where there is a display or `rerun --serve-web FILE` for a browser"
    )


def free_ports(count: int) -> list[int]:
    """``count`` distinct TCP ports free now on every interface (the OS's choice: bind port 0).

    The sockets are held until all are chosen, so the ports differ, then closed for the servers to
    bind; another process could take one in between (then the start fails in one line). Rerun's
    servers take port 0 too, but then name port 0 in the URL they return, so we choose.
    """
    with contextlib.ExitStack() as stack:
        ports = []
        for _ in range(count):
            sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            sock.bind(("", 0))
            ports.append(sock.getsockname()[1])
    return ports


def live_recording(spawn: bool, serve_web: bool, name: str = "live"):
    """A Rerun recording streaming to a spawned viewer and/or the web viewer, or None.

    ``--serve-web`` serves the gRPC stream and the web viewer on free ports (free_ports) and prints
    the viewer's URL. The recording id is ``name`` plus a uuid4 (rerun_views.recording_id)."""
    if not (spawn or serve_web):
        return None
    import rerun as rr

    from gcs_planner.telemetry.rerun_views import APPLICATION_ID, flight_blueprint, recording_id

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id(name))
    try:
        if spawn:
            rec.spawn(default_blueprint=flight_blueprint())
        if serve_web:
            grpc_port, web_port = free_ports(2)
            uri = rec.serve_grpc(grpc_port=grpc_port, default_blueprint=flight_blueprint())
            rr.serve_web_viewer(web_port=web_port, connect_to=uri, open_browser=False)
            url = f"http://localhost:{web_port}/?url={quote(uri, safe='')}"
            print(f"live view: {url}  (Rerun web viewer)")
    except Exception as exc:  # noqa: BLE001 - rerun raises RuntimeError / OSError variants
        raise UserError(f"cannot start the live Rerun view ({exc}); fly without --live/--serve-web") from None
    return rec
