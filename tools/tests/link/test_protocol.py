"""The serial link protocol, Python side (graspguide.link): CRC, COBS, the generated
messages, the golden frames shared with the C++ tests (test/data/golden_frames.json),
the parser's resynchronization, agreement with the core, and generated code freshness."""

from __future__ import annotations

import binascii
import filecmp
import json
import math
import os
import random
import shutil
import struct
import subprocess
import sys

import pytest
from conftest import TOOLS_DIR

from graspguide import link as gp
from graspguide.link import messages as M
from graspguide.link.codec import (
    FRAME_OVERHEAD,
    MAX_RAW_FRAME_SIZE,
    Accept,
    FrameParser,
    ParseEvent,
    check_frame,
    cobs_decode,
    cobs_encode,
    cobs_max_encoded_size,
    crc16,
    decode_frame,
    decode_message,
    encode_frame,
    encode_message,
)
from graspguide.link.message_base import INT_RANGES

TOOLS_DIR = TOOLS_DIR
REPO_ROOT = os.path.dirname(TOOLS_DIR)
GOLDEN = os.path.join(REPO_ROOT, "test", "data", "golden_frames.json")
GENERATOR = os.path.join(TOOLS_DIR, "codegen")
SEED = 20240611

with open(GOLDEN, encoding="utf-8") as _fh:
    GOLDEN_DATA = json.load(_fh)
GOLDEN_FRAMES = GOLDEN_DATA["frames"]


def golden_wire(index: int) -> bytes:
    return bytes.fromhex(GOLDEN_FRAMES[index]["hex"])


def random_value(spec: M.FieldSpec, rng: random.Random):
    """A random wire-valid value of a field (floats: random float32 bit patterns, no NaN,
    since NaN != NaN)."""

    def one():
        if spec.kind == "f32":
            while True:
                x = struct.unpack("<f", struct.pack("<I", rng.getrandbits(32)))[0]
                if not math.isnan(x):
                    return x
        if spec.kind == "bool":
            return rng.random() < 0.5
        if spec.kind == "enum":
            return rng.choice(list(spec.enum))
        if spec.kind == "ascii":
            return "".join(chr(rng.randint(0x20, 0x7E)) for _ in range(rng.randint(0, spec.size)))
        lo, hi = INT_RANGES[spec.kind]
        return rng.randint(lo, hi)

    def shaped(shape):
        return one() if not shape else tuple(shaped(shape[1:]) for _ in range(shape[0]))

    return shaped(spec.shape)


def random_message(cls, rng: random.Random):
    return cls(**{spec.name: random_value(spec, rng) for spec in cls.FIELDS})


# --- CRC and COBS ---------------------------------------------------------------------


def test_crc16_known_vectors():
    assert crc16(b"123456789") == 0x29B1
    assert crc16(b"") == 0xFFFF
    assert crc16(b"A") == 0xB915


def test_crc16_matches_the_standard_library_and_continues():
    rng = random.Random(SEED)
    for _ in range(200):
        data = rng.randbytes(rng.randint(0, 300))
        assert crc16(data) == binascii.crc_hqx(data, 0xFFFF)
        cut = rng.randint(0, len(data))
        assert crc16(data[cut:], crc16(data[:cut])) == crc16(data)


def test_cobs_known_encodings():
    assert cobs_encode(b"") == b"\x01"
    assert cobs_encode(b"\x00") == b"\x01\x01"
    assert cobs_encode(b"\x00\x00") == b"\x01\x01\x01"
    assert cobs_encode(b"\x11\x22\x00\x33") == b"\x03\x11\x22\x02\x33"
    assert cobs_encode(b"\x11\x22\x33\x44") == b"\x05\x11\x22\x33\x44"
    assert cobs_encode(b"\x11\x00\x00\x00") == b"\x02\x11\x01\x01\x01"
    run254 = bytes(range(1, 255))
    assert cobs_encode(run254) == b"\xff" + run254  # no 0x01 after a final full block
    run255 = bytes(range(1, 256))
    assert cobs_encode(run255) == b"\xff" + run254 + b"\x02\xff"


@pytest.mark.parametrize("n", [0, 1, 2, 253, 254, 255, 256, 508, 509, 600])
def test_cobs_round_trips_runs_and_zeros(n):
    rng = random.Random(SEED + n)
    run = bytes(rng.randint(1, 255) for _ in range(n))
    for data in (bytes(n), run, b"\0" + run + b"\0", run + b"\0" + run):
        enc = cobs_encode(data)
        assert 0 not in enc
        assert len(enc) <= cobs_max_encoded_size(len(data))
        assert cobs_decode(enc) == data


