"""Mutated inputs for every CLI reader, shared by tests/test_input_fuzz.py and benchmarks/input_fuzz.py.

Each case builds one mutated input (scenario TOML and its world tables, plan.json, .tlog bytes,
MCAP bytes, CLI flag values, a study TOML or a sweep's results CSV) in a fresh folder from a
``random.Random``, and returns the ``gcs-planner`` argv that reads it. :func:`run_case` runs it
through ``gcs_planner.cli.main`` and records what came out: the exit code, stderr, any uncaught
exception and the files left in the folder.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import random
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

NASTY: list[object] = [
    0, -1, -50, 1e-9, 1e9, 1e308, -1e308, math.inf, -math.inf, math.nan, "x", "", "é\u0000", True,
    [], {}, [1, 2], [[[1]]], 2**63, -(2**63), 256, 3.5, "uav1", 1, 2,
]  # fmt: skip
FLAG_VALUES = ["0", "-1", "1", "2", "nan", "inf", "-inf", "1e308", "x", "", "3.5", "99:1:1", "1:1:1",
               "1:nan:0", "1:2", "a:b:c", "1,2,3", "47,8", "91,0,0", "47,8,1e400"]  # fmt: skip

SCENARIO: dict = {
    "name": "fuzz",
    "origin": {"lat_deg": 47.397742, "lon_deg": 8.545594, "alt_m": 488.0},
    "planner": {"name": "straight", "seed": 1, "waypoint_spacing_m": 80.0},
    "bounds": {"x": [-100.0, 400.0], "y": [-100.0, 300.0]},
    "obstacles": {
        "cylinders": [{"x": 150.0, "y": 200.0, "radius_m": 10.0, "z_max_m": 60.0, "buffer_m": 2.0}],
        "hemispheres": [{"x": 50.0, "y": -80.0, "radius_m": 40.0}],
    },
    "vehicles": [
        {"id": "uav1", "sysid": 1, "start": [0.0, 0.0, 20.0], "goal": [300.0, 0.0, 20.0], "speed_mps": 12.0},
        {
            "id": "uav2",
            "sysid": 2,
            "type": "fixed_wing",
            "start": [0.0, 30.0, 25.0],
            "goal": [300.0, 130.0, 25.0],
            "speed_mps": 15.0,
            "turn_radius_m": 40.0,
            "min_alt_m": 10.0,
            "max_alt_m": 120.0,
            "separation_m": 5.0,
        },
    ],
}

# the world tables: manned traffic (a mode mixture and a recorded track) and terrain peaks
WORLD: dict = {
    "manned": [
        {"id": "ga1", "dt_s": 1.0, "position_m": [-60.0, 6.0, 12.0], "velocity_mps": [10.0, 0.0, 0.0],
         "observed_s": 10.0,
         "modes": [{"name": "cruise", "velocity_mps": [10.0, 0.0, 0.0], "sigma_mps": [0.3, 0.3, 0.1],
                    "strength": 20.0, "weight": 0.9},
                   {"name": "descent", "velocity_mps": [9.0, 0.0, -2.0], "sigma_mps": [0.3, 0.3, 0.2],
                    "strength": 20.0, "weight": 0.1}]},
    ],
    "terrain": {"type": "peaks",
                "peaks": [{"h_m": 15.0, "x_m": 150.0, "y_m": -60.0, "sx_m": 30.0, "sy_m": 20.0}]},
}  # fmt: skip
STUDY: dict = {
    "name": "fuzz",
    "scenario": "s.toml",
    "seeds": [0, 1],
    "metrics": ["feasible_fraction"],
    "grid": {"waypoint_spacing_m": [80.0, 120.0]},
}


# -- TOML and tree mutation ------------------------------------------------------------------------
def toml_value(v: object) -> str:
    """One value as inline TOML (tables inline, floats with nan / inf)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def toml_dumps(data: dict) -> str:
    """A dict as TOML: one ``key = inline value`` line per top-level key."""
    return "".join(f"{json.dumps(str(k))} = {toml_value(v)}\n" for k, v in data.items())


