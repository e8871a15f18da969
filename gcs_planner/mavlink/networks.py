"""Fleets past one MAVLink network: one link per network, vehicles named by a fleet id.

A MAVLink system id is a byte, so one network holds at most 254 vehicles beside the GCS. A larger
fleet is split over several networks (a radio, a port, a mock process each), where system ids
repeat. Above the links every vehicle is named by its fleet id, ``network x 256 + sysid``: on
network 0 it is the system id itself, so a one-network fleet is unchanged. ``NetworkLinks`` opens
one MavlinkLink per network and offers the MavlinkLink methods a flight uses (``send``,
``subscribe``, ``wait_for``, ``vehicles``, ``check_target``, ``duplicates``, ``close``, and an
upload's ``take``, ``send_payload``, ``corked``) in fleet ids: a received message's source system
is rewritten to its fleet id before any subscriber sees it, and a sent message's
``target_system`` goes out as the system id on its own network (broadcasts to every network). A
taken frame and a packed payload are bytes as on the wire: their system ids are the network's
(mission.py packs the payload with ``wire_sysid``).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.fleet_ids import fleet_id, network_of, wire_sysid
from gcs_planner.mavlink.link import Address, Callback, FrameCallback, MavlinkLink, VehicleInfo, first_message
from gcs_planner.wire.codec import Packer

__all__ = ["NetworkLinks", "open_networks"]


async def open_networks(networks: Sequence[Sequence[str]], **options) -> MavlinkLink | NetworkLinks:
    """A MavlinkLink to one network's URLs, or NetworkLinks over several (``options``: MavlinkLink.open's)."""
    if len(networks) == 1:
        return await MavlinkLink.open(*networks[0], **options)
    links = []
    try:
        for urls in networks:
            links.append(await MavlinkLink.open(*urls, **options))
    except BaseException:
        await asyncio.gather(*(link.close() for link in links))
        raise
    return NetworkLinks(links)


class _FleetVehicles(Mapping[int, VehicleInfo]):
    """Every network's vehicle table, keyed by fleet id (a live view)."""

    def __init__(self, links: list[MavlinkLink]) -> None:
        self.links = links

    def __getitem__(self, vehicle: int) -> VehicleInfo:
        n = network_of(vehicle)
        if not 0 <= n < len(self.links):
            raise KeyError(vehicle)
        return self.links[n].vehicles[wire_sysid(vehicle)]

    def __iter__(self) -> Iterator[int]:
        for n, link in enumerate(self.links):
            yield from (fleet_id(n, s) for s in link.vehicles)

    def __len__(self) -> int:
        return sum(len(link.vehicles) for link in self.links)


class NetworkLinks:
    """One MavlinkLink per network, spoken to in fleet ids (module docstring)."""

    def __init__(self, links: list[MavlinkLink]) -> None:
        self.links = links
        self.vehicles = _FleetVehicles(links)
        self.sysid, self.compid = links[0].sysid, links[0].compid
        self._renamed: dict[Callback, Callback] = {}  # a vehicle's subscriber -> what its link calls

    @property
    def frames_received(self) -> int:
        return sum(link.frames_received for link in self.links)

    @property
    def frames_sent(self) -> int:
        return sum(link.frames_sent for link in self.links)

    @property
    def frames_dropped(self) -> int:
        return sum(link.frames_dropped for link in self.links)

    def send(self, msg: mavlink.MAVLink_message) -> None:
        """To the target's network as its own system id; a broadcast (target 0) to every network."""
        target = getattr(msg, "target_system", 0)
        if not target:
            for link in self.links:
                link.send(msg)
            return
        link = self._link(target)
        msg.target_system = wire_sysid(target)
        try:
            link.send(msg)
        finally:
            msg.target_system = target

    def subscribe(self, callback: Callback, sysid: int | None = None) -> Callable[[], None]:
        """MavlinkLink.subscribe in fleet ids."""
        if sysid is not None:
            renamed = self._renamed[callback] = _renamed(callback, network_of(sysid))
            stop = self._link(sysid).subscribe(renamed, wire_sysid(sysid))

            def unsubscribe_vehicle() -> None:
                self._renamed.pop(callback, None)
                stop()

            return unsubscribe_vehicle
        stops = [link.subscribe(_renamed(callback, n)) for n, link in enumerate(self.links)]

        def unsubscribe() -> None:
            for stop in stops:
                stop()

        return unsubscribe

    def take(
        self, sysid: int, msgids: Collection[int], callback: FrameCallback, owner: Callback
    ) -> Callable[[], None]:
        """MavlinkLink.take for fleet id ``sysid`` (``owner`` subscribed to it here)."""
        owner = self._renamed.get(owner, owner)
        return self._link(sysid).take(wire_sysid(sysid), msgids, callback, owner)

    def send_payload(self, target: int, packer: Packer, payload: bytes) -> None:
        """MavlinkLink.send_payload to fleet id ``target`` (the payload names its wire id); 0: all."""
        if not target:
            for link in self.links:
                link.send_payload(0, packer, payload)
            return
        self._link(target).send_payload(wire_sysid(target), packer, payload)

    @contextlib.contextmanager
    def corked(self) -> Iterator[None]:
        """MavlinkLink.corked on every network."""
        with contextlib.ExitStack() as stack:
            for link in self.links:
                stack.enter_context(link.corked())
            yield

    def flush(self) -> None:
        """MavlinkLink.flush on every network."""
        for link in self.links:
            link.flush()

    async def wait_for(self, predicate: Callable[[mavlink.MAVLink_message], bool], timeout_s: float):
        """The first message (in fleet ids) for which ``predicate`` is true; TimeoutError after timeout_s."""
        return await first_message(self.subscribe, predicate, timeout_s)

    def check_target(self, sysid: int) -> None:
        self._link(sysid).check_target(wire_sysid(sysid))

    def duplicates(self) -> dict[int, list[Address]]:
        return {fleet_id(n, s): a for n, link in enumerate(self.links) for s, a in link.duplicates().items()}

    async def close(self) -> None:
        await asyncio.gather(*(link.close() for link in self.links))

    def _link(self, vehicle: int) -> MavlinkLink:
        n = network_of(vehicle)
        if not 0 <= n < len(self.links):
            raise ValueError(f"fleet id {vehicle} is on network {n}; this flight has {len(self.links)}")
        return self.links[n]


def _renamed(callback: Callback, network: int) -> Callback:
    """``callback`` with each message's source system rewritten to its fleet id on ``network``."""
    if network == 0:
        return callback
    offset = fleet_id(network, 0)

    def renamed(msg, raw: bytes, t_s: float) -> None:
        header = msg._header
        if header.srcSystem < offset:  # one frame reaches several subscribers: rename it once
            header.srcSystem += offset
        callback(msg, raw, t_s)

    return renamed
