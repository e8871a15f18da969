"""Upload missions to many vehicles at once: bounded worker pool, per-vehicle results, retries.

Choices:
- ``workers`` concurrent transfers (default 8, as Skybrush Live): enough to hide round trips, few
  enough not to flood a shared radio. Vehicles are served in the order given; a failed attempt
  goes to the back of the queue, so one bad vehicle never blocks the others.
- Retried (up to ``retries`` more attempts): timeouts, cancellations, generic ERROR, DENIED (another
  GCS was uploading), INVALID_SEQUENCE, BUSY and read-back mismatches. Not retried: answers that
  would repeat (NO_SPACE, UNSUPPORTED*, INVALID*), malformed input and duplicate system ids.
- A system id heard from two addresses is refused before anything is sent to it (reported in its
  result, never merged).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass

from gcs_planner.autopilots import quirks_for
from gcs_planner.core.errors import UserError
from gcs_planner.core.lockstep import now_s
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import BusyError, MavlinkError, MissionError, MissionTimeoutError, VerifyError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.preflight import arm_when_ready, start_or_disarm
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType

__all__ = ["DEFAULT_WORKERS", "StartResult", "VehicleResult", "retryable", "start_fleet", "upload_fleet"]

DEFAULT_WORKERS = 8
RETRYABLE_FAILURES: tuple[type[MavlinkError], ...] = (MissionTimeoutError, BusyError, VerifyError)
# refusals of the moment, not of the items: another attempt may be accepted
RETRYABLE_RESULTS = frozenset(
    MissionResult[name] for name in ("OPERATION_CANCELLED", "ERROR", "DENIED", "INVALID_SEQUENCE")
)


def retryable(exc: MavlinkError) -> bool:
    """Whether another attempt may succeed: a timeout, a busy or mismatched transfer, or a refusal
    of the moment (cancelled, generic, denied, out of sequence), not of the items themselves."""
    refused_now = isinstance(exc, MissionError) and exc.result in RETRYABLE_RESULTS
    return isinstance(exc, RETRYABLE_FAILURES) or refused_now


@dataclass(frozen=True)
class VehicleResult:
    """Outcome for one vehicle; ``error`` is the last attempt's error (None on success)."""

    sysid: int
    ok: bool
    attempts: int
    elapsed_s: float  # from the first attempt's start to the final result [s]
    opaque_id: int = 0
    error: MavlinkError | None = None


Progress = Callable[[int, int, VehicleResult], None]


