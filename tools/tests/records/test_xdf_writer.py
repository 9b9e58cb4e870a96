"""The XDF writer against the specification (https://github.com/sccn/xdf/wiki/Specifications)
and against pyxdf, the independent reader: every stream, label, unit, timestamp and value
read back exactly, the footers, the bytes of small chunks laid out by hand, and a
recording killed mid-way."""

from __future__ import annotations

import logging
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import pyxdf

from graspguide.records.storage import RecordWriteError
from graspguide.records.xdf_writer import Channel, XdfFormatError, XdfWriter, varlen_int

# The Boundary chunk's UUID as the specification prints it.
SPEC_BOUNDARY = bytes(
    [0x43, 0xA5, 0x46, 0xDC, 0xCB, 0xF5, 0x41, 0x0F, 0xB3, 0x0E, 0xD5, 0x46, 0x73, 0x83, 0xCB, 0xE4]
)


def first(d, *keys):
    """pyxdf's nested lists of dicts: d[k][0] for each key."""
    for k in keys:
        d = d[k][0]
    return d


def channels(stream):
    return [
        (first(c, "label"), first(c, "unit"), first(c, "type"))
        for c in first(stream["info"], "desc", "channels")["channel"]
    ]


def test_pyxdf_reads_back_every_stream_exactly(tmp_path):
    path = str(tmp_path / "all.xdf")
    rng = np.random.default_rng(7)
    f32 = rng.normal(scale=1e3, size=(250, 3)).astype(np.float32)
    f64 = rng.normal(size=(40, 2)) * np.array([1e-300, 1e300])
    f64[0] = [1 / 3, -0.0]
    texts = ['{"event":"trial_start","trial_index":1}', "", "ümlaut ✓", "x" * 300]
    t32 = np.cumsum(rng.uniform(0.001, 0.01, size=len(f32)))
    t64 = 1000.0 + np.arange(len(f64)) / 3.0
    tt = [0.0, 0.5, 0.5, 7.25]
    with XdfWriter(path, header={"note": "test"}, chunk_samples=16) as w:
        a = w.add_stream(
            "Cues",
            "EMG",
            [Channel("c1", "volts", "EMG"), Channel("c2", "volts", "EMG"), Channel("c3")],
            "float32",
            0.0,
            source_id="sid-a",
            desc={"acquisition": {"manufacturer": "GraspGuide", "simulated": "true"}},
        )
        b = w.add_stream("Precise", "MoCap", ["lo", "hi"], "double64", 0.0)
        c = w.add_stream("Events", "Markers", [Channel("event_json", "json")], "string")
        for t, row in zip(t32, f32):
            w.push(a, float(t), [float(x) for x in row])
        w.write_samples(b, [float(t) for t in t64], [list(r) for r in f64])
        for t, text in zip(tt, texts):
            w.push(c, t, [text])
    streams, header = pyxdf.load_xdf(path, synchronize_clocks=False, dejitter_timestamps=False)
    assert header["info"]["version"] == ["1.0"] and header["info"]["note"] == ["test"]
    by = {first(s["info"], "name"): s for s in streams}
    assert list(by) == ["Cues", "Precise", "Events"]
    cues, precise, events = by["Cues"], by["Precise"], by["Events"]
    assert first(cues["info"], "type") == "EMG" and first(cues["info"], "source_id") == "sid-a"
    assert first(cues["info"], "channel_format") == "float32"
    assert channels(cues) == [("c1", "volts", "EMG"), ("c2", "volts", "EMG"), ("c3", None, None)]
    assert first(cues["info"], "desc", "acquisition", "simulated") == "true"
    assert cues["time_series"].dtype == np.float32
    assert cues["time_series"].tobytes() == f32.tobytes()  # bit for bit
    assert np.array_equal(cues["time_stamps"], t32)
    assert precise["time_series"].dtype == np.float64
    assert precise["time_series"].tobytes() == f64.tobytes()
    assert np.array_equal(precise["time_stamps"], t64)
    assert [row[0] for row in events["time_series"]] == texts
    assert list(events["time_stamps"]) == tt
    assert channels(events) == [("event_json", "json", None)]
    for s, n, t in ((cues, len(f32), t32), (precise, len(f64), t64), (events, 4, tt)):
        footer = s["footer"]["info"]
        assert int(first(footer, "sample_count")) == n
        assert float(first(footer, "first_timestamp")) == t[0]
        assert float(first(footer, "last_timestamp")) == t[-1]