def _paths(tree: object, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += _paths(v, (*prefix, i))
    return out


def mutate_tree(tree: object, rng: random.Random, rounds: int | None = None) -> object:
    """A deep copy of ``tree`` with 1-3 random edits: a nasty value, a deleted key, a duplicated
    list entry, or a value wrapped in a list."""
    tree = copy.deepcopy(tree)
    for _ in range(rounds or rng.randint(1, 3)):
        path = rng.choice(_paths(tree)[1:] or [()])
        if not path:
            return rng.choice(NASTY)
        parent = tree
        for key in path[:-1]:
            parent = parent[key]
        key, op = path[-1], rng.random()
        if op < 0.6:
            parent[key] = copy.deepcopy(rng.choice(NASTY))
        elif op < 0.75 and isinstance(parent, dict):
            del parent[key]
        elif op < 0.9 and isinstance(parent, list):
            parent.append(copy.deepcopy(parent[key]))
        else:
            parent[key] = [parent[key]]
    return tree


def mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    """Flip, overwrite, cut or insert bytes (1-4 edits)."""
    buf = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if not buf:
            buf += bytes([rng.randrange(256)])
            continue
        i, op = rng.randrange(len(buf)), rng.random()
        if op < 0.35:
            buf[i] ^= 1 << rng.randrange(8)
        elif op < 0.55:
            buf[i : i + 8] = rng.choice(
                [b"\xff" * 8, b"\x00" * 8, bytes(rng.randrange(256) for _ in range(8))]
            )
        elif op < 0.75:
            del buf[rng.randrange(len(buf)) :]
        else:
            buf[i:i] = rng.choice([b"\xff\xfe", b"\x80", b"\xef\xbb\xbf", b"\x00", b"[" * 3, b'"'])
    return bytes(buf)


def deep_nesting(kind: str) -> bytes:
    """A document nested far deeper than Python's recursion limit."""
    if kind == "json":
        return b"[" * 200_000 + b"]" * 200_000
    return b"a = " + b"[" * 200_000 + b"]" * 200_000 + b"\n"


# -- base inputs ---------------------------------------------------------------------------------------
_cache: dict[str, object] = {}


def base_plan() -> dict:
    """plan.json (as a dict) of SCENARIO with the straight planner."""
    if "plan" not in _cache:
        from gcs_planner.planning import parse_scenario, plan_scenario

        _cache["plan"] = plan_scenario(parse_scenario(copy.deepcopy(SCENARIO))).to_dict()
    return copy.deepcopy(_cache["plan"])


def base_tlog() -> bytes:
    """A small .tlog: two vehicles, 12 position reports each."""
    if "tlog" not in _cache:
        from telemetry_frames import flight_frames

        rows = [(round(t * 1e6) & ~3, raw) for _, raw, t in flight_frames([1, 2], samples=12)]
        _cache["tlog"] = b"".join(t_us.to_bytes(8, "big") + raw for t_us, raw in rows)
    return _cache["tlog"]


def base_mcap(tmp: Path) -> bytes:
    """The MCAP that import-tlog writes for base_tlog() with base_plan() attached."""
    if "mcap" not in _cache:
        from gcs_planner.model.plan import Plan
        from gcs_planner.telemetry.tlog import import_tlog

        (tmp / "base.tlog").write_bytes(base_tlog())
        plan = Plan.from_dict(base_plan())
        import_tlog(tmp / "base.tlog", tmp / "base.mcap", plan=plan, scenario_text=toml_dumps(SCENARIO))
        _cache["mcap"] = (tmp / "base.mcap").read_bytes()
        (tmp / "base.tlog").unlink()
        (tmp / "base.mcap").unlink()
    return _cache["mcap"]


# -- cases: (rng, folder) -> argv -------------------------------------------------------------------------
def _scenario_text(rng: random.Random) -> bytes:
    r = rng.random()
    if r < 0.7:
        return toml_dumps(mutate_tree(SCENARIO, rng)).encode()
    if r < 0.97:
        return mutate_bytes(toml_dumps(SCENARIO).encode(), rng)
    return deep_nesting("toml")


def _plan_text(rng: random.Random) -> bytes:
    r = rng.random()
    if r < 0.75:
        return json.dumps(mutate_tree(base_plan(), rng)).encode()
    if r < 0.97:
        return mutate_bytes(json.dumps(base_plan()).encode(), rng)
    return deep_nesting("json")


def _world_text(rng: random.Random) -> bytes:
    """SCENARIO with manned traffic and terrain peaks, one of the two mutated."""
    tree = {**copy.deepcopy(SCENARIO), **copy.deepcopy(WORLD)}
    key = rng.choice(["manned", "terrain"])
    tree[key] = mutate_tree(tree[key], rng)
    if rng.random() < 0.1:
        tree = mutate_tree(tree, rng)
    return toml_dumps(tree).encode()


def base_sweep_csv(tmp: Path) -> bytes:
    """The results CSV of a complete sweep of STUDY (4 runs)."""
    if "csv" not in _cache:
        from gcs_planner.cli import main

        (tmp / "s.toml").write_text(toml_dumps(SCENARIO))
        (tmp / "study.toml").write_text(toml_dumps(STUDY))
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            argv = ["sweep", str(tmp / "study.toml"), "-o", str(tmp / "base.csv"), "--workers", "1"]
            assert main(argv) == 0
        _cache["csv"] = (tmp / "base.csv").read_bytes()
        for name in ("s.toml", "study.toml", "base.csv", "base_summary.csv", "base_plots.png"):
            (tmp / name).unlink(missing_ok=True)
    return _cache["csv"]


def _study_files(rng: random.Random | None, d: Path) -> str:
    """STUDY (mutated when ``rng`` is given) and its scenario in ``d``; the study's path."""
    (d / "s.toml").write_text(toml_dumps(SCENARIO))
    study = STUDY if rng is None else mutate_tree(STUDY, rng)
    text = toml_dumps(study).encode() if rng is None or rng.random() < 0.8 else None
    if text is None:
        text = mutate_bytes(toml_dumps(STUDY).encode(), rng)
    return _write(d, "study.toml", text)


def _write(folder: Path, name: str, data: bytes) -> str:
    (folder / "out").mkdir(exist_ok=True)
    (folder / name).write_bytes(data)
    return str(folder / name)


def case_plan(rng: random.Random, d: Path) -> list[str]:
    return ["plan", _write(d, "s.toml", _scenario_text(rng)), "-o", str(d / "out" / "plan.json")]


def case_fly_scenario(rng: random.Random, d: Path) -> list[str]:
    return ["fly", _write(d, "s.toml", _scenario_text(rng)), "-o", str(d / "out"), "--no-rrd"]


def case_fly_plan(rng: random.Random, d: Path) -> list[str]:
    scen = _write(d, "s.toml", toml_dumps(SCENARIO).encode())
    return ["fly", scen, "--plan", _write(d, "p.json", _plan_text(rng)), "-o", str(d / "out"), "--no-rrd"]


def case_export(rng: random.Random, d: Path) -> list[str]:
    fmt = rng.choice(["qgc", "wpl"])
    return ["export", _write(d, "p.json", _plan_text(rng)), "--format", fmt, "-o", str(d / "out")]


def case_upload(rng: random.Random, d: Path) -> list[str]:
    sysid = rng.choice(["all", "1", "2", "1,2"])
    plan = _write(d, "p.json", _plan_text(rng))
    return [
        "upload",
        "--connect",
        "udpout:127.0.0.1:9",
        "--heartbeat-timeout",
        "0.05",
        "--sysid",
        sysid,
        plan,
    ]


def case_import_tlog(rng: random.Random, d: Path) -> list[str]:
    tlog = _write(d, "f.tlog", mutate_bytes(base_tlog(), rng))
    return ["import-tlog", tlog, "-o", str(d / "out" / "f.mcap")]


def case_replay(rng: random.Random, d: Path) -> list[str]:
    mcap = _write(d, "f.mcap", mutate_bytes(base_mcap(d), rng))
    return ["replay", mcap, "--to", "udpout:127.0.0.1:9", "--speed", "0"]


def case_flags(rng: random.Random, d: Path) -> list[str]:
    scen = _write(d, "s.toml", toml_dumps(SCENARIO).encode())
    value = rng.choice(FLAG_VALUES)
    out = rng.choice([str(d / "out"), str(d / "missing" / "deeper"), scen])
    choices: list[list[str]] = [
        ["fly", scen, "-o", str(d / "out"), "--no-rrd", "--workers", value],
        ["fly", scen, "-o", str(d / "out"), "--no-rrd", "--speedup", value],
        ["fly", scen, "-o", str(d / "out"), "--no-rrd", "--drift", value],
        ["fly", scen, "-o", str(d / "out"), "--no-rrd", "--max-cross-track", value],
        ["fly", scen, "-o", out, "--no-rrd"],
        ["plan", scen, "--seed", value, "-o", str(d / "out" / "plan.json")],
        ["plan", scen, "-o", out if out != scen else str(d / "missing" / "plan.json")],
        ["import-tlog", _write(d, "f.tlog", base_tlog()), "--origin", value, "-o", str(d / "out" / "f.mcap")],
        ["import-tlog", _write(d, "f.tlog", base_tlog()), "-o", out if out != scen else str(d / "x.mcap")],
        ["replay", _write(d, "f.mcap", base_mcap(d)), "--to", "udpout:127.0.0.1:9", "--speed", value],
        ["upload", "--connect", "udpout:127.0.0.1:9", "--heartbeat-timeout", value, "--sysid", "1",
         _write(d, "p.json", json.dumps(base_plan()).encode())],
        ["upload", "--connect", "udpout:127.0.0.1:9", "--heartbeat-timeout", "0.05", "--workers", value,
         "--sysid", "all", _write(d, "p.json", json.dumps(base_plan()).encode())],
        ["export", _write(d, "p.json", json.dumps(base_plan()).encode()), "-o", out],
    ]  # fmt: skip
    return rng.choice(choices)


def case_world(rng: random.Random, d: Path) -> list[str]:
    return ["plan", _write(d, "s.toml", _world_text(rng)), "-o", str(d / "out" / "plan.json")]


def case_study(rng: random.Random, d: Path) -> list[str]:
    return ["sweep", _study_files(rng, d), "-o", str(d / "out" / "r.csv"), "--workers", "1"]


def case_sweep_csv(rng: random.Random, d: Path) -> list[str]:
    """Resume a cut, garbled or foreign results CSV (it is in out/ before the run)."""
    study = _study_files(None, d)
    data = base_sweep_csv(d)
    r = rng.random()
    if r < 0.4:
        data = data[: rng.randrange(len(data) + 1)]  # a sweep killed mid-row
    elif r < 0.9:
        data = mutate_bytes(data, rng)
    else:
        data = rng.choice([b"\xff\xfe" + data.decode().encode("utf-16-le"), b"\x00" * 64, b"a,b\n1,2\n"])
    _write(d, "out/r.csv", data)
    return ["sweep", study, "-o", str(d / "out" / "r.csv"), "--workers", "1"]


CASES: dict[str, Callable[[random.Random, Path], list[str]]] = {
    "plan (scenario)": case_plan,
    "fly (scenario)": case_fly_scenario,
    "fly (plan.json)": case_fly_plan,
    "export (plan.json)": case_export,
    "upload (plan.json)": case_upload,
    "import-tlog (.tlog)": case_import_tlog,
    "replay (MCAP)": case_replay,
    "CLI flags": case_flags,
    "plan (world tables)": case_world,
    "sweep (study)": case_study,
    "sweep (resume CSV)": case_sweep_csv,
}


# -- running -----------------------------------------------------------------------------------------
@dataclass
class Outcome:
    argv: list[str]
    code: int | None
    stderr: str
    exception: str | None  # the traceback of an uncaught exception
    new_files: list[str]  # files in the folder that were not there before the run


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()}


