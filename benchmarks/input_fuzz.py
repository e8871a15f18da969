"""Count what mutated inputs do to every CLI reader: exit codes, tracebacks, multi-line errors, leftovers.

    PYTHONPATH=tests python benchmarks/input_fuzz.py --n 4000 --seed 1

Each input comes from tests/input_mutations.py (mutated scenario TOML and its world tables,
plan.json, .tlog, MCAP, CLI flag values, study TOML and cut or garbled sweep CSVs to resume) and
runs through ``gcs_planner.cli.main`` in-process, with the flight itself stubbed out (the checks
`fly` makes before it sends still run). Prints one row per reader and the first few distinct
problems; exits 1 when any input broke a rule.
"""

from __future__ import annotations

import argparse
import logging
import random
import shutil
import signal
import sys
import tempfile
from collections import Counter
from pathlib import Path
from unittest import mock

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import input_mutations as im  # noqa: E402


class Hang(BaseException):
    """An input that kept one command busy for --hang-after seconds."""


def _hang(signum, frame):
    raise Hang()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4000, help="mutated inputs in all [4000]")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--show", type=int, default=15, help="distinct problems to print [15]")
    ap.add_argument("--hang-after", type=int, default=20, help="seconds before an input counts as a hang")
    args = ap.parse_args()
    logging.disable(logging.CRITICAL)
    rng = random.Random(args.seed)
    rows: dict[str, Counter] = {name: Counter() for name in im.CASES}
    seen: dict[str, list[str]] = {}
    root = Path(tempfile.mkdtemp(prefix="input-fuzz-"))
    try:
        with mock.patch("gcs_planner.commands.fly.fly", im.stub_fly):
            for i in range(args.n):
                name = list(im.CASES)[i % len(im.CASES)]
                folder = root / str(i)
                folder.mkdir()
                argv = im.CASES[name](rng, folder)
                signal.signal(signal.SIGALRM, _hang)
                signal.alarm(args.hang_after)
                try:
                    outcome = im.run_case(argv, folder)
                finally:
                    signal.alarm(0)
                row = rows[name]
                row["inputs"] += 1
                row[f"exit {outcome.code}" if outcome.exception is None else "traceback"] += 1
                if outcome.exception and "Hang" in outcome.exception.strip().splitlines()[-1]:
                    row["hang"] += 1
                for problem in im.problems(outcome):
                    kind = next(
                        k for k in ("traceback", "exit code", "stderr lines", "left behind") if k in problem
                    )
                    row[
                        {
                            "traceback": "counted",
                            "exit code": "bad exit",
                            "stderr lines": "stderr",
                            "left behind": "left",
                        }.get(kind, kind)
                    ] += 1
                    key = f"{name}: {problem[:160]}"
                    seen.setdefault(key, argv)
                shutil.rmtree(folder, ignore_errors=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    cols = ["inputs", "exit 0", "exit 2", "traceback", "hang", "bad exit", "stderr", "left"]
    labels = [
        "inputs",
        "exit 0",
        "exit 2",
        "traceback",
        "(of which hang)",
        "other exit",
        "multi-line",
        "leftover",
    ]
    print(f"{'reader':<22}" + "".join(f"{h:>11}" for h in labels))
    total = Counter()
    for name, row in rows.items():
        total.update(row)
        print(f"{name:<22}" + "".join(f"{row[c]:>11}" for c in cols))
    print(f"{'all':<22}" + "".join(f"{total[c]:>11}" for c in cols))
    for key in list(seen)[: args.show]:
        print(f"- {key}")
    broken = total["traceback"] + total["bad exit"] + total["stderr"] + total["left"]  # per input and kind
    print(f"{len(seen)} distinct problems; {broken} rule breaks in {total['inputs']} inputs")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
