"""Whole STATUSTEXTs from their chunks: an autopilot's words, never a fragment of them.

A text longer than one STATUSTEXT's 50 characters is sent as chunks that share a non-zero ``id``
and count up ``chunk_seq``; the last chunk is the one shorter than 50 characters (the MAVLink
common.xml STATUSTEXT definition; PX4 splits long texts this way, mavlink_messages.cpp). A text
with ``id`` 0 stands alone. A chunk that does not follow its predecessor (a lost chunk) drops the
text: a text is whole or not shown, never a fragment or two texts glued together. At most
MAX_OPEN texts wait for their next chunk, the one waiting longest dropped first: first chunks that
never finish, from any number of senders and ids, cannot fill the memory.
"""

from __future__ import annotations

__all__ = ["CHUNK_CHARS", "MAX_OPEN", "TextAssembler", "text_of"]

CHUNK_CHARS = 50
MAX_OPEN = 64  # unfinished texts kept (chunk_seq is a uint8: each at most 256 x 50 characters)


def text_of(msg) -> str:
    """The characters of one STATUSTEXT chunk (padding removed)."""
    text = msg.text
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    return text.split("\x00", 1)[0]


class TextAssembler:
    """Feed STATUSTEXT messages of any sender; ``feed`` returns each text once it is whole."""

    def __init__(self) -> None:
        self._open: dict[tuple[int, int, int], tuple[int, list[str]]] = {}  # (sys, comp, id) -> (seq, parts)

    def feed(self, msg) -> str | None:
        part = text_of(msg)
        text_id = getattr(msg, "id", 0) or 0
        if text_id == 0:
            return part
        key = (msg.get_srcSystem(), msg.get_srcComponent(), text_id)
        seq = getattr(msg, "chunk_seq", 0) or 0
        last_seq, parts = self._open.pop(key, (-1, []))
        if seq == 0:
            parts = [part]
        elif seq == last_seq + 1:
            parts = [*parts, part]
        else:
            return None
        if len(part) < CHUNK_CHARS:
            return "".join(parts)
        self._open[key] = (seq, parts)  # re-inserted: the dict's first key waited longest
        if len(self._open) > MAX_OPEN:
            del self._open[next(iter(self._open))]
        return None