def test_cobs_round_trips_random_data():
    rng = random.Random(SEED)
    for _ in range(500):
        density = rng.random()
        data = bytes(
            0 if rng.random() < density else rng.randint(1, 255) for _ in range(rng.randint(0, 700))
        )
        assert cobs_decode(cobs_encode(data)) == data


@pytest.mark.parametrize("bad", [b"", b"\x03\x11", b"\x03\x11\x00", b"\x00"])
def test_cobs_rejects_malformed_input(bad):
    with pytest.raises(gp.BadCobsError):
        cobs_decode(bad)


# --- schema vs. core ------------------------------------------------------------------


def test_error_codes_mirror_the_core_status(core):
    core_codes = [c for c in M.ErrorCode if c < M.LINK_ERROR_BASE]
    assert [c.name.lower() for c in core_codes] == list(core.STATUS_NAMES)
    assert [int(c) for c in core_codes] == list(range(len(core.STATUS_NAMES)))
    assert M.ErrorCode.IMPRECISE_CONTACTS == 6
    assert all(
        c >= M.LINK_ERROR_BASE for c in M.ErrorCode if c.name.lower() not in core.STATUS_NAMES
    )


def test_scene_enums_mirror_the_core(core):
    assert [m.name.lower() for m in M.ConstraintModel] == list(core.CONSTRAINT_MODELS)
    assert [p.name.lower() for p in M.Policy] == [p.lower() for p in core.POLICIES]
    assert [m.name.lower() for m in M.Mode] == [m.lower() for m in core.MODES]
    assert M.MAX_CONTACTS == core.kMaxContacts


def test_parse_events_name_their_error_codes():
    for event in ParseEvent:
        if event in (ParseEvent.NONE, ParseEvent.FRAME):
            continue
        assert M.ErrorCode[event.value.upper()] >= M.LINK_ERROR_BASE


def test_ids_are_unique_and_in_their_ranges():
    assert len({cls.MSG_ID for cls in M.MESSAGES.values()}) == len(M.MESSAGES)
    for cls in M.MESSAGES.values():
        ids = M.HOST_TO_DEVICE_IDS if cls.DIRECTION == "host_to_device" else M.DEVICE_TO_HOST_IDS
        assert cls.MSG_ID in ids
        assert cls.STRUCT.size == cls.PAYLOAD_SIZE
        # The per-field formats the fast paths build on spell the whole payload's.
        assert cls.STRUCT.format == "<" + "".join(spec.format for spec in cls.FIELDS)
    assert max(cls.PAYLOAD_SIZE for cls in M.MESSAGES.values()) == M.MAX_PAYLOAD_SIZE
    assert len(encode_message(M.SetScene(), 0)) == 84  # the largest frame on the wire


# --- messages -------------------------------------------------------------------------


@pytest.mark.parametrize("cls", list(M.MESSAGES.values()), ids=lambda c: c.NAME)
def test_every_message_round_trips(cls):
    rng = random.Random(SEED + cls.MSG_ID)
    for _ in range(300):
        msg = random_message(cls, rng)
        payload = msg.pack()
        assert len(payload) == cls.PAYLOAD_SIZE
        assert cls.unpack(payload) == msg
        seq = rng.randint(0, 0xFFFF)
        decoded = decode_message(encode_message(msg, seq))
        assert decoded.seq == seq and decoded.message == msg
        assert cls.from_dict(json.loads(json.dumps(msg.to_dict()))) == msg
    with pytest.raises(gp.BadLengthError):
        cls.unpack(bytes(cls.PAYLOAD_SIZE + 1))


def test_defaults_are_the_schema_defaults():
    s = M.SetScene()
    assert (s.k, s.y_axis, s.threshold_deg, s.hold_s, s.timeout_s) == (
        3,
        (0.0, 1.0, 0.0),
        3.0,
        0.5,
        90.0,
    )
    assert s.constraints is M.ConstraintModel.PAPER
    assert M.Pose().quat_wxyz == (1.0, 0.0, 0.0, 0.0)
    assert M.Hello().protocol_version == M.PROTOCOL_VERSION


def test_values_are_stored_as_the_wire_carries_them():
    pose = M.Pose(quat_wxyz=[0.1, 0, 0, 1], contacts=[[0.045] * 3] * 4)
    assert pose.quat_wxyz == (struct.unpack("<f", struct.pack("<f", 0.1))[0], 0.0, 0.0, 1.0)
    assert isinstance(pose.contacts, tuple) and isinstance(pose.contacts[0], tuple)
    assert M.Pose.unpack(pose.pack()) == pose
    assert M.SetScene(constraints=1).constraints is M.ConstraintModel.NORMAL


