"""Count what mutated inputs do to every CLI reader: exit codes, tracebacks, multi-line errors, leftovers.

    PYTHONPATH=tests python benchmarks/input_fuzz.py --n 4000 --seed 1

Each input comes from tests/input_mutations.py (mutated scenario TOML, plan.json, .tlog, MCAP and
CLI flag values) and runs through ``gcs_planner.cli.main`` in-process, with the flight itself
stubbed out (the checks `fly` makes before it sends still run). Prints one row per reader and
the first few distinct problems; exits 1 when any input broke a rule.
"""

from __future__ import annotations

import argparse
import logging
import random
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path
from unittest import mock

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import input_mutations as im  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4000, help="mutated inputs in all [4000]")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--show", type=int, default=15, help="distinct problems to print [15]")
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
                outcome = im.run_case(argv, folder)
                row = rows[name]
                row["inputs"] += 1
                row[f"exit {outcome.code}" if outcome.exception is None else "traceback"] += 1
                for problem in im.problems(outcome):
                    kind = problem.split(":")[0].split(" ")[0]
                    row[{"traceback": "traceback!", "exit": "bad exit"}.get(kind, kind)] += 1
                    key = f"{name}: {problem[:160]}"
                    seen.setdefault(key, argv)
                shutil.rmtree(folder, ignore_errors=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    cols = ["inputs", "exit 0", "exit 2", "traceback", "bad exit", "stderr", "left", "1", "2"]
    labels = ["inputs", "exit 0", "exit 2", "traceback", "other exit", "multi-line", "leftover", "", ""]
    print(f"{'reader':<22}" + "".join(f"{h:>11}" for h in labels[:7]))
    total = Counter()
    for name, row in rows.items():
        total.update(row)
        print(f"{name:<22}" + "".join(f"{row[c]:>11}" for c in cols[:7]))
    print(f"{'all':<22}" + "".join(f"{total[c]:>11}" for c in cols[:7]))
    for key in list(seen)[: args.show]:
        print(f"- {key}")
    broken = total["traceback"] + total["bad exit"] + total["stderr"] + total["left"]
    print(f"{len(seen)} distinct problems; {broken} rule breaks in {total['inputs']} inputs")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
