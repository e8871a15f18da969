"""Subcommands of `gcs-planner` (see gcs_planner.cli)."""