@pytest.mark.parametrize(
    "kwargs",
    [
        {"k": 256},
        {"k": -1},
        {"k": 3.0},
        {"contacts": [[0.0] * 3] * 3},
        {"y_axis": "abc"},
        {"constraints": 3},
        {"policy": "F"},
        {"threshold_deg": 1e39},
        {"hold_s": True},
    ],
)
def test_bad_values_are_refused_when_building(kwargs):
    with pytest.raises(gp.FieldValueError):
        M.SetScene(**kwargs)


def test_bad_wire_values_name_the_field():
    p = bytearray(M.SetScene().pack())
    p[61] = 3  # constraints
    with pytest.raises(gp.BadEnumValueError) as e:
        M.SetScene.unpack(bytes(p))
    assert e.value.field == 3
    pose = bytearray(M.Pose().pack())
    pose[20] = 2  # has_contacts
    with pytest.raises(gp.BadEnumValueError) as e:
        M.Pose.unpack(bytes(pose))
    assert e.value.field == 2
    reply = bytearray(M.HelloReply(board="native").pack())
    reply[6 + 7] = ord("x")  # a character after the NUL padding started
    with pytest.raises(gp.BadEnumValueError) as e:
        M.HelloReply.unpack(bytes(reply))
    assert e.value.field == 3
    with pytest.raises(gp.FieldValueError):
        M.HelloReply(board="x" * 17)
    with pytest.raises(gp.UnknownIdError):
        M.unpack_payload(0x3F, b"")


# --- golden frames --------------------------------------------------------------------


@pytest.mark.parametrize("golden", GOLDEN_FRAMES, ids=lambda g: g["name"])
def test_golden_frame_decodes_and_reencodes(golden):
    wire = bytes.fromhex(golden["hex"])
    cls = M.MESSAGES[golden["msg_id"]]
    assert cls.NAME == golden["message"]
    expected = cls.from_dict(golden["fields"])
    decoded = decode_message(wire)
    assert decoded.seq == golden["seq"]
    assert decoded.message == expected
    assert decoded.message.to_dict() == golden["fields"]
    assert encode_message(decoded.message, decoded.seq) == wire
    assert encode_message(expected, golden["seq"]) == wire


def test_golden_frames_cover_every_message():
    assert GOLDEN_DATA["protocol_version"] == M.PROTOCOL_VERSION
    assert {g["msg_id"] for g in GOLDEN_FRAMES} == set(M.MESSAGES)


# --- parser ---------------------------------------------------------------------------


def events(parser: FrameParser, data: bytes):
    return [e for e, _ in parser.feed(data)]


def test_frames_back_to_back_and_idle_delimiters():
    wires = [bytes.fromhex(g["hex"]) for g in GOLDEN_FRAMES]
    stream = b"\0\0" + b"".join(wires) + b"\0".join(wires) + b"".join(wires)
    p = FrameParser()
    got = p.feed(stream)
    assert [e for e, _ in got] == [ParseEvent.FRAME] * (3 * len(wires))
    assert p.good_frames == 3 * len(wires) and p.bad_frames == 0


def test_resync_after_garbage():
    good = golden_wire(1)
    rng = random.Random(SEED)
    for _ in range(200):
        p = FrameParser()
        got = events(p, rng.randbytes(rng.randint(1, 300)) + b"\0" + good)
        assert got[-1] is ParseEvent.FRAME and p.good_frames == 1
        assert p.bad_frames == len(got) - 1


def test_resync_after_a_truncated_frame():
    a, b = golden_wire(1), golden_wire(3)
    for cut in range(1, len(a) - 1):
        p = FrameParser()
        got = events(p, a[:cut] + b"\0" + b)
        assert len(got) == 2 and got[0] is not ParseEvent.FRAME and got[1] is ParseEvent.FRAME
        q = FrameParser()
        got = events(q, a[:cut] + b + b)  # without the delimiter, the cut frame eats one
        assert got[0] is not ParseEvent.FRAME and got[-1] is ParseEvent.FRAME and q.good_frames == 1


def test_resync_after_an_oversized_frame():
    good = golden_wire(0)
    for n in (MAX_RAW_FRAME_SIZE + 2, 254, 255, 1000):
        assert events(FrameParser(), b"\x42" * n + b"\0" + good) == [
            ParseEvent.TOO_LONG,
            ParseEvent.FRAME,
        ]
    raw = bytes([M.PROTOCOL_VERSION, 0x02, 1, 0]) + b"\x5a" * (M.MAX_PAYLOAD_SIZE + 1)
    raw += struct.pack("<H", crc16(raw))
    assert events(FrameParser(), cobs_encode(raw) + b"\0" + good) == [
        ParseEvent.TOO_LONG,
        ParseEvent.FRAME,
    ]
    with pytest.raises(gp.TooLongError):
        decode_frame(cobs_encode(raw) + b"\0")


