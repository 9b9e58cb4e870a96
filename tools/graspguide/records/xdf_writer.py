"""A small writer of XDF files (Extensible Data Format 1.0, the format LabRecorder writes;
the specification: https://github.com/sccn/xdf/wiki/Specifications), standard library only.

Layout: the magic ``XDF:`` then chunks, each ``[NumLengthBytes][Length][Tag][Content]``:
NumLengthBytes is 1, 4 or 8 and says how wide the little-endian unsigned Length is;
Length counts the 2-byte Tag and the Content. Tags: FileHeader=1 (XML ``<info><version>
1.0</version>...``), StreamHeader=2 (uint32 stream id + XML ``<info>``), Samples=3 (stream
id, a variable-length sample count, then each sample: a timestamp byte 8 and a double, or
0 for a timestamp deduced from the previous one and the nominal rate, then the values
little-endian in the stream's channel_format; a string value is a variable-length byte
count then UTF-8), ClockOffset=4 (stream id, collection time, offset, doubles), Boundary=5
(a fixed 16-byte UUID, where a reader that met a damaged chunk resumes), StreamFooter=6
(stream id + XML with first_timestamp, last_timestamp, sample_count, clock_offsets).

Crash safety: every chunk is written whole with one append and handed to the operating
system at once (:func:`graspguide.records.storage.append_record`: a write the disk cut
short is cut back off the file). A killed run therefore leaves a file of whole chunks,
which pyxdf reads up to the last one (without footers: they come at :meth:`close`).
Samples are buffered per stream and written as a chunk every ``chunk_samples`` samples or
``chunk_s`` seconds, whichever comes first, so a kill loses at most that much. The file is
fsync'ed only at :meth:`close`: a power loss can lose what the OS had not written yet.

What pyxdf (1.17.5) does with a file whose *last* chunk is cut (a power loss, a copy cut
short): a cut Samples chunk or footer is dropped with a logged error and everything
before it is read -- except a cut inside the values of the chunk's *last* sample, which
pyxdf keeps with that sample's values partly the previous sample's bytes; a cut inside a
chunk's 2-byte tag, a StreamHeader's XML or a ClockOffset chunk makes ``load_xdf`` raise
(struct.error / ParseError). The chunk-whole appends above never leave such a file
behind a killed process.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import socket
import struct
import time
import uuid
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from graspguide.records.storage import RecordWriteError, append_record

MAGIC = b"XDF:"
TAG_FILE_HEADER = 1
TAG_STREAM_HEADER = 2
TAG_SAMPLES = 3
TAG_CLOCK_OFFSET = 4
TAG_BOUNDARY = 5
TAG_STREAM_FOOTER = 6
#: The Boundary chunk's content, fixed by the specification.
BOUNDARY_UUID = bytes.fromhex("43A546DCCBF5410FB30ED5467383CBE4")
#: channel_format -> the struct code of one value (strings are written apart).
NUMERIC_FORMATS = {"float32": "f", "double64": "d"}
CHANNEL_FORMATS = (*NUMERIC_FORMATS, "string")
FLOAT32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]

_HINT = " (or give another --record file)"


class XdfFormatError(ValueError):
    """A stream or sample the writer cannot put in the file; says what to fix."""


def varlen_int(n: int) -> bytes:
    """The specification's variable-length integer: a byte 1, 4 or 8 (the width), then
    ``n`` little-endian in that many bytes."""
    if n < 0:
        raise XdfFormatError(f"a length cannot be negative, got {n}")
    if n <= 0xFF:
        return b"\x01" + struct.pack("<B", n)
    if n <= 0xFFFFFFFF:
        return b"\x04" + struct.pack("<I", n)
    return b"\x08" + struct.pack("<Q", n)


def chunk(tag: int, content: bytes) -> bytes:
    """One whole chunk: the length (of tag and content), the tag, the content."""
    return varlen_int(2 + len(content)) + struct.pack("<H", tag) + content


def _append_xml(parent: ET.Element, key: str, value: Any) -> None:
    """``value`` under ``parent`` as ``<key>``: a mapping nests, a list repeats the key,
    anything else is text (floats as repr, so they read back exactly)."""
    if isinstance(value, (list, tuple)):
        for item in value:
            _append_xml(parent, key, item)
        return
    el = ET.SubElement(parent, key)
    if isinstance(value, Mapping):
        for k, v in value.items():
            _append_xml(el, str(k), v)
    elif isinstance(value, bool):
        el.text = "true" if value else "false"
    elif isinstance(value, float):
        el.text = repr(value)
    elif value is not None:
        el.text = str(value)


def _xml(root: ET.Element) -> bytes:
    return b'<?xml version="1.0"?>' + ET.tostring(root, encoding="utf-8", xml_declaration=False)


@dataclass(frozen=True)
class Channel:
    """One channel's description (``<desc><channels><channel>``)."""

    label: str
    unit: str = ""
    type: str = ""


