"""CLI start-up: wall time from exec to the first useful work, against MAVProxy in the same run.

    python benchmarks/cli_startup.py --runs 15

Rows (each the median of ``--runs`` fresh interpreters): the bare interpreter, ``gcs-planner
--help``, ``import gcs_planner.cli`` plus the ``upload`` command's module (all an upload pays
before its first network wait), ``upload`` of a missing file (it fails before opening a socket),
and the peer: MAVProxy's ``mavproxy.py --help``. Then the heaviest imports of
``python -X importtime -c "import gcs_planner.cli"``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

PY = sys.executable
CASES = {
    "python -c pass": [PY, "-c", "pass"],
    "gcs-planner --help": [PY, "-m", "gcs_planner.cli", "--help"],
    "import cli + upload module": [PY, "-c", "import gcs_planner.cli, gcs_planner.commands.upload"],
    "gcs-planner upload (missing file)": [
        PY,
        "-m",
        "gcs_planner.cli",
        "upload",
        "--connect",
        "udpout:127.0.0.1:9",
        "--sysid",
        "1",
        "/missing.plan",
    ],  # fmt: skip
    "mavproxy.py --help (peer)": [PY, "-m", "MAVProxy.mavproxy", "--help"],
}


def _median_s(argv: list[str], runs: int) -> float:
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run(argv, capture_output=True, timeout=120)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _heaviest_imports(n: int) -> list[tuple[int, str]]:
    err = subprocess.run([PY, "-X", "importtime", "-c", "import gcs_planner.cli"], capture_output=True,
                         text=True).stderr  # fmt: skip
    rows = []
    for line in err.splitlines()[1:]:
        _, cumulative, name = (part.strip() for part in line.split("|"))
        if not name.startswith(" "):  # top level imports only
            rows.append((int(cumulative), name.strip()))
    return sorted(rows, reverse=True)[:n]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=15)
    args = ap.parse_args()
    results = {name: _median_s(argv, args.runs) for name, argv in CASES.items()}
    peer = results["mavproxy.py --help (peer)"]
    print(f"| command | median wall [s] ({args.runs} runs) | / MAVProxy --help |")
    print("|---|---|---|")
    for name, seconds in results.items():
        print(f"| {name} | {seconds:.3f} | {seconds / peer:.2f} |")
    print("\nheaviest top-level imports of `import gcs_planner.cli` (cumulative us):")
    for us, name in _heaviest_imports(8):
        print(f"  {us:>8d}  {name}")


if __name__ == "__main__":
    main()
