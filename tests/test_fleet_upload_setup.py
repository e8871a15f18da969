"""Fleet upload set-up stays linear in the fleet (issue 36): `upload plan.json --sysid all` reads
plan.json once and finds each vehicle's plan by its fleet id, however many vehicles there are.

Before, each vehicle's lists were prepared by reading and checking the whole plan.json again (twice:
once before the link opened, once with the vehicle's autopilot) and by scanning the plan's vehicles
for its sysid: 2N + 2 plan reads for N vehicles, quadratic in N (200 vehicles 56 s; 1,000 sent
nothing for over 5 minutes). These tests count those operations, not seconds.
"""

from __future__ import annotations

import numpy as np
from ports import free_port_run

from gcs_planner.cli import build_parser, main
from gcs_planner.commands import upload
from gcs_planner.core.geo import Origin
from gcs_planner.model.plan import Plan, VehiclePlan
from sitl_mock.fleet import MockFleet

ORIGIN = Origin(47.397742, 8.545594, 488.0)


def _plan(fleet_ids: list[int]) -> Plan:
    """One short straight mission per fleet id."""
    vehicles = []
    for i, fid in enumerate(fleet_ids):
        wps = np.array([[0.0, 20.0 * i, 30.0], [100.0, 20.0 * i, 30.0], [200.0, 20.0 * i, 30.0]])
        times = np.array([0.0, 10.0, 20.0])
        vehicles.append(VehiclePlan(f"uav{i + 1}", fid, wps, times, np.full(3, 10.0), wps, times))
    return Plan(origin=ORIGIN, planner="straight", vehicles=vehicles)


def _fleet_ids(per_network: int, networks: int = 2) -> list[int]:
    return [n * 256 + s for n in range(networks) for s in range(1, per_network + 1)]


def _counting(monkeypatch) -> dict[str, int]:
    """Live counts of full plan.json reads (Plan.load) and of scans of the plan's vehicles
    (select_vehicles) made by the upload command."""
    counts = {"plan reads": 0, "vehicle scans": 0}
    load, select = Plan.load.__func__, upload.select_vehicles

    def counted_load(cls, path):
        counts["plan reads"] += 1
        return load(cls, path)

    def counted_select(*args, **kwargs):
        counts["vehicle scans"] += 1
        return select(*args, **kwargs)

    monkeypatch.setattr(Plan, "load", classmethod(counted_load))
    monkeypatch.setattr(upload, "select_vehicles", counted_select)
    return counts


def test_preparing_the_uploads_reads_the_plan_once_at_any_fleet_size(tmp_path, monkeypatch):
    """The set-up before any I/O, as `upload` runs it (UploadSource, then prepare per vehicle):
    one plan read and no scan, for 10 vehicles as for 500."""
    counts = _counting(monkeypatch)
    for size in (10, 500):
        plan_path = tmp_path / f"plan_{size}.json"
        _plan(_fleet_ids(size // 2)).save(plan_path)
        argv = ["upload", str(plan_path), "--sysid", "all", "--connect", "udpout:127.0.0.1:9"]
        args = build_parser("upload").parse_args(argv)
        counts.update({"plan reads": 0, "vehicle scans": 0})
        source = upload.UploadSource(args)
        prepared = [upload.prepare(args, "px4", s, source) for s in upload.target_sysids(args, source)]
        assert len(prepared) == size and all(lists[0][1] for lists in prepared)
        assert counts == {"plan reads": 1, "vehicle scans": 0}, size


def test_uploading_a_fleet_over_two_networks_reads_the_plan_once(tmp_path, monkeypatch, capsys):
    """The whole command, 2 networks x 5 vehicles: every mission ACCEPTED, one plan read, no scan
    (before the fix: 22 reads and 21 scans)."""
    per_network = 5
    fleet_ids = _fleet_ids(per_network)
    plan_path = tmp_path / "plan.json"
    _plan(fleet_ids).save(plan_path)
    counts = _counting(monkeypatch)
    base = free_port_run(2 * per_network)
    argv = ["upload", str(plan_path), "--sysid", "all", "--workers", str(len(fleet_ids))]
    with (
        MockFleet(count=per_network, home=ORIGIN, base_port=base, speedup=20.0),
        MockFleet(count=per_network, home=ORIGIN, base_port=base + per_network, speedup=20.0),
    ):
        for first in (base, base + per_network):
            argv += ["--connect", f"udpout:127.0.0.1:{first}-{first + per_network - 1}"]
        assert main(argv) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines() if " ACCEPTED " in line]
    assert sorted(int(r[0]) for r in rows) == fleet_ids
    assert counts == {"plan reads": 1, "vehicle scans": 0}