@dataclass
class _Stream:
    stream_id: int
    name: str
    channel_count: int
    channel_format: str
    nominal_srate: float
    pending_t: list[float | None] = field(default_factory=list)
    pending_v: list[Sequence[Any]] = field(default_factory=list)
    first_timestamp: float | None = None
    last_timestamp: float | None = None
    sample_count: int = 0
    clock_offsets: list[tuple[float, float]] = field(default_factory=list)
    footer_written: bool = False


class XdfWriter:
    """Writes one XDF file: :meth:`add_stream`, then :meth:`push` (buffered) or
    :meth:`write_samples` (one chunk at once), :meth:`close` (the rest, the footers).

    The file must not exist (a recording is never overwritten). ``header`` adds elements
    to the FileHeader's ``<info>`` (``version`` 1.0 and ``datetime`` are always there).
    Raises RecordWriteError (an OSError naming the file) when the disk refuses a chunk;
    the file then holds only whole chunks."""

    def __init__(
        self,
        path: str,
        *,
        header: Mapping[str, Any] | None = None,
        chunk_samples: int = 100,
        chunk_s: float = 0.5,
        boundary_s: float = 10.0,
    ):
        self.path = path
        self.chunk_samples = max(1, int(chunk_samples))
        self.chunk_s = float(chunk_s)
        self.boundary_s = float(boundary_s)
        self.streams: dict[int, _Stream] = {}
        self.fd = -1
        try:
            self.fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError as e:
            err = RecordWriteError(path, e)
            err.message = (
                f"cannot write {path}: it exists and a recording is never overwritten; "
                "give a new file name or move the old file away"
            )
            raise err from None
        except OSError as e:
            raise RecordWriteError(path, e, _HINT) from e
        info = ET.Element("info")
        ET.SubElement(info, "version").text = "1.0"
        now = _dt.datetime.now(_dt.UTC).astimezone()
        ET.SubElement(info, "datetime").text = now.isoformat(timespec="seconds")
        for key, value in (header or {}).items():
            _append_xml(info, str(key), value)
        self._write(MAGIC + chunk(TAG_FILE_HEADER, _xml(info)))
        self._last_chunk = self._last_boundary = time.monotonic()

    # ---- streams
    def add_stream(
        self,
        name: str,
        type: str,
        channels: Sequence[Channel | str],
        channel_format: str = "float32",
        nominal_srate: float = 0.0,
        *,
        source_id: str = "",
        created_at: float = 0.0,
        desc: Mapping[str, Any] | None = None,
    ) -> int:
        """A new stream's header, written now; returns its stream id (1, 2, ...).
        ``nominal_srate`` 0 means irregular. ``desc`` adds elements after
        ``<channels>`` in ``<desc>`` (mappings nest, lists repeat)."""
        if channel_format not in CHANNEL_FORMATS:
            raise XdfFormatError(
                f"stream {name!r}: channel_format must be one of "
                f"{', '.join(CHANNEL_FORMATS)}, got {channel_format!r}"
            )
        if not channels:
            raise XdfFormatError(f"stream {name!r}: give at least one channel")
        if not (math.isfinite(nominal_srate) and nominal_srate >= 0):
            raise XdfFormatError(
                f"stream {name!r}: nominal_srate must be >= 0 (0: irregular), got {nominal_srate}"
            )
        chans = [c if isinstance(c, Channel) else Channel(str(c)) for c in channels]
        stream_id = len(self.streams) + 1
        info = ET.Element("info")
        for key, value in (
            ("name", name),
            ("type", type),
            ("channel_count", len(chans)),
            ("nominal_srate", float(nominal_srate)),
            ("channel_format", channel_format),
            ("source_id", source_id),
            ("version", 1.1),
            ("created_at", float(created_at)),
            ("uid", str(uuid.uuid4())),
            ("session_id", "default"),
            ("hostname", socket.gethostname()),
        ):
            _append_xml(info, key, value)
        desc_el = ET.SubElement(info, "desc")
        chans_el = ET.SubElement(desc_el, "channels")
        for c in chans:
            _append_xml(chans_el, "channel", {"label": c.label, "unit": c.unit, "type": c.type})
        for key, value in (desc or {}).items():
            _append_xml(desc_el, str(key), value)
        self._write(chunk(TAG_STREAM_HEADER, struct.pack("<I", stream_id) + _xml(info)))
        self.streams[stream_id] = _Stream(
            stream_id, name, len(chans), channel_format, float(nominal_srate)
        )
        return stream_id

    def _stream(self, stream_id: int) -> _Stream:
        try:
            s = self.streams[stream_id]
        except KeyError:
            raise XdfFormatError(
                f"no stream {stream_id} in {self.path} (add_stream first)"
            ) from None
        if s.footer_written:
            raise XdfFormatError(f"stream {s.name!r} of {self.path} is closed")
        return s

    # ---- samples
    def push(self, stream_id: int, timestamp: float | None, values: Sequence[Any]) -> None:
        """One sample, buffered; its stream's chunk is written when ``chunk_samples``
        are buffered or ``chunk_s`` passed since the last chunk. ``timestamp`` None: deduced
        from the one before and the nominal rate (a regular stream only)."""
        s = self._stream(stream_id)
        s.pending_v.append(self._check(s, timestamp, values))
        s.pending_t.append(timestamp)
        if len(s.pending_t) >= self.chunk_samples:
            self._flush_stream(s)
        elif time.monotonic() - self._last_chunk >= self.chunk_s:
            self.flush()

    def write_samples(
        self,
        stream_id: int,
        timestamps: Sequence[float | None],
        samples: Sequence[Sequence[Any]],
    ) -> None:
        """The samples as one Samples chunk now (after any buffered ones of the stream)."""
        s = self._stream(stream_id)
        if len(timestamps) != len(samples):
            raise XdfFormatError(
                f"stream {s.name!r}: {len(timestamps)} timestamps for {len(samples)} samples"
            )
        checked = [self._check(s, t, v) for t, v in zip(timestamps, samples)]
        self._flush_stream(s)
        s.pending_t, s.pending_v = list(timestamps), checked
        self._flush_stream(s)

    def _check(self, s: _Stream, timestamp: float | None, values: Sequence[Any]) -> list[Any]:
        """The sample's values as the stream's format takes them, or XdfFormatError."""
        if len(values) != s.channel_count:
            raise XdfFormatError(
                f"stream {s.name!r} has {s.channel_count} channels, a sample gave {len(values)}"
            )
        if timestamp is None and s.nominal_srate <= 0:
            raise XdfFormatError(
                f"stream {s.name!r} is irregular (nominal_srate 0): every sample needs a timestamp"
            )
        if s.channel_format == "string":
            return [str(v) for v in values]
        try:
            floats = [float(v) for v in values]
        except (TypeError, ValueError):
            raise XdfFormatError(
                f"stream {s.name!r} ({s.channel_format}): a sample's values are not "
                f"numbers: {list(values)}"
            ) from None
        if s.channel_format == "float32" and any(
            math.isfinite(v) and abs(v) > FLOAT32_MAX for v in floats
        ):
            raise XdfFormatError(
                f"stream {s.name!r} is float32: a value is beyond its range "
                f"(+-{FLOAT32_MAX:.4g}): {floats}; use double64"
            )
        return floats

    def _flush_stream(self, s: _Stream) -> None:
        if not s.pending_t:
            return
        times, values = s.pending_t, s.pending_v
        parts = [struct.pack("<I", s.stream_id), varlen_int(len(times))]
        code = NUMERIC_FORMATS.get(s.channel_format)
        pack = struct.Struct(f"<{s.channel_count}{code}").pack if code else None
        last = s.last_timestamp
        for t, v in zip(times, values):
            if t is None:
                parts.append(b"\x00")
                t = (0.0 if last is None else last) + 1.0 / s.nominal_srate
            else:
                parts.append(b"\x08" + struct.pack("<d", t))
            if pack is not None:
                parts.append(pack(*v))
            else:
                for text in v:
                    raw = text.encode("utf-8")
                    parts.append(varlen_int(len(raw)) + raw)
            last = float(t)
        self._write(chunk(TAG_SAMPLES, b"".join(parts)))
        if s.first_timestamp is None:
            first = times[0]
            s.first_timestamp = (
                float(first)
                if first is not None
                else (0.0 if s.last_timestamp is None else s.last_timestamp) + 1.0 / s.nominal_srate
            )
        s.last_timestamp = last
        s.sample_count += len(times)
        s.pending_t, s.pending_v = [], []
        self._last_chunk = time.monotonic()
        if self._last_chunk - self._last_boundary >= self.boundary_s:
            self.write_boundary()

    def flush(self) -> None:
        """Every stream's buffered samples, as chunks now."""
        for s in self.streams.values():
            if not s.footer_written:
                self._flush_stream(s)

    # ---- the other chunks
    def write_clock_offset(self, stream_id: int, collection_time: float, offset: float) -> None:
        """A ClockOffset chunk: at ``collection_time`` (the recorder's clock) the stream's
        clock was ``offset`` seconds behind it (a reader adds the offset)."""
        s = self._stream(stream_id)
        self._write(
            chunk(
                TAG_CLOCK_OFFSET,
                struct.pack("<Idd", stream_id, float(collection_time), float(offset)),
            )
        )
        s.clock_offsets.append((float(collection_time), float(offset)))

    def write_boundary(self) -> None:
        self._write(chunk(TAG_BOUNDARY, BOUNDARY_UUID))
        self._last_boundary = time.monotonic()

    def close_stream(self, stream_id: int) -> None:
        """The stream's buffered samples, then its footer; no samples after it."""
        s = self._stream(stream_id)
        self._flush_stream(s)
        info = ET.Element("info")
        if s.first_timestamp is not None:
            _append_xml(info, "first_timestamp", s.first_timestamp)
            _append_xml(info, "last_timestamp", s.last_timestamp)
        _append_xml(info, "sample_count", s.sample_count)
        offsets = ET.SubElement(info, "clock_offsets")
        for t, v in s.clock_offsets:
            _append_xml(offsets, "offset", {"time": t, "value": v})
        self._write(chunk(TAG_STREAM_FOOTER, struct.pack("<I", s.stream_id) + _xml(info)))
        s.footer_written = True

    def close(self) -> None:
        """Every open stream's samples and footer, then the file is synced and closed."""
        if self.fd < 0:
            return
        try:
            for stream_id, s in self.streams.items():
                if not s.footer_written:
                    self.close_stream(stream_id)
            try:
                os.fsync(self.fd)
            except OSError as e:
                raise RecordWriteError(self.path, e, _HINT) from e
        finally:
            fd, self.fd = self.fd, -1
            os.close(fd)

    def __enter__(self) -> XdfWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _write(self, data: bytes) -> None:
        if self.fd < 0:
            raise XdfFormatError(f"{self.path} is closed")
        append_record(self.fd, self.path, data, False, _HINT)


__all__ = [
    "XdfWriter",
    "XdfFormatError",
    "Channel",
    "CHANNEL_FORMATS",
    "BOUNDARY_UUID",
    "varlen_int",
    "chunk",
]
