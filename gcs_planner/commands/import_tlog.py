"""Import a flight log into an MCAP flight log (the older name of `import-log`, kept as an alias)."""

from gcs_planner.commands.import_log import add_arguments, run

__all__ = ["add_arguments", "run"]