def run_case(argv: list[str], folder: Path) -> Outcome:
    """Run ``gcs-planner argv`` in-process with the flight stubbed out (see stub_fly)."""
    from gcs_planner.cli import main

    before = _files(folder)
    err = io.StringIO()
    code, exc = None, None
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse
            code = e.code if isinstance(e.code, int) else 2
        except BaseException:  # noqa: BLE001 - what the fuzz counts
            exc = traceback.format_exc()
    return Outcome(argv, code, err.getvalue(), exc, sorted(_files(folder) - before))


async def stub_fly(scenario, plan, options, vehicles, progress=None):
    """Stands in for gcs_planner.flight.fly: what the real one checks before it sends, then no flight."""
    from gcs_planner.autopilots import quirks_named
    from gcs_planner.flight import FlyResult
    from gcs_planner.flight.ops import build_missions
    from gcs_planner.missions.items import AUTOPILOTS

    for conventions in AUTOPILOTS:
        build_missions(plan, {vp.sysid: quirks_named(conventions) for vp in plan.vehicles})
    return FlyResult([], {}, options.out_dir / "flight.mcap", None, [], 0.0)


def problems(outcome: Outcome) -> list[str]:
    """What the fuzz forbids: an exit code other than 0 / 2 (or 1 from `plan` that wrote a plan the
    plan checker found infeasible), an uncaught exception, more than one stderr line on exit 2, a
    file left behind on exit 2."""
    out = []
    infeasible = outcome.argv[0] == "plan" and outcome.code == 1 and "out/plan.json" in outcome.new_files
    if outcome.exception:
        out.append("traceback: " + outcome.exception.strip().splitlines()[-1])
    elif outcome.code not in (0, 2) and not infeasible:
        out.append(f"exit code {outcome.code}")
    if outcome.code == 2:
        lines = [line for line in outcome.stderr.splitlines() if line.strip()]
        if len(lines) != 1:
            out.append(f"{len(lines)} stderr lines: {outcome.stderr[:300]!r}")
        leftovers = [f for f in outcome.new_files if f.startswith(("out", "missing"))]
        if leftovers:
            out.append(f"left behind on exit 2: {leftovers}")
    return out
