"""Core: errors, geodesy, fleet ids, input reading and atomic writes, typed configs, the clock.

The bottom layer: it imports nothing else of gcs_planner."""
