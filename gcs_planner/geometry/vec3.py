"""3-vectors as tuples of floats, for compiled (numba) loops: no array allocated per vector."""

from __future__ import annotations

from gcs_planner.core.compiled import compiled

__all__ = ["add", "along", "dot", "dot_xzy", "row", "scale", "sub", "times_each"]


@compiled
def row(points, i: int) -> tuple:
    """Row i of an (n, 3) array as a 3-vector."""
    return (points[i, 0], points[i, 1], points[i, 2])


@compiled
def dot(a: tuple, b: tuple) -> float:
    """a . b, summed x + y + z in order (the vectorised code's order, for the same bits)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@compiled
def dot_xzy(a: tuple, b: tuple) -> float:
    """a . b summed (x + z) + y: the order of the numpy einsum the 4-D planner's closest approach
    used before it was compiled, so its plans kept their bits."""
    return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]


@compiled
def add(a: tuple, b: tuple) -> tuple:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@compiled
def sub(a: tuple, b: tuple) -> tuple:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@compiled
def scale(a: tuple, s: float) -> tuple:
    return (a[0] * s, a[1] * s, a[2] * s)


@compiled
def along(p: tuple, s: float, q: tuple) -> tuple:
    """p + s q."""
    return (p[0] + s * q[0], p[1] + s * q[1], p[2] + s * q[2])


@compiled
def times_each(a: tuple, b: tuple) -> tuple:
    """a * b axis by axis."""
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])