def test_every_flipped_bit_is_caught():
    for g in GOLDEN_FRAMES[:6]:
        wire = bytes.fromhex(g["hex"])
        for i in range(len(wire) - 1):
            for bit in range(8):
                bad = bytearray(wire)
                bad[i] ^= 1 << bit
                p = FrameParser()
                got = events(p, bytes(bad) + wire)
                assert ParseEvent.FRAME not in got[:-1] and got[-1] is ParseEvent.FRAME


@pytest.mark.parametrize(
    "version,msg_id,payload,event,error",
    [
        (M.PROTOCOL_VERSION + 1, 0x01, b"\x01", ParseEvent.BAD_VERSION, gp.BadVersionError),
        (0, 0x01, b"\x01", ParseEvent.BAD_VERSION, gp.BadVersionError),
        (M.PROTOCOL_VERSION, 0x3F, b"\x01", ParseEvent.UNKNOWN_ID, gp.UnknownIdError),
        (M.PROTOCOL_VERSION, 0xFF, b"", ParseEvent.UNKNOWN_ID, gp.UnknownIdError),
        (M.PROTOCOL_VERSION, 0x01, b"", ParseEvent.BAD_LENGTH, gp.BadLengthError),
        (M.PROTOCOL_VERSION, 0x01, b"\x01\x02", ParseEvent.BAD_LENGTH, gp.BadLengthError),
        (M.PROTOCOL_VERSION, 0x05, b"\x00", ParseEvent.BAD_LENGTH, gp.BadLengthError),
    ],
)
def test_header_errors_keep_a_trusted_header(version, msg_id, payload, event, error):
    wire = encode_frame(msg_id, 77, payload, version=version)
    p = FrameParser()
    got = p.feed(wire + golden_wire(0))
    assert [e for e, _ in got] == [event, ParseEvent.FRAME]
    assert got[0][1].seq == 77 and got[0][1].msg_id == msg_id
    with pytest.raises(error) as e:
        decode_frame(wire)
    assert e.value.header == (version, msg_id, 77)


def test_receivers_accept_their_direction_only():
    ack, pose = encode_message(M.Ack(), 5), encode_message(M.Pose(), 6)
    device, host = FrameParser(Accept.HOST_TO_DEVICE), FrameParser(Accept.DEVICE_TO_HOST)
    assert events(device, ack + pose) == [ParseEvent.UNKNOWN_ID, ParseEvent.FRAME]
    assert events(host, ack + pose) == [ParseEvent.FRAME, ParseEvent.UNKNOWN_ID]


def test_too_short_bad_cobs_and_counters():
    p = FrameParser()
    for n in range(1, FRAME_OVERHEAD):
        assert events(p, cobs_encode(b"\x01" * n) + b"\0") == [ParseEvent.TOO_SHORT]
    assert events(p, b"\x09\x01\x02\x00") == [ParseEvent.BAD_COBS]
    assert p.counts[ParseEvent.TOO_SHORT] == FRAME_OVERHEAD - 1 and p.bad_frames == FRAME_OVERHEAD
    bad_crc = bytearray(golden_wire(5))
    bad_crc[-2] ^= 1
    assert events(p, golden_wire(0) + bytes(bad_crc) + golden_wire(2)) == [
        ParseEvent.FRAME,
        ParseEvent.BAD_CRC,
        ParseEvent.FRAME,
    ]
    assert p.good_frames == 2 and p.counts[ParseEvent.BAD_CRC] == 1
    p.feed(golden_wire(1)[:10])
    p.discard_partial()
    assert events(p, golden_wire(1)) == [ParseEvent.FRAME]
    p.reset_counters()
    assert p.good_frames == 0 and p.bad_frames == 0
    assert check_frame(b"\x01" * 3) == (ParseEvent.TOO_SHORT, None)


def test_decode_frame_wants_exactly_one_frame():
    with pytest.raises(gp.IncompleteFrameError):
        decode_frame(golden_wire(0)[:-1])
    with pytest.raises(gp.IncompleteFrameError):
        decode_frame(golden_wire(0) + golden_wire(1))
    with pytest.raises(gp.IncompleteFrameError):
        decode_frame(b"\0\0")
    assert decode_frame(b"\0" + golden_wire(0)).msg_id == M.MsgId.HELLO
    with pytest.raises(gp.BadCrcError):
        bad = bytearray(golden_wire(0))
        bad[-2] ^= 0x80
        decode_frame(bytes(bad))


