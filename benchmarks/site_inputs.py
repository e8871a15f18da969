"""Site inputs (docs/sites.md): what the readers' libraries cost to import, how long the bundled
site takes to read, and what planning and checking it costs per planner.

    python benchmarks/site_inputs.py --runs 7

Import rows: CPU seconds of ``import X`` in a fresh interpreter that has already imported numpy
(every candidate needs it), median of ``--runs``; a library that is not installed is listed as
such (fastkml and rasterio are the alternatives weighed, not dependencies). Read rows: CPU
seconds (``time.process_time``) of reading each input of missions/site_valley, of an SRTM3 tile
(1201 x 1201, written to a temporary folder) and of the KML equivalent of the site's GeoJSON, and
of loading the scenario (features + DEM resampled into the local frame). Plan rows: CPU seconds
of planning each site scenario and of the plan checker on the result.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "missions" / "site_valley"
SCENARIOS = ("site_valley_swarm", "site_valley_acmpso", "site_valley_4d")
IMPORTS = ("shapely", "tifffile", "xml.etree.ElementTree", "zipfile", "fastkml", "rasterio")


def _import_cpu_s(module: str, runs: int) -> float | None:
    code = (
        "import time, numpy; t = time.process_time(); import importlib;"
        f" importlib.import_module({module!r}); print(time.process_time() - t)"
    )
    times = []
    for _ in range(runs):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
        if done.returncode:
            return None
        times.append(float(done.stdout))
    return statistics.median(times)


def _cpu(fn, runs: int = 3) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(runs):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


def _kml_text() -> str:
    marks = []
    for f in json.loads((SITE / "valley.geojson").read_text())["features"]:
        data = "".join(f'<Data name="{k}"><value>{v}</value></Data>' for k, v in f["properties"].items())
        g = f["geometry"]
        if g["type"] == "Point":
            shape = f"<Point><coordinates>{g['coordinates'][0]},{g['coordinates'][1]}</coordinates></Point>"
        else:
            ring = " ".join(f"{a},{b}" for a, b in g["coordinates"][0])
            shape = (
                "<Polygon><outerBoundaryIs><LinearRing><coordinates>"
                f"{ring}</coordinates></LinearRing></outerBoundaryIs></Polygon>"
            )
        marks.append(f"<Placemark><ExtendedData>{data}</ExtendedData>{shape}</Placemark>")
    return f'<kml xmlns="http://www.opengis.net/kml/2.2"><Document>{"".join(marks)}</Document></kml>'


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    print("| import (after numpy) | CPU [ms], median of", args.runs, "|")
    print("|---|---|")
    for module in IMPORTS:
        cpu = _import_cpu_s(module, args.runs)
        print(f"| {module} | {'not installed' if cpu is None else f'{cpu * 1e3:.1f}'} |")

    from gcs_planner.model.sites.dem import read_dem
    from gcs_planner.model.sites.geojson import read_geojson
    from gcs_planner.model.sites.kml import read_kml
    from gcs_planner.planning import load_scenario, plan_scenario
    from gcs_planner.safety.separation import check_plan

    swarm = ROOT / "missions" / f"{SCENARIOS[0]}.toml"
    with tempfile.TemporaryDirectory() as tmp:
        hgt = Path(tmp) / "N47E008.hgt"
        hgt.write_bytes(np.random.default_rng(1).integers(300, 900, (1201, 1201)).astype(">i2").tobytes())
        (Path(tmp) / "valley.kml").write_text(_kml_text())
        rows = [
            ("GeoJSON features (valley.geojson, 5 features)", lambda: read_geojson(SITE / "valley.geojson")),
            ("KML features (the same 5, stdlib reader)", lambda: read_kml(Path(tmp) / "valley.kml")),
            ("GeoTIFF DEM (valley_dem.tif, tifffile)", lambda: read_dem(SITE / "valley_dem.tif", "dem")),
            ("SRTM3 .hgt tile (1201 x 1201)", lambda: read_dem(hgt, "dem")),
            ("scenario with its site (features + DEM -> local frame)", lambda: load_scenario(swarm)),
        ]  # fmt: skip
        print("\n| read | CPU [ms] (best of 3) |")
        print("|---|---|")
        for label, fn in rows:
            cpu, _ = _cpu(fn)
            print(f"| {label} | {cpu * 1e3:.1f} |")

    print(
        "\n| scenario | planner | plan CPU [s] | check_plan CPU [s] | vehicles | feasible | site findings |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in SCENARIOS:
        scenario = load_scenario(ROOT / "missions" / f"{name}.toml")
        plan_cpu, plan = _cpu(lambda s=scenario: plan_scenario(s), runs=1)
        check_cpu, report = _cpu(lambda p=plan, s=scenario: check_plan(p, s), runs=1)
        findings = {
            k: getattr(report, k) for k in ("outside_area", "no_fly", "terrain") if getattr(report, k)
        }
        print(
            f"| {name} | {plan.planner} | {plan_cpu:.2f} | {check_cpu:.3f} | {len(plan.vehicles)} |"
            f" {plan.feasible} | {findings or 'none'} |"
        )


if __name__ == "__main__":
    main()
