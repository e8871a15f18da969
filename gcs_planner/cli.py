"""`gcs-planner`: one command, a subcommand per job; thin over the library.

Each subcommand lives in gcs_planner/commands/<name>.py with ``add_arguments(parser)`` and
``run(args) -> int``; a module docstring's first line is its help text. User mistakes
(UserError) print one line of bounded length and exit 2; no traceback.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from importlib import import_module

from gcs_planner import __version__
from gcs_planner.core.errors import UserError, one_line

# command -> its one-line help (the first line of its module's docstring, tested): `--help` lists
# them without importing every command
COMMANDS = {
    "plan": "Plan a scenario file and write plan.json.",
    "sweep": "Run a study: a scenario's planner over a grid of parameters and seeds, resumable, on processes or Dask.",
    "fly": "Plan a scenario and fly it: upload to every vehicle, arm, start, record, check conformance.",
    "fly-coalition": "Coalition HIL run: fly mock fixed wings and upload each coalition award to them in flight.",
    "demo": "Run the bundled demo: plan missions/swarm_small.toml and fly it against mock vehicles.",
    "replay": "Replay a flight log (MCAP) to Rerun (.rrd or a live viewer) or as MAVLink over UDP.",
    "watch": "Watch vehicles the tool did not start: log their telemetry to MCAP, optionally with live views.",
    "import-log": "Import a flight log into an MCAP flight log: .tlog, raw MAVLink, ArduPilot DataFlash, PX4 ULog.",
    "import-tlog": "Import a flight log into an MCAP flight log (the older name of `import-log`, kept as an alias).",
    "export": "Export plan.json as QGroundControl .plan or Mission Planner WPL files, one per vehicle.",
    "convert": "Convert a mission file: .plan, .mission, WPL 110 / 120 or a fence / rally list -> .plan or WPL.",
    "upload": "Upload a mission (plus fence and rally points) to one vehicle or many, and print what each accepted.",
    "download": "Download a vehicle's mission (and fence and rally points) and print it; optionally save it to FILE.",
    "clear": "Clear a vehicle's mission, fence or rally list (or all three) and confirm each was cleared.",
    "start": "Start a vehicle's mission: optionally upload FILE first, then arm and send MISSION_START.",
    "signing-setup": "Give a vehicle a MAVLink 2 signing key (SETUP_SIGNING), or turn its signing off, and check it took.",
    "params": "Get, set or diff a vehicle's parameters against a Mission Planner .param or QGroundControl .params file.",
}  # fmt: skip


class OneLineParser(argparse.ArgumentParser):
    """argparse with its usage errors on one line (``gcs-planner fly: error: ...``), exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser; ``only``: import just that command's module (the others are listed with their
    help line, without their arguments), so a short command does not pay for the others' imports."""
    parser = OneLineParser(prog="gcs-planner", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"gcs-planner {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, help_text in COMMANDS.items():
        if name != only:
            sub.add_parser(name, help=help_text)
            continue
        module = import_module(f"gcs_planner.commands.{name.replace('-', '_')}")
        p = sub.add_parser(name, help=help_text, description=module.__doc__)
        module.add_arguments(p)
        p.set_defaults(run=module.run)
    return parser


def _command_in(argv: list[str]) -> str | None:
    """The subcommand ``argv`` names (its first word that is not an option), if it is one."""
    words = [a for a in argv if not a.startswith("-")]
    return words[0] if words and words[0] in COMMANDS else None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        args = build_parser(_command_in(argv)).parse_args(argv)
    except SystemExit as exc:  # --help, --version (0) or a usage error already printed (2)
        return exc.code if isinstance(exc.code, int) else 2
    handler = logging.StreamHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    if not args.verbose:
        handler.addFilter(one_line_logs)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, handlers=[handler])
    try:
        return int(args.run(args) or 0)
    except UserError as exc:
        print(f"gcs-planner {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"gcs-planner {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `... | head`: the reader is gone; stop quietly as other CLI tools do
        _silence_stdout()
        return 141  # 128 + SIGPIPE, what a shell reports for a tool that died of it


def one_line_logs(record: logging.LogRecord) -> bool:
    """Log filter without --verbose: no tracebacks. A UserError logged on its way (a link subscriber
    that hit a duplicate sysid) is dropped, since the command reports it as its one error line;
    any other exception shrinks to one line (-v shows the traceback)."""
    if not record.exc_info or record.exc_info[1] is None:
        return True
    exc = record.exc_info[1]
    if isinstance(exc, UserError):
        return False
    text = str(exc).splitlines()[0][:200] if str(exc) else ""
    record.msg, record.args = f"{record.getMessage()}: {type(exc).__name__}: {text} (-v: traceback)", ()
    record.exc_info, record.exc_text, record.stack_info = None, None, None
    return True


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the flush at exit does not raise BrokenPipeError again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # no real file descriptor (captured in tests)
        pass


if __name__ == "__main__":
    sys.exit(main())