async def upload_fleet(
    link: MavlinkLink,
    missions: Mapping[int, Sequence[MissionItem]],
    workers: int = DEFAULT_WORKERS,
    retries: int = 2,
    progress: Progress | None = None,
    *,
    mission_type: int = MissionType.MISSION,
    compid: int = 1,
    timing: Timing | None = None,
    verify: bool = False,
) -> dict[int, VehicleResult]:
    """Upload ``missions[sysid]`` to each vehicle; returns a result per sysid (never raises per vehicle).

    ``progress(done, total, result)`` is called once per vehicle when its final result is known.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if retries < 0:
        raise ValueError(f"retries must be >= 0, got {retries}")
    total = len(missions)
    results: dict[int, VehicleResult] = {}
    started: dict[int, float] = {}
    queue: asyncio.Queue[tuple[int, int]] = asyncio.Queue()
    for sysid in missions:
        queue.put_nowait((sysid, 1))

    def finish(result: VehicleResult) -> None:
        results[result.sysid] = result
        if progress is not None:
            progress(len(results), total, result)

    async def worker() -> None:
        while True:
            sysid, attempt = await queue.get()
            try:
                t0 = started.setdefault(sysid, now_s())
                client = MissionClient(link, sysid, compid, timing=timing)
                try:
                    up = await client.upload(missions[sysid], mission_type=mission_type, verify=verify)
                except MavlinkError as exc:
                    if retryable(exc) and attempt <= retries:
                        queue.put_nowait((sysid, attempt + 1))
                    else:
                        finish(VehicleResult(sysid, False, attempt, now_s() - t0, error=exc))
                else:
                    finish(VehicleResult(sysid, True, attempt, now_s() - t0, up.opaque_id))
            finally:
                queue.task_done()

    tasks = [asyncio.create_task(worker()) for _ in range(min(workers, max(total, 1)))]
    joined = asyncio.ensure_future(queue.join())
    try:  # a worker ends only on an error that is not a vehicle's (a bug): raised, not waited out
        await asyncio.wait([joined, *tasks], return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in (joined, *tasks):
            task.cancel()
        await asyncio.gather(joined, *tasks, return_exceptions=True)
    for task in tasks:
        if not task.cancelled() and task.exception() is not None:
            raise task.exception()
    return {sysid: results[sysid] for sysid in missions}


@dataclass(frozen=True)
class StartResult:
    """One vehicle's part in ``start_fleet``: why it did not arm (``arm_error``) or refused the
    start (``start_error``, then disarmed again); ``ok`` when it flies its mission."""

    sysid: int
    arm_error: UserError | None = None
    start_error: UserError | None = None
    started: bool = True  # False: another vehicle did not arm, so none started

    @property
    def ok(self) -> bool:
        return self.started and self.start_error is None


async def start_fleet(
    link: MavlinkLink,
    sysids: Sequence[int],
    *,
    arm: bool = True,
    compid: int = 1,
    workers: int = DEFAULT_WORKERS,
    arm_timeout_s: float = 120.0,
    waiting: Callable[[int, str], None] | None = None,
) -> dict[int, StartResult]:
    """Arm every vehicle (once its pre-arm checks pass; ``waiting(sysid, reason)`` meanwhile), and
    only when all are armed MISSION_START(0, 0) each; ``workers`` vehicles at a time.

    ArduCopter is put in GUIDED before arming (it refuses to arm in AUTO); MISSION_START then
    switches it to AUTO. A vehicle that will not arm starts none, and those armed are disarmed
    again; one that disarmed itself while the others armed (ArduCopter's DISARM_DELAY) is armed
    again; one that refuses the start is disarmed (preflight.start_or_disarm).
    """
    gate = asyncio.Semaphore(workers)
    status = VehicleStatus(link, list(sysids))
    commands = {s: CommandClient(link, s, compid) for s in sysids}

    async def arm_one(sysid: int) -> None:
        link.check_target(sysid)
        info = link.vehicles.get(sysid)
        mode = None if info is None else quirks_for(info.autopilot, info.mav_type).start_arm_mode
        if mode is not None:
            await commands[sysid].set_mode(mode)
        await arm_when_ready(link, status, sysid, arm_timeout_s, waiting=waiting)

    async def each(
        step: Callable[[int], Awaitable[None]], which: Sequence[int]
    ) -> dict[int, UserError | None]:
        async def one(sysid: int) -> UserError | None:
            async with gate:
                try:
                    await step(sysid)
                except UserError as exc:  # MavlinkError included
                    return exc
                return None

        return dict(zip(which, await asyncio.gather(*(one(s) for s in which)), strict=True))

    try:
        arm_errors: dict[int, UserError | None] = dict.fromkeys(sysids)
        if arm:
            arm_errors = await each(arm_one, sysids)
            if not any(arm_errors.values()):
                arm_errors.update(await each(arm_one, [s for s in sysids if not link.vehicles[s].armed]))
        if any(arm_errors.values()):
            await asyncio.gather(*(commands[s].disarm() for s in sysids if arm_errors[s] is None))
            return {s: StartResult(s, arm_error=arm_errors[s], started=False) for s in sysids}
        start_errors = await each(lambda s: start_or_disarm(commands[s], status, arm), sysids)
    finally:
        status.close()
    return {s: StartResult(s, start_error=start_errors[s]) for s in sysids}