def test_clock_offsets_and_deduced_timestamps(tmp_path):
    path = str(tmp_path / "clock.xdf")
    with XdfWriter(path) as w:
        s = w.add_stream("Reg", "EEG", ["a"], "double64", 250.0)
        w.write_samples(s, [2.0, None, None, 3.0, None], [[1.0], [2.0], [3.0], [4.0], [5.0]])
        w.write_clock_offset(s, 2.0, 0.25)
    raw, _ = pyxdf.load_xdf(path, synchronize_clocks=False, dejitter_timestamps=False)
    # the spec: a missing timestamp is the previous one plus 1 / nominal_srate
    expected = [2.0, 2.0 + 1 / 250, 2.0 + 1 / 250 + 1 / 250, 3.0, 3.0 + 1 / 250]
    assert raw[0]["time_stamps"] == pytest.approx(expected, abs=1e-12)
    assert raw[0]["clock_times"] == [2.0] and raw[0]["clock_values"] == [0.25]
    footer = raw[0]["footer"]["info"]
    offset = first(footer, "clock_offsets", "offset")
    assert float(first(offset, "time")) == 2.0 and float(first(offset, "value")) == 0.25
    assert float(first(footer, "last_timestamp")) == pytest.approx(3.004, abs=1e-12)
    synced, _ = pyxdf.load_xdf(path, dejitter_timestamps=False)
    assert synced[0]["time_stamps"] == pytest.approx(np.array(expected) + 0.25, abs=1e-12)


def test_chunk_bytes_follow_the_specification(tmp_path):
    path = str(tmp_path / "bytes.xdf")
    w = XdfWriter(path)
    sid = w.add_stream("S", "T", ["x", "y"], "float32", 0.0)
    mid = w.add_stream("M", "Markers", ["m"], "string")
    w.write_samples(sid, [0.5, 1.25], [[1.0, -2.0], [3.5, 0.0]])
    w.write_samples(mid, [0.75], [["hé"]])
    w.write_boundary()
    w.close()
    data = open(path, "rb").read()
    assert data[:4] == b"XDF:"
    # [NumLengthBytes=1][Length][Tag=3, uint16][StreamId uint32][NumSampleBytes=1][NumSamples]
    # then per sample [TimeStampBytes=8][double][values float32 LE]
    content = (
        struct.pack("<I", 1)
        + bytes([1, 2])
        + bytes([8])
        + struct.pack("<d", 0.5)
        + struct.pack("<ff", 1.0, -2.0)
        + bytes([8])
        + struct.pack("<d", 1.25)
        + struct.pack("<ff", 3.5, 0.0)
    )
    samples = bytes([1, len(content) + 2]) + struct.pack("<H", 3) + content
    assert data.count(samples) == 1
    # a string value: [NumLengthBytes][Length] then its UTF-8 bytes
    text = "hé".encode()
    content = struct.pack("<I", 2) + bytes([1, 1, 8]) + struct.pack("<d", 0.75)
    content += bytes([1, len(text)]) + text
    assert data.count(bytes([1, len(content) + 2]) + struct.pack("<H", 3) + content) == 1
    boundary = bytes([1, 18]) + struct.pack("<H", 5) + SPEC_BOUNDARY
    assert data.count(boundary) == 1
    # the FileHeader chunk comes first; its XML is more than 255 bytes? then 4-byte length
    n = data[4]
    assert n in (1, 4, 8)
    length = int.from_bytes(data[5 : 5 + n], "little")
    assert struct.unpack("<H", data[5 + n : 7 + n])[0] == 1
    assert b"<info><version>1.0</version>" in data[7 + n : 5 + n + length]
    # the stream header's XML is longer than 255 bytes: a 4-byte length
    at = 5 + n + length
    assert data[at] == 4
    assert struct.unpack("<H", data[at + 5 : at + 7])[0] == 2
    assert struct.unpack("<I", data[at + 7 : at + 11])[0] == 1


@pytest.mark.parametrize(
    "n,expected",
    [
        (0, b"\x01\x00"),
        (255, b"\x01\xff"),
        (256, b"\x04\x00\x01\x00\x00"),
        (2**32 - 1, b"\x04\xff\xff\xff\xff"),
        (2**32, b"\x08\x00\x00\x00\x00\x01\x00\x00\x00"),
    ],
)
def test_variable_length_integers(n, expected):
    assert varlen_int(n) == expected


def test_an_existing_file_is_never_overwritten(tmp_path):
    path = tmp_path / "old.xdf"
    path.write_bytes(b"precious")
    with pytest.raises(RecordWriteError) as e:
        XdfWriter(str(path))
    assert str(path) in str(e.value) and "never overwritten" in str(e.value)
    assert path.read_bytes() == b"precious"
    with pytest.raises(RecordWriteError) as e:
        XdfWriter(str(tmp_path / "missing" / "x.xdf"))
    assert "missing" in str(e.value)