def test_recovers_every_frame_from_random_streams():
    rng = random.Random(SEED)
    classes = list(M.MESSAGES.values())
    p = FrameParser()
    sent, got = [], []
    for _ in range(1500):
        zero_rate = 0.1 if rng.random() < 0.25 else 0.005
        garbage = bytes(
            0 if rng.random() < zero_rate else rng.randint(0, 255)
            for _ in range(rng.randint(0, 95))
        )
        if rng.random() < 0.25:
            w = encode_message(random_message(rng.choice(classes), rng), rng.randint(0, 0xFFFF))
            garbage += w[: rng.randint(0, len(w) - 2)]
        stream = garbage + b"\0"
        for _ in range(rng.randint(1, 3)):
            msg, seq = random_message(rng.choice(classes), rng), rng.randint(0, 0xFFFF)
            sent.append((seq, msg))
            stream += encode_message(msg, seq)
        got += [(f.seq, gp.codec.message_of(f)) for e, f in p.feed(stream) if e is ParseEvent.FRAME]
    assert got == sent


# --- generated code -------------------------------------------------------------------


def test_generated_code_is_up_to_date():
    r = subprocess.run([sys.executable, GENERATOR, "--check"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_stale_generated_code_fails_the_check(tmp_path):
    """--check must notice a hand edit of any output: run it on a copy of the tree."""
    generator = [
        os.path.join("tools", "codegen", name)
        for name in sorted(os.listdir(os.path.join(TOOLS_DIR, "codegen")))
        if name.endswith((".py", ".toml"))
    ]
    outputs = [
        "lib/graspguide_link/src/graspguide_link/messages.h",
        "lib/graspguide_link/src/graspguide_link/core_status.h",
        "tools/graspguide/link/messages.py",
        "test/data/golden_frames.json",
        "test/data/golden_frames.h",
        "test/data/retry_hands.h",
        "docs/protocol.md",
    ]
    for r in generator + outputs + ["test/data/hard_hands.json"]:
        os.makedirs(tmp_path / os.path.dirname(r), exist_ok=True)
        shutil.copy(os.path.join(REPO_ROOT, r), tmp_path / r)
    gen = str(tmp_path / "tools" / "codegen")
    assert subprocess.run([sys.executable, gen, "--check"], capture_output=True).returncode == 0
    for r in outputs:
        original = (tmp_path / r).read_text(encoding="utf-8")
        # Edit the generated part (docs/protocol.md is hand-written outside its markers).
        start = original.find("Largest payload") if r.endswith(".md") else 0
        edited = original[:start] + original[start:].replace("0", "1", 1)
        if edited == original:  # a file without a 0 (core_status.h): one more line
            edited = original + "\n"
        (tmp_path / r).write_text(edited, encoding="utf-8")
        res = subprocess.run([sys.executable, gen, "--check"], capture_output=True, text=True)
        assert res.returncode == 1 and r in res.stderr, r
        (tmp_path / r).write_text(original, encoding="utf-8")


def test_a_retry_hand_without_its_doubt_is_refused_naming_the_field(tmp_path):
    for name in os.listdir(os.path.join(TOOLS_DIR, "codegen")):
        if name.endswith((".py", ".toml")):
            os.makedirs(tmp_path / "tools" / "codegen", exist_ok=True)
            shutil.copy(os.path.join(TOOLS_DIR, "codegen", name), tmp_path / "tools" / "codegen")
    hands = json.loads(open(os.path.join(REPO_ROOT, "test", "data", "hard_hands.json")).read())
    del hands["retry"][1]["doubt"]
    (tmp_path / "test" / "data").mkdir(parents=True)
    (tmp_path / "test" / "data" / "hard_hands.json").write_text(json.dumps(hands))
    res = subprocess.run(
        [sys.executable, str(tmp_path / "tools" / "codegen")], capture_output=True, text=True
    )
    assert res.returncode == 2
    assert "retry hand 'p1453642': 'doubt' must be one of ['residual', 'verdict']" in res.stderr
    assert not (tmp_path / "test" / "data" / "retry_hands.h").exists()


def test_the_installed_package_has_the_current_protocol_code():
    for name in ("messages.py", "message_base.py", "codec.py", "errors.py", "__init__.py"):
        installed = os.path.join(os.path.dirname(gp.__file__), name)
        assert filecmp.cmp(
            installed, os.path.join(TOOLS_DIR, "graspguide", "link", name), shallow=False
        ), f"{name}: run tools/bootstrap.sh to reinstall ./tools"
