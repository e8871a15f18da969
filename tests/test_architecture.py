"""The layers are the folders of gcs_planner/, and imports go down them: no cycle, no upward import.

Every import in gcs_planner/ and sitl_mock/ is read from the source (function-level ones too), so
a lazy import cannot hide a cycle. The layer order is docs/architecture.md's table.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("gcs_planner", "sitl_mock")
MAX_FUNCTION_LINES = 80
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def _layers() -> list[str]:
    """The folders of gcs_planner/, bottom layer first, as docs/architecture.md's layer table lists them."""
    return re.findall(r"^\| \d+ \| `gcs_planner/(\w+)/` \|", ARCHITECTURE.read_text(), flags=re.M)


LAYERS = _layers()
# the root holds the version (imported by anything) and the CLI's entry point (imports anything)
ROOT_MODULES = {"gcs_planner": -1, "gcs_planner.cli": len(LAYERS)}
# the MAVLink wire core: what the GCS and the mock autopilot share. The mock keeps its own geodesy
# (sitl_mock/geodesy.py, checked against the client's by tests/test_geodesy_crosscheck.py), fleet
# ids and plan reading (plan_fleet.py) and models of an autopilot (storage.py, l1.py): a simulated
# autopilot shares no code with the GCS it tests beyond the wire format
WIRE = "gcs_planner.wire"


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str) -> set[str]:
    """The project modules ``name`` imports, anywhere in its source."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            # `from package import module` imports the module; `from module import name` the module
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        found |= {t for t in targets if t in MODULES}
    return found


GRAPH = {name: _imports(name) for name in MODULES}
MODULES_OF = {p: [m for m in MODULES if m.split(".")[0] == p] for p in PACKAGES}


def layer(module: str) -> int:
    """The layer of a module of gcs_planner: its folder's place in LAYERS."""
    if module in ROOT_MODULES:
        return ROOT_MODULES[module]
    return LAYERS.index(module.split(".")[1])


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """``module -> dependency`` for every import of a higher layer."""
    return sorted(
        f"{m} -> {d}"
        for m, deps in graph.items()
        for d in deps
        if m.startswith("gcs_planner") and d.startswith("gcs_planner") and layer(d) > layer(m)
    )


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph, if it has any (depth-first search)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if state.get(w) == 1:
                return stack[stack.index(w) :] + [w]
            if w not in state and (found := visit(w)):
                return found
        state[v] = 2
        stack.pop()
        return None

    for v in sorted(edges):
        if v not in state and (found := visit(v)):
            return found
    return None


def test_the_folders_are_the_layers_and_the_root_holds_only_the_version_and_the_cli():
    folders = {p.name for p in (ROOT / "gcs_planner").iterdir() if (p / "__init__.py").is_file()}
    assert len(LAYERS) == len(set(LAYERS)) and set(LAYERS) == folders, "docs/architecture.md's layer table"
    assert {p.name for p in (ROOT / "gcs_planner").glob("*.py")} == {"__init__.py", "cli.py"}


def test_imports_go_down_the_layers():
    assert upward_imports(GRAPH) == []


def test_no_import_cycle_between_modules():
    assert _cycle(GRAPH) is None, _cycle(GRAPH)


def test_the_checks_find_an_upward_import_and_a_cycle():
    low, high = f"gcs_planner.{LAYERS[0]}.a", f"gcs_planner.{LAYERS[-1]}.b"
    assert upward_imports({low: {high}, high: {low}}) == [f"{low} -> {high}"]
    assert upward_imports({"gcs_planner": {"gcs_planner.cli"}}) == ["gcs_planner -> gcs_planner.cli"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_gcs_planner_never_imports_the_mock():
    offenders = sorted(m for m, deps in GRAPH.items() if m.startswith("gcs_planner") and any(
        d.startswith("sitl_mock") for d in deps))  # fmt: skip
    assert offenders == [], "the flight code gets its vehicles from a VehicleSource (flight/vehicles.py)"


def test_the_mock_uses_only_the_wire_core_of_gcs_planner():
    used = {d for m in MODULES_OF["sitl_mock"] for d in GRAPH[m]} - set(MODULES_OF["sitl_mock"])
    assert used and all(d.startswith(WIRE + ".") for d in used), sorted(used)


def test_the_wire_core_builds_on_nothing_else():
    for module in (m for m in MODULES if m.startswith(WIRE)):
        assert all(d.startswith(WIRE) for d in GRAPH[module]), (module, sorted(GRAPH[module]))


# the steps of a flight: only the one flight runner (gcs_planner/flight/runner.py) takes them, so
# that fly and fly-coalition, its two front ends, cannot drift apart again; the telemetry package
# and `watch` (which logs without flying) write logs too
FLIGHT_STEPS = {
    "wait_for_vehicles", "take_off_all", "start_routes", "safe_end", "FlightLogger", "SafeEndSignals",
}  # fmt: skip
TAKERS = {"gcs_planner.flight.runner": FLIGHT_STEPS, "gcs_planner.commands.watch": {"FlightLogger"}}


def _calls(name: str) -> set[str]:
    """The names ``name`` calls (``f(...)`` and ``x.f(...)``)."""
    calls = set()
    for node in ast.walk(ast.parse(MODULES[name].read_text())):
        if isinstance(node, ast.Call):
            f = node.func
            calls.add(f.id if isinstance(f, ast.Name) else getattr(f, "attr", ""))
    return calls


def test_only_the_flight_runner_takes_the_steps_of_a_flight():
    modules = [m for m in MODULES_OF["gcs_planner"] if not m.startswith("gcs_planner.telemetry")]
    taken = {m: _calls(m) & FLIGHT_STEPS for m in modules}
    stray = {m: sorted(steps - TAKERS.get(m, set())) for m, steps in taken.items()}
    assert {m: steps for m, steps in stray.items() if steps} == {}
    assert taken["gcs_planner.flight.runner"] == FLIGHT_STEPS  # the test looks where the steps are


def _long_functions(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    return [
        f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)"
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_function_over_80_lines(package):
    long = [entry for path in sorted((ROOT / package).rglob("*.py")) for entry in _long_functions(path)]
    assert long == []