def test_bad_streams_and_samples_are_refused_by_name(tmp_path):
    w = XdfWriter(str(tmp_path / "bad.xdf"))
    with pytest.raises(XdfFormatError, match="'A'.*channel_format.*int16"):
        w.add_stream("A", "T", ["x"], "int16")
    sid = w.add_stream("B", "T", ["x", "y"], "float32", 0.0)
    with pytest.raises(XdfFormatError, match="'B' has 2 channels, a sample gave 3"):
        w.push(sid, 0.0, [1.0, 2.0, 3.0])
    with pytest.raises(XdfFormatError, match="'B' is irregular.*needs a timestamp"):
        w.push(sid, None, [1.0, 2.0])
    with pytest.raises(XdfFormatError, match="'B'.*not numbers"):
        w.write_samples(sid, [0.0], [["a", "b"]])
    w.close()
    streams, _ = pyxdf.load_xdf(str(tmp_path / "bad.xdf"))
    assert len(streams) == 1 and len(streams[0]["time_stamps"]) == 0


_KILLED_WRITER = textwrap.dedent(
    """
    import sys, time
    from graspguide.records.xdf_writer import XdfWriter
    w = XdfWriter(sys.argv[1], chunk_samples=10, chunk_s=60.0)
    s = w.add_stream("Live", "MoCap", ["qw", "qx"], "double64", 0.0)
    print("ready", flush=True)
    i = 0
    while True:
        w.push(s, i * 0.01, [float(i), -float(i)])
        i += 1
        time.sleep(0.0005)
    """
)


def test_a_killed_recording_reads_up_to_its_last_chunk(tmp_path):
    path = str(tmp_path / "killed.xdf")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    p = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, path], stdout=subprocess.PIPE, env=env
    )
    assert p.stdout is not None and p.stdout.readline() == b"ready\n"
    time.sleep(0.5)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=10)
    streams, _ = pyxdf.load_xdf(path)
    s = streams[0]
    n = len(s["time_stamps"])
    assert n >= 10 and n % 10 == 0  # whole chunks only
    assert "footer" not in s  # footers come at close()
    i = np.arange(n, dtype=float)
    assert np.array_equal(s["time_series"], np.column_stack([i, -i]))
    assert np.array_equal(s["time_stamps"], i * 0.01)


def test_what_pyxdf_makes_of_a_cut_final_samples_chunk(tmp_path, caplog):
    """A file cut inside its last Samples chunk (a power loss, a copy cut short; never a
    killed writer, whose chunks are whole): pyxdf drops the chunk and keeps all before
    it, except two cuts: inside the chunk's 2-byte tag it raises, and inside the values
    of the chunk's last sample it keeps the chunk with that sample's values stale (the
    previous sample's bytes). The writer's docstring and docs/lab-streams.md say so."""
    path = str(tmp_path / "whole.xdf")
    with XdfWriter(path) as w:
        s = w.add_stream("S", "MoCap", ["a"], "double64", 0.0)
        w.write_samples(s, [0.0, 1.0], [[1.0], [2.0]])
        w.write_samples(s, [2.0, 3.0, 4.0], [[3.0], [-4.0], [5.0]])
    data = open(path, "rb").read()
    head = struct.pack("<I", 1) + bytes([1, 3])  # stream id, 3 samples
    body = b"".join(bytes([8]) + struct.pack("<dd", t, v) for t, v in ((2, 3), (3, -4), (4, 5)))
    whole = bytes([1, 2 + len(head) + len(body)]) + struct.pack("<H", 3) + head + body
    start = data.index(whole)
    caplog.set_level(logging.CRITICAL, logger="pyxdf")
    cut = tmp_path / "cut.xdf"
    outcomes = set()
    for kept in range(len(whole)):
        cut.write_bytes(data[: start + kept])
        if kept in (2, 3):  # inside the tag
            with pytest.raises(struct.error):
                pyxdf.load_xdf(str(cut))
            outcomes.add("raises")
            continue
        values = list(pyxdf.load_xdf(str(cut))[0][0]["time_series"][:, 0])
        last_values_from = 4 + len(head) + 2 * 17 + 9  # the third sample's value bytes
        if kept >= last_values_from:
            assert values[:4] == [1.0, 2.0, 3.0, -4.0] and values[4] != 5.0, kept
            outcomes.add("stale last sample")
        else:
            assert values == [1.0, 2.0], kept
            outcomes.add("chunk dropped")
    assert outcomes == {"raises", "stale last sample", "chunk dropped"}
