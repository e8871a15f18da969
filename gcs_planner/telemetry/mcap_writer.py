"""A small chunked MCAP writer built for many small messages (MAVLink telemetry).

Why not ``mcap.writer.Writer`` directly: its ``add_message`` builds a record object and a
message index entry per message (about 5 us each); a flight log writes two or three records per
MAVLink frame, so the stock writer alone would cap logging near 60,000 records/s. Here messages
are packed straight into the open chunk with one ``struct`` call, and the rest of the file
(header, schemas, channels, attachments, metadata, summary, footer) is serialised by the mcap
package's own record classes, so the layout is standard MCAP that any reader opens.

Choices:
- Schemas and channels are written in the data section *before* the chunk that first uses them,
  never inside chunks, and repeated in the summary. A sequential reader of a truncated file
  therefore knows every channel of every complete chunk.
- Message index records after every chunk (one per channel: each message's log time and offset
  in the chunk), found by walking the chunk's records once at flush, not per message on the hot
  path: Foxglove's reader (@mcap/core, McapIndexedReader) refuses a chunk index without them
  ("Encountered a chunk index without message indexes"), so every finished log carries them.
- ``flush()`` closes the open chunk, compresses it (zstd) and writes it together with every
  record added since the last flush, followed by a *provisional end*: Data End, a Footer without
  summary (``summary_start`` 0) and the closing magic. Between flushes nothing is written, so the
  file on disk is always a complete, valid MCAP stream without summary, and a SIGKILLed writer
  leaves a file that the stock ``mcap.reader.make_reader(f).iter_messages()`` reads to the last
  flush (its seeking reader finds the footer, sees no summary and reads the stream linearly). The
  next flush writes over that provisional end (``_commit``): first the new provisional end at its
  final place, then the records past the old end's length, then its bytes, so that the file stays
  valid between the writes (a linear reader stops at the old footer, one flush earlier).
  ``finish()`` replaces it with the real summary.
  A stream that cannot seek (a pipe) is written append-only, without provisional end.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections import defaultdict
from pathlib import Path
from typing import IO

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import MCAP0_MAGIC

__all__ = ["MESSAGE_FIXED_LEN", "MESSAGE_HEADER", "MESSAGE_OPCODE", "ChunkedMcapWriter"]

# A Message record is MESSAGE_HEADER.pack(MESSAGE_OPCODE, MESSAGE_FIXED_LEN + len(data), channel,
# sequence, log_time_ns, publish_time_ns) followed by data (see add_packed).
MESSAGE_HEADER = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
MESSAGE_FIXED_LEN = 2 + 4 + 8 + 8
MESSAGE_OPCODE = int(Opcode.MESSAGE)


class ChunkedMcapWriter:
    """MCAP writer: integer-ns timestamps, output a path or a binary stream (closed only if opened).

    zstd_level: compression level of chunks (3 is zstd's default; higher trades CPU for size).
    """

    def __init__(self, output: str | Path | IO[bytes], zstd_level: int = 3, library: str = "") -> None:
        if isinstance(output, str | Path):
            # unbuffered: every byte goes out in _commit's writes, in the order that keeps the file valid
            self._stream: IO[bytes] = open(output, "wb", buffering=0)  # noqa: SIM115 - closed in finish()
            self._owns_stream = True
        else:
            self._stream = output
            self._owns_stream = False
        try:
            self._seekable = bool(self._stream.seekable())
        except (AttributeError, OSError, ValueError):
            self._seekable = False
        self._base = self._stream.tell() if self._seekable else 0  # where this MCAP starts in the stream
        self._offset = 0  # MCAP offset of the next record (records not yet committed included)
        self._pending = bytearray()  # records added since the last commit, not yet in the stream
        self._tail_len = 0  # length of the provisional end in the stream after the committed bytes
        self._compressor = zstandard.ZstdCompressor(level=zstd_level)
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk = bytearray()
        self._chunk_start_ns = 0
        self._chunk_end_ns = 0
        self._chunk_messages = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = defaultdict(int)
        self._message_count = 0
        self._start_ns: int | None = None
        self._end_ns = 0
        self._finished = False
        self._write(MCAP0_MAGIC)
        self._write_record(Header(profile="", library=library))

    # -- definitions -----------------------------------------------------------------------------
    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Add a schema (e.g. encoding "jsonschema"); returns its id (>= 1)."""
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._write_record(schema)
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str] | None = None
    ) -> int:
        """Add a channel (schema_id 0 = schemaless); returns its id (>= 1)."""
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels.append(channel)
        self._write_record(channel)
        return channel.id

    # -- messages --------------------------------------------------------------------------------
    def add_message(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        """Append one message to the open chunk (publish time = log time)."""
        self.add_messages([(channel_id, log_time_ns, data)])

    def add_messages(self, rows: list[tuple[int, int, bytes]]) -> None:
        """Append (channel id, log time [ns], data) rows to the open chunk, in the given order."""
        if not rows:
            return
        pack = MESSAGE_HEADER.pack
        buckets: dict[int, list[bytes]] = {}
        for channel_id, t_ns, data in rows:
            bucket = buckets.setdefault(channel_id, [])
            bucket.append(pack(MESSAGE_OPCODE, MESSAGE_FIXED_LEN + len(data), channel_id, 0, t_ns, t_ns))
            bucket.append(data)
        self.add_packed(buckets, min(row[1] for row in rows), max(row[1] for row in rows))

    def add_packed(self, buckets: dict[int, list[bytes]], start_ns: int, end_ns: int) -> None:
        """Append packed message records: per channel id a list alternating header, data.

        The hot-path form of add_messages: callers pack headers with MESSAGE_HEADER; start_ns and
        end_ns bound the log times of these records.
        """
        chunk = self._chunk
        counts = self._counts
        n = 0
        for channel_id, parts in buckets.items():
            chunk += b"".join(parts)
            counts[channel_id] += len(parts) // 2
            n += len(parts) // 2
        if n == 0:
            return
        if self._chunk_messages == 0:
            self._chunk_start_ns, self._chunk_end_ns = start_ns, end_ns
        else:
            self._chunk_start_ns = min(self._chunk_start_ns, start_ns)
            self._chunk_end_ns = max(self._chunk_end_ns, end_ns)
        self._chunk_messages += n

    @property
    def chunk_bytes(self) -> int:
        """Uncompressed size of the open chunk [bytes]."""
        return len(self._chunk)

    @property
    def message_count(self) -> int:
        return self._message_count + self._chunk_messages

    def flush(self) -> None:
        """Close the open chunk (if it has messages), write it compressed, flush the stream."""
        if self._chunk_messages:
            data = bytes(self._chunk)
            compressed = self._compressor.compress(data)
            chunk = Chunk(
                compression="zstd",
                data=compressed,
                message_start_time=self._chunk_start_ns,
                message_end_time=self._chunk_end_ns,
                uncompressed_crc=zlib.crc32(data),
                uncompressed_size=len(data),
            )
            start = self._offset
            length = self._write_record(chunk)
            index_start = self._offset
            offsets = {}
            for channel_id, records in _message_index(data).items():
                offsets[channel_id] = self._offset
                self._write_record(MessageIndex(channel_id=channel_id, records=records))
            self._chunk_indexes.append(
                ChunkIndex(
                    message_start_time=self._chunk_start_ns,
                    message_end_time=self._chunk_end_ns,
                    chunk_start_offset=start,
                    chunk_length=length,
                    message_index_offsets=offsets,
                    message_index_length=self._offset - index_start,
                    compression="zstd",
                    compressed_size=len(compressed),
                    uncompressed_size=len(data),
                )
            )
            if self._start_ns is None or self._chunk_start_ns < self._start_ns:
                self._start_ns = self._chunk_start_ns
            self._end_ns = max(self._end_ns, self._chunk_end_ns)
            self._message_count += self._chunk_messages
            self._chunk = bytearray()
            self._chunk_messages = 0
        self._commit(_PROVISIONAL_END if self._seekable else b"")

    # -- attachments and metadata ----------------------------------------------------------------
    def add_attachment(self, name: str, media_type: str, data: bytes, log_time_ns: int) -> None:
        attachment = Attachment(
            create_time=log_time_ns, log_time=log_time_ns, name=name, media_type=media_type, data=data
        )
        offset = self._offset
        length = self._write_record(attachment)
        self._attachment_indexes.append(
            AttachmentIndex(
                offset=offset,
                length=length,
                log_time=log_time_ns,
                create_time=log_time_ns,
                data_size=len(data),
                name=name,
                media_type=media_type,
            )
        )

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Add a metadata record; values must be strings (use JSON for structure)."""
        data = {k: v if isinstance(v, str) else json.dumps(v) for k, v in data.items()}
        offset = self._offset
        length = self._write_record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    # -- end -------------------------------------------------------------------------------------
    def finish(self) -> None:
        """Write the last chunk, the summary section and the footer; close an owned stream."""
        if self._finished:
            return
        self._finished = True
        self.flush()
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._offset
        summary = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: int, records: list) -> None:
            if not records:
                return
            begin = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(opcode, summary_start + begin, summary.count - begin))

        stats = Statistics(
            attachment_count=len(self._attachment_indexes),
            channel_count=len(self._channels),
            channel_message_counts=dict(self._counts),
            chunk_count=len(self._chunk_indexes),
            message_count=self._message_count,
            message_end_time=self._end_ns,
            message_start_time=self._start_ns or 0,
            metadata_count=len(self._metadata_indexes),
            schema_count=len(self._schemas),
        )
        group(Opcode.SCHEMA, self._schemas)
        group(Opcode.CHANNEL, self._channels)
        group(Opcode.STATISTICS, [stats])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, self._attachment_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        summary_data = summary.end()
        footer_prefix = struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start)
        crc = zlib.crc32(footer_prefix, zlib.crc32(summary_data))
        self._write(summary_data)
        self._write_record(
            Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc)
        )
        self._write(MCAP0_MAGIC)
        self._commit(b"")
        if self._owns_stream:
            self._stream.close()

    def _commit(self, tail: bytes) -> None:
        """Write the pending records followed by ``tail`` (the provisional end, or nothing) over the
        previous provisional end, and flush the stream.

        Order: the new provisional end at its final place first (a small write), then the records
        beyond the old end's length, then the first ``_tail_len`` bytes over the old end. The file
        always ends in a provisional end, and until the last write the old one still stands whole,
        so a reader sees a valid file (up to the previous flush) whichever write a SIGKILL cuts:
        a large write can be cut part way (seen once in five loaded runs with the old order, which
        wrote the records and the new end in one write)."""
        if not self._pending and self._tail_len == len(tail):
            return  # nothing new: the file on disk already ends this way
        blob = bytes(self._pending) + tail
        self._pending = bytearray()
        if not self._seekable:
            self._stream.write(blob)
            self._stream.flush()
            return
        start = self._base + self._offset - len(blob) + len(tail)  # where the pending records begin
        old = self._tail_len
        if old and len(blob) - len(tail) >= old:
            end = len(blob) - len(tail)
            self._write_at(start + end, blob[end:])  # 1. the new end first: the file's last bytes
            self._write_at(start + old, blob[old:end])  # 2. the records behind the old end
            self._write_at(start, blob[:old])  # 3. over the old end: the records join up
        elif blob:
            self._write_at(start, blob)
        self._tail_len = len(tail)

    def _write_at(self, position: int, data: bytes) -> None:
        """Write ``data`` at ``position`` and push it to the OS before the next step."""
        self._stream.seek(position)
        view = memoryview(data)
        while view:
            n = self._stream.write(view)
            if n is None:  # a non-blocking raw stream that took nothing: try again
                continue
            view = view[n:]
        self._stream.flush()

    def _write_record(self, record) -> int:
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        self._write(data)
        return len(data)

    def _write(self, data: bytes) -> None:
        self._pending += data
        self._offset += len(data)


_RECORD_START = struct.Struct("<BQH4xQ")  # opcode, length, channel, (sequence), log time


def _message_index(chunk: bytes) -> dict[int, list[tuple[int, int]]]:
    """Per channel, (log time, offset) of each Message record in an uncompressed chunk."""
    index: dict[int, list[tuple[int, int]]] = defaultdict(list)
    unpack, offset, end = _RECORD_START.unpack_from, 0, len(chunk)
    while offset < end:
        opcode, length, channel_id, log_time = unpack(chunk, offset)
        if opcode == MESSAGE_OPCODE:
            index[channel_id].append((log_time, offset))
        offset += 9 + length
    return index


def _provisional_end() -> bytes:
    """Data End, a Footer without summary and the magic: the end of a valid summary-less MCAP."""
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC


_PROVISIONAL_END = _provisional_end()
