"""Base error for mistakes a user can fix (bad file, bad argument, vehicle said no).

The CLI prints these as one line of at most MAX_ERROR_CHARS characters (see :func:`one_line`)
and exits non-zero, without a traceback.
"""

from typing import Any

MAX_ERROR_CHARS = 500  # an error line: a 100k-vehicle list in a message must not print 300 KB
MAX_VALUE_CHARS = 200  # a value quoted in an error message


class UserError(Exception):
    """An error caused by input or by a vehicle's answer, reported as one clear line."""


def shorten(value: Any, limit: int = MAX_VALUE_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters (with ``...``), for quoting values in errors."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def one_line(text: str, limit: int = MAX_ERROR_CHARS) -> str:
    """``text`` as one line (line breaks become spaces) of at most about ``limit`` characters: a
    longer one keeps its start and says how long it was."""
    text = " ".join(text.split())
    if len(text) <= limit:
        return text
    return f"{text[: limit - 40]}... ({len(text):,} characters in all)"
