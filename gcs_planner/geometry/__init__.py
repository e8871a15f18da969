"""Geometry shared by the planners: Dubins paths, obstacles, time-parametrised separation checks."""
