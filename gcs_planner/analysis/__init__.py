"""Analysis of results: the flight report and parameter sweeps."""
