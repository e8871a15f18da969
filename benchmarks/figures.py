"""Every figure the project quotes: the command that makes it and the file it is written to.

One entry per docs/results/<name>.md. `benchmarks/run_all.py` runs the ``steps`` of an entry (or
its ``quick`` steps) and writes the file; the tests check that every benchmark script is either a
figure's command here or a generator in ``GENERATORS``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FIGURES", "GENERATORS", "Figure", "by_name"]


@dataclass(frozen=True)
class Figure:
    """A figure: shell-like steps run from the repository root, in order.

    ``python`` in a step means this interpreter and ``gcs-planner`` / ``sitl-mock`` its entry
    points. ``markdown``: the steps print markdown (tables) that goes into the file as it is; else
    the output is kept as a code block. ``minutes``: a full run on an idle 2-core machine.
    ``needs``: modules that must import, else the figure is skipped with that reason.
    """

    name: str
    title: str
    steps: tuple[str, ...]
    quick: tuple[str, ...] = ()
    markdown: bool = True
    minutes: float = 1.0
    needs: tuple[str, ...] = ()


PEERS = ("pyswarms", "cma", "mealpy")  # pip install -e ".[bench]" && pip install --no-deps mealpy==3.0.3 ...

FIGURES: tuple[Figure, ...] = (
    Figure(
        "hil_flights",
        "The HIL run: bundled scenarios flown against mock autopilots in lockstep",
        (
            "gcs-planner demo -o {out}/demo",
            "gcs-planner fly missions/straight_4uav.toml -o {out}/straight_4uav --no-rrd",
            "gcs-planner fly missions/deconflict_10uav_manned.toml -o {out}/deconflict_10 --no-rrd",
            "gcs-planner plan missions/swarm40_cylinders.toml -o {out}/swarm40_plan.json",
            "gcs-planner fly missions/swarm40_cylinders.toml --plan {out}/swarm40_plan.json"
            " -o {out}/swarm40 --no-rrd",
        ),
        quick=("gcs-planner demo -o {out}/demo",),
        markdown=False,
        minutes=4,
    ),
    Figure(
        "lockstep",
        "Lockstep against the paced mock: the same flights, wall time per step",
        (
            "gcs-planner demo -o {out}/demo",
            "gcs-planner demo -o {out}/demo_paced --speedup 10",
            "python benchmarks/coalition_online.py --runs 1 --targets T1",
            "python benchmarks/coalition_online.py --runs 1 --targets T1 --speedup 5",
        ),
        quick=("gcs-planner demo -o {out}/demo",),
        minutes=2,
    ),
    Figure(
        "same_flight",
        "The same flight idle and beside busy processes",
        ("python benchmarks/same_flight.py",),
        quick=("python benchmarks/same_flight.py --targets T1",),
        minutes=3,
    ),
    Figure(
        "fly_swarm500",
        "500 vehicles flown by one fly over two MAVLink networks",
        ("python benchmarks/fly_swarm500.py --out {out}/fly500 --errors {out}/time_errors.json",),
        minutes=17,
    ),
    Figure(
        "cli_startup",
        "CLI start-up against MAVProxy",
        ("python benchmarks/cli_startup.py --runs 15",),
        quick=("python benchmarks/cli_startup.py --runs 3",),
        minutes=0.5,
    ),
    Figure(
        "site_inputs",
        "Site inputs: import cost of the readers' libraries, reading the bundled site, planning it",
        ("python benchmarks/site_inputs.py --runs 7",),
        quick=("python benchmarks/site_inputs.py --runs 2",),
        minutes=1,
    ),
    Figure(
        "sweep_throughput",
        "Sweep throughput: local workers and a Dask LocalCluster",
        ("python benchmarks/sweep_throughput.py studies/swarm_small_budget.toml --seeds 20",),
        quick=("python benchmarks/sweep_throughput.py studies/swarm_small_budget.toml --seeds 4",),
        minutes=6,
        needs=("distributed",),
    ),
    Figure(
        "upload_latency",
        "Mission upload: ours against pymavlink and MAVSDK, both mock profiles",
        (
            "python benchmarks/upload_latency.py --profile px4",
            "python benchmarks/upload_latency.py --profile ardupilot",
        ),
        quick=("python benchmarks/upload_latency.py --profile px4 --quick",),
        minutes=8,
        needs=("mavsdk",),
        markdown=False,
    ),
    Figure(
        "upload_cpu",
        "Upload CPU per item and transfer time: ours against MAVSDK in one run",
        (
            "python benchmarks/upload_cpu.py",
            "python benchmarks/upload_cpu.py --profile ardupilot",
            "python benchmarks/upload_hot_path.py",
            "python benchmarks/udp_wakeup.py",
        ),
        quick=(
            "python benchmarks/upload_cpu.py --sizes 100 --rounds 1 --reps 2",
            "python benchmarks/upload_hot_path.py --items 100 --runs 2",
            "python benchmarks/udp_wakeup.py --count 500 --rounds 1",
        ),
        minutes=3,
        needs=("mavsdk",),
    ),
    Figure(
        "upload_window",
        "Upload time against items in flight on lossy and slow links (fake time)",
        ("python benchmarks/upload_window.py",),
        quick=("python benchmarks/upload_window.py --items 30 --seeds 4",),
        minutes=0.2,
    ),
    Figure(
        "fleet_upload",
        "Fleet upload: gcs-planner upload --sysid all to N mock vehicles",
        ("python benchmarks/fleet_upload.py --counts 100 200 400 1000",),
        quick=("python benchmarks/fleet_upload.py --counts 20",),
        minutes=1,
    ),
    Figure(
        "mock_capacity",
        "Mock vehicles one process carries at 10 Hz",
        ("python benchmarks/mock_capacity.py --counts 100 200 254",),
        quick=("python benchmarks/mock_capacity.py --counts 20 --window 2 --warmup 1",),
        minutes=2,
    ),
    Figure(
        "logging_throughput",
        "Telemetry: MCAP logger throughput, size, replay, a live fleet",
        ("python benchmarks/logging_throughput.py --vehicles 100 --seconds 60 --live-seconds 10",),
        quick=(
            "python benchmarks/logging_throughput.py --vehicles 10 --seconds 10 --live-seconds 3 --repeat 1",
        ),
        minutes=3,
    ),
    Figure(
        "mcap_writers",
        "MCAP writers: ours against the stock Python writer and foxglove-sdk's",
        ("python benchmarks/mcap_writers.py",),
        quick=("python benchmarks/mcap_writers.py --messages 20000 --repeat 1",),
        minutes=0.5,
    ),
    Figure(
        "mission_items",
        "Plan -> mission items and the file formats, per mission size",
        ("python benchmarks/mission_items.py --sizes 100 1000 10000",),
        quick=("python benchmarks/mission_items.py --sizes 100 --repeat 1",),
        minutes=0.5,
    ),
    Figure(
        "input_fuzz",
        "Mutated inputs through every CLI reader",
        ("python benchmarks/input_fuzz.py --n 4000 --seed 1",),
        quick=("python benchmarks/input_fuzz.py --n 100 --seed 1",),
        minutes=5,
        markdown=False,
    ),
    Figure(
        "priority_swarm_compare",
        "Priority swarm (seed 000) against PSO / DE / GWO baselines, 40 UAVs, seeds 0-9",
        (
            "python benchmarks/priority_swarm.py compare --out {out}/bench_swarm.csv",
            "python benchmarks/priority_swarm.py table {out}/bench_swarm.csv",
        ),
        minutes=40,
    ),
    Figure(
        "priority_swarm_scale",
        "Priority swarm scaling: 40 and 500 UAVs (swarm500)",
        (
            "python benchmarks/priority_swarm.py scale --out {out}/bench_scale.json",
            "python benchmarks/priority_swarm.py table {out}/bench_scale.json",
        ),
        minutes=4,
    ),
    Figure(
        "sweep_scaling",
        "Sweep scaling: runs / min and CPU per run at 1 and 2 workers, local pool and Dask",
        (
            "python benchmarks/sweep_scaling.py studies/swarm_one_point.toml --seeds 32 --workers 1 2"
            " --dask local cli",
        ),
        quick=("python benchmarks/sweep_scaling.py studies/swarm_one_point.toml --seeds 2 --workers 1",),
        minutes=2,
        needs=("distributed",),
    ),
    Figure(
        "priority_swarm_ablation",
        "Priority swarm ablation on swarm40_cylinders (sweep)",
        ("gcs-planner sweep studies/priority_swarm_ablation.toml -o {out}/ablation.csv",),
        markdown=False,
        minutes=25,
    ),
    Figure(
        "planner_peers",
        "Priority swarm against library optimisers on its own cost",
        (
            "python benchmarks/planner_peers.py --scenarios swarm40_open swarm40_cylinders swarm40_passages"
            " swarm40_urban --seeds 0 1 2 3 4 --out {out}/bench_peers.json",
        ),
        minutes=60,
        needs=PEERS,
    ),
    Figure(
        "acmpso_table3",
        "ACMPSO (seed 001) Table 3: 100 runs of BPSO / LPSO / ACMPSO, three readings",
        ("python benchmarks/acmpso_table3.py --runs 100 --out {out}/acmpso_table3.csv",),
        quick=("python benchmarks/acmpso_table3.py --runs 3 --variants literal,tuned --out {out}/runs.csv",),
        minutes=20,
        markdown=False,
    ),
    Figure(
        "acmpso_fly",
        "The ACMPSO plan flown on the mock fixed wing",
        ("python benchmarks/acmpso_fly.py --speedup 200",),
        markdown=False,
        minutes=3,
    ),
    Figure(
        "coalition_timeline",
        "Coalition planning (seed 003): event timeline and compute per coalition",
        ("python benchmarks/coalition_timeline.py --repeat 10",),
        quick=("python benchmarks/coalition_timeline.py --repeat 1",),
        markdown=False,
        minutes=2,
    ),
    Figure(
        "coalition_online",
        "The paper coalition flown online on the mock",
        ("python benchmarks/coalition_online.py --runs 2",),
        quick=("python benchmarks/coalition_online.py --runs 1 --targets T1",),
        minutes=2,
    ),
    Figure(
        "coalition_montecarlo",
        "Coalition Monte Carlo: ACO against the polynomial baseline and global optimisation",
        ("python benchmarks/coalition_montecarlo.py --study mc --runs 20",),
        markdown=False,
        minutes=15,
    ),
    Figure(
        "mock_scurve",
        "What ArduCopter's S-curve legs cost the mock, against its tuned kinematics",
        ("python benchmarks/mock_scurve.py --counts 10 100 250",),
        quick=("python benchmarks/mock_scurve.py --counts 10 --steps 20 --rounds 1",),
        minutes=1,
    ),
    Figure(
        "deconflict_tables",
        "4-D deconfliction (seed 004) Tables 1-3 and the scaled fleets",
        ("python benchmarks/deconflict_tables.py --seeds 3 --out {out}",),
        quick=("python benchmarks/deconflict_tables.py --seeds 1 --sizes 4 --scaled --out {out}",),
        markdown=False,
        minutes=10,
    ),
    Figure(
        "deconflict_100uav",
        "4-D deconfliction of 100 UAVs: planning time",
        ("gcs-planner plan missions/deconflict_100uav_scaled.toml -o {out}/plan.json",),
        minutes=0.5,
    ),
    Figure(
        "deconflict_peers",
        "4-D deconfliction's joint PSO against library optimisers",
        (
            "python benchmarks/deconflict_peers.py --sizes 4 5 6 7 8 9 10 --seeds 1 2 3 4 5"
            " --out {out}/bench_deconflict_peers.json",
        ),
        minutes=30,
        needs=PEERS,
    ),
)

# scripts that write inputs (scenario files), not figures
GENERATORS = ("make_coalition_sitl.py", "make_site_valley.py", "make_swarm_scenarios.py")


def by_name(name: str) -> Figure:
    """The figure called ``name``; KeyError naming the known ones otherwise."""
    for figure in FIGURES:
        if figure.name == name:
            return figure
    raise KeyError(f"{name!r} (known: {', '.join(f.name for f in FIGURES)})")
