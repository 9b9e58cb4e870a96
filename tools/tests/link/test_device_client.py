"""DeviceClient and the transports without a device: a fake Transport plays the device
(timeouts, ERROR mapping, interleaved TRIAL_RESULT, garbage on the line, protocol
mismatch, lost answers), plus the transport's error messages."""

from __future__ import annotations

import math
import os
import time
import tomllib

import pytest
from conftest import TOOLS_DIR
from fake_device import HAND3, WRENCH, FakeDevice, client_for, good_device, telemetry_for

from graspguide.devices import registry
from graspguide.devices import sim as gsim
from graspguide.link import client as gd
from graspguide.link import codec
from graspguide.link import messages as m
from graspguide.link import transport as gt

_TOOLS = TOOLS_DIR
SCHEMA = os.path.join(_TOOLS, "codegen", "link_messages.toml")


# --------------------------------------------------------------------------------------
# Requests and answers
# --------------------------------------------------------------------------------------
def test_requests_are_numbered_and_answered():
    c = client_for(good_device)
    assert c.transport.rx == b"" and c.hello().board == "fake"
    c.set_scene(HAND3, policy="Fperp", mode="V", constraints="normal")
    c.start_trial(7, WRENCH)
    tel = c.pose(1234, (1, 0, 0, 0))
    assert tel.host_time_us == 1234 and tel.pwm == (100, 120, 140, 0)
    assert c.status().state is m.DeviceState.SCENE_SET
    c.stop()
    c.set_motors([10, 20])
    seqs = [s for s, _ in c.transport.received]
    assert seqs == list(range(len(seqs)))
    scene = c.transport.received[1][1]
    assert scene.k == 3 and scene.policy is m.Policy.FPERP and scene.mode is m.Mode.V
    assert scene.constraints is m.ConstraintModel.NORMAL and scene.contacts[3] == (0, 0, 0)
    assert c.transport.received[-1][1].pwm == (10, 20, 0, 0)
    assert c.host_bad_frames == 0 and c.device_frames_lost == 0


def test_idle_delimiter_sent_on_open():
    t = FakeDevice(good_device)
    sent = []
    orig = t.write
    t.write = lambda data: (sent.append(bytes(data)), orig(data))
    gd.DeviceClient(t)
    assert sent == [b"\x00"]


def test_every_write_of_frames_starts_with_a_delimiter():
    """A 0x00 before each frame ends whatever partial frame the device holds, so a STOP
    after a write cut short is not merged with it (docs/protocol.md, framing)."""
    t = FakeDevice(good_device)
    sent = []
    orig = t.write
    t.write = lambda data: (sent.append(bytes(data)), orig(data))
    c = gd.DeviceClient(t, timeout=0.2)
    c.hello()
    c.set_scene(HAND3)
    c.start_trial(1, WRENCH)
    c.pose(5, (1, 0, 0, 0))  # the fast path
    c.pose(6, (1, 0, 0, 0), contacts=HAND3)  # the generic path
    c.pose_batch([(7, (1, 0, 0, 0)), (8, (1, 0, 0, 0))])
    c.pose_batch([(9, (1, 0, 0, 0)), (10, (1, 0, 0, 0))])
    c.status()
    c.stop()
    frames = sent[1:]
    assert sent[0] == b"\x00" and len(frames) == 9
    for wire in frames:
        assert wire[:1] == b"\x00" and wire[-1:] == b"\x00" and wire[1:2] != b"\x00", wire
    assert [type(msg).__name__ for _, msg in t.received][-3:] == ["Pose", "GetStatus", "Stop"]
    assert t.parser.bad_frames == 0


def test_bad_arguments_are_refused_before_sending():
    c = client_for(good_device)
    with pytest.raises(ValueError, match="policy"):
        c.set_scene(HAND3, policy="G")
    with pytest.raises(ValueError, match="wrench"):
        c.start_trial(1, [1, 2, 3])
    with pytest.raises(ValueError, match="pwm"):
        c.set_motors([300])
    assert c.transport.received == []


def test_values_beyond_float32_are_infinite_on_the_wire():
    assert gd.to_f32(1e300) == math.inf and gd.to_f32(-1e300) == -math.inf
    assert math.isnan(gd.to_f32(math.nan)) and gd.to_f32(0.1) != 0.1
    c = client_for(good_device)
    c.start_trial(1, [1e300, 0, 0, 0, 0, 0])
    assert c.transport.received[-1][1].wrench[0] == math.inf


def test_contact_count_other_than_3_or_4_is_passed_on():
    c = client_for(good_device)
    c.set_scene(HAND3 + HAND3)
    scene = c.transport.received[-1][1]
    assert scene.k == 6 and scene.contacts[3] == tuple(gd.to_f32(v) for v in HAND3[0])


# --------------------------------------------------------------------------------------
# ERROR -> DeviceError
# --------------------------------------------------------------------------------------
def test_error_meanings_are_the_schema_text():
    with open(SCHEMA, "rb") as f:
        schema = tomllib.load(f)
    codes = next(e for e in schema["enum"] if e["name"] == "ErrorCode")["values"]
    assert gd.ERROR_MEANINGS == {v["name"]: v["doc"] for v in codes}
    assert set(gd.ERROR_MEANINGS) == {c.name.lower() for c in m.ErrorCode}


@pytest.mark.parametrize(
    "code", [c for c in m.ErrorCode if c != m.ErrorCode.OK], ids=lambda c: c.name.lower()
)
def test_every_error_code_maps_to_a_device_error(code):
    c = client_for(lambda msg, seq: [m.Error(request_seq=seq, code=code, detail=2)])
    with pytest.raises(gd.DeviceError) as info:
        c.set_scene(HAND3)
    e = info.value
    assert isinstance(e, gt.LinkError)
    assert e.code is code and e.code_name == code.name.lower() and e.detail == 2
    assert e.request == "SET_SCENE" and e.request_seq == 0
    assert e.meaning == gd.ERROR_MEANINGS[e.code_name]
    assert e.code_name in str(e) and "SET_SCENE" in str(e)


def test_error_details_are_spelled_out():
    def refuse(code, detail):
        return lambda msg, seq: [m.Error(request_seq=seq, code=code, detail=detail)]

    c = client_for(refuse(m.ErrorCode.NOT_ALLOWED_IN_STATE, m.DeviceState.TRIAL_RUNNING))
    with pytest.raises(gd.DeviceError, match="trial_running: send STOP first"):
        c.set_scene(HAND3)
    c = client_for(refuse(m.ErrorCode.NO_SCENE, m.MsgId.START_TRIAL))
    with pytest.raises(gd.DeviceError, match="START_TRIAL needs a valid SET_SCENE first"):
        c.start_trial(1, WRENCH)
    c = client_for(refuse(m.ErrorCode.BAD_ENUM_VALUE, 3))
    with pytest.raises(gd.DeviceError, match="field 'constraints'"):
        c.set_scene(HAND3)


def test_bad_config_names_the_field_and_its_range():
    from graspguide.core import _core

    names = [f.name for f in m.SetScene.FIELDS]
    for key, r in _core.TRIAL_LIMITS.items():
        index = names.index(key)
        c = client_for(
            lambda msg, seq, i=index: [
                m.Error(request_seq=seq, code=m.ErrorCode.BAD_CONFIG, detail=i)
            ]
        )
        with pytest.raises(gd.DeviceError) as info:
            c.set_scene(HAND3)
        text = str(info.value)
        assert f"field '{key}' (index {names.index(key)})" in text, text
        assert (
            f"{r['min']:g}, {r['max']:g}]" in text
            and ("(" if r["min_exclusive"] else "[") + f"{r['min']:g}," in text
        ), text
    # an index that is no trial field (a device that does not name it) is not guessed
    c = client_for(
        lambda msg, seq: [
            m.Error(request_seq=seq, code=m.ErrorCode.BAD_CONFIG, detail=names.index("policy"))
        ]
    )
    with pytest.raises(gd.DeviceError) as info:
        c.set_scene(HAND3)
    assert "field" not in str(info.value) and "threshold, hold or timeout" in str(info.value)


def test_telemetry_status_raises_only_when_asked():
    def fails(msg, seq):
        if isinstance(msg, m.Pose):
            return [
                m.Telemetry(host_time_us=msg.host_time_us, solver_status=m.ErrorCode.RANK_DEFICIENT)
            ]
        return good_device(msg, seq)

    c = client_for(fails)
    assert c.pose(5).solver_status is m.ErrorCode.RANK_DEFICIENT
    with pytest.raises(gd.DeviceError, match="could not solve POSE: rank_deficient") as info:
        c.pose(6, check=True)
    assert info.value.source == "TELEMETRY"


# --------------------------------------------------------------------------------------
# Timeouts and what they say
# --------------------------------------------------------------------------------------
def test_silent_device_times_out_with_a_diagnosis():
    c = client_for(lambda msg, seq: [], timeout=0.15)
    t0 = time.monotonic()
    with pytest.raises(gt.LinkTimeout) as info:
        c.hello()
    elapsed = time.monotonic() - t0
    assert 0.14 <= elapsed < 1.0
    text = str(info.value)
    assert "HELLO (seq 0)" in text and "0.15 s" in text and "nothing at all" in text
    assert isinstance(info.value, TimeoutError)


def test_per_request_timeout_overrides_the_default():
    c = client_for(lambda msg, seq: [], timeout=5)
    t0 = time.monotonic()
    with pytest.raises(gt.LinkTimeout):
        c.status(timeout=0.05)
    assert time.monotonic() - t0 < 1.0


def test_garbage_only_suggests_the_baud_rate():
    c = client_for(lambda msg, seq: [bytes(range(1, 200)) + b"\x00"] * 3, timeout=0.1)
    with pytest.raises(gt.LinkTimeout, match="baud"):
        c.hello()
    assert c.host_bad_frames == 3


def test_answer_after_garbage_and_stale_answers():
    """Noise, a frame with a bad CRC, an answer to an old request, an unknown device id:
    all counted or kept, and the real answer still found."""

    def noisy(msg, seq):
        raw = bytes([m.PROTOCOL_VERSION, m.Ack.MSG_ID, 99, 0]) + m.Ack(seq).pack()
        bad_crc = (
            codec.cobs_encode(raw + bytes([codec.crc16(raw) & 0xFF ^ 0x55, codec.crc16(raw) >> 8]))
            + b"\x00"
        )
        return [
            b"\x13\x37\xff\x00",
            bad_crc,
            m.Ack(request_seq=(seq + 500) & 0xFFFF),
            codec.encode_frame(0xBF, 0, b""),
            m.Ack(request_seq=seq),
        ]

    c = client_for(noisy)
    c.set_scene(HAND3)
    c.stop()
    assert c.host_bad_frames == 6  # per request: noise (bad_cobs), bad_crc, unknown id
    assert c.parse_counts["bad_cobs"] == c.parse_counts["bad_crc"] == 2
    assert [a.request_seq for a in c.unmatched] == [500, 501]


def test_device_frame_gaps_are_counted():
    def gappy(msg, seq):
        t.seq.next()  # the device "lost" a frame
        return good_device(msg, seq)

    c = client_for(gappy)
    t = c.transport
    c.hello()
    c.stop()
    c.stop()
    assert c.device_frames_lost == 2


# --------------------------------------------------------------------------------------
# TRIAL_RESULT is never dropped
# --------------------------------------------------------------------------------------
def test_interleaved_trial_result_is_queued():
    result = m.TrialResult(trial_id=3, success=True, completion_s=0.5, first_entry_s=0.0)

    def interleaving(msg, seq):
        if isinstance(msg, m.Pose):
            return [result, telemetry_for(msg), result]  # before and after the answer
        if isinstance(msg, m.GetStatus):
            return [result, m.Status()]
        return [result, m.Ack(request_seq=seq)]

    c = client_for(interleaving)
    c.set_scene(HAND3)
    c.pose(10)
    c.status()
    assert len(c.trial_results) == 4
    assert c.wait_trial_result() == result
    assert len(c.trial_results) == 3


def test_wait_trial_result_waits_and_times_out():
    c = client_for(good_device, timeout=0.05)
    with pytest.raises(gt.LinkTimeout, match="TRIAL_RESULT"):
        c.wait_trial_result()
    c.transport.rx += c.transport.frame(m.TrialResult(trial_id=9))
    assert c.wait_trial_result().trial_id == 9


# --------------------------------------------------------------------------------------
# Pipelined POSEs (pose_batch)
# --------------------------------------------------------------------------------------
def test_pose_batch_answers_in_order_and_queues_the_trial_end():
    state = {"n": 0}

    def trial(msg, seq):
        if not isinstance(msg, m.Pose):
            return good_device(msg, seq)
        state["n"] += 1
        if state["n"] < 50:
            return [telemetry_for(msg)]
        if state["n"] == 50:
            return [telemetry_for(msg), m.TrialResult(trial_id=1, completion_s=0.49)]
        return [m.Error(request_seq=seq, code=m.ErrorCode.NOT_ALLOWED_IN_STATE, detail=1)]

    c = client_for(trial)
    answers = c.pose_batch([(i * 10_000, (1, 0, 0, 0)) for i in range(56)])
    assert [type(a) for a in answers] == [m.Telemetry] * 50 + [m.Error] * 6
    assert [t.host_time_us for t in answers[:50]] == [i * 10_000 for i in range(50)]
    assert all(e.code == m.ErrorCode.NOT_ALLOWED_IN_STATE for e in answers[50:])
    assert c.wait_trial_result(timeout=0.1).completion_s == pytest.approx(0.49)
    assert not c.trial_results  # handed out once


def test_pose_batch_returns_a_refusal_in_its_place():
    def refuses_third(msg, seq):
        if isinstance(msg, m.Pose) and msg.host_time_us == 3:
            return [m.Error(request_seq=seq, code=m.ErrorCode.NO_SCENE, detail=3)]
        return good_device(msg, seq)

    c = client_for(refuses_third)
    answers = c.pose_batch([(t, (1, 0, 0, 0)) for t in range(6)])
    assert isinstance(answers[3], m.Error) and answers[3].code == m.ErrorCode.NO_SCENE
    assert [a.host_time_us for i, a in enumerate(answers) if i != 3] == [0, 1, 2, 4, 5]


def test_pose_batch_times_out_on_silence():
    c = client_for(lambda msg, seq: [], timeout=0.1)
    with pytest.raises(gt.LinkTimeout, match="no answer to POSE"):
        c.pose_batch([(t, (1, 0, 0, 0)) for t in range(5)])


# --------------------------------------------------------------------------------------
# Protocol versions
# --------------------------------------------------------------------------------------
def test_hello_reply_of_another_version_is_a_mismatch():
    future = m.PROTOCOL_VERSION + 1

    def newer(msg, seq):
        return [m.HelloReply(request_seq=seq, protocol_version=future, board="future")]

    with pytest.raises(gd.ProtocolMismatch, match=f"version {future}") as info:
        client_for(newer).hello()
    assert info.value.device_version == future


def test_frames_of_another_version_are_a_mismatch_not_a_timeout():
    c = client_for(good_device, version=7, timeout=5.0)
    t0 = time.monotonic()
    with pytest.raises(gd.ProtocolMismatch, match="protocol version 7"):
        c.hello()
    assert time.monotonic() - t0 < 1.0


# --------------------------------------------------------------------------------------
# Transports
# --------------------------------------------------------------------------------------
def test_open_port_of_a_missing_path_says_what_to_do():
    with pytest.raises(gt.DeviceNotFound, match="graspguide ports"):
        registry.open_port("/dev/graspguide-no-such-port")
    with pytest.raises(gt.DeviceNotFound, match="--port"):
        registry.open_port("")


def test_missing_sim_binary_names_the_build_command(tmp_path, monkeypatch):
    (tmp_path / "platformio.ini").write_text("[env:sim]\n")
    (tmp_path / "src" / "sim").mkdir(parents=True)
    monkeypatch.delenv(gsim.SIM_ENV, raising=False)
    monkeypatch.setattr(gsim, "find_repo_root", lambda: str(tmp_path))
    with pytest.raises(gt.SimNotBuilt) as info:
        gsim.SimulatedDevice()
    text = str(info.value)
    assert "pio run -e sim" in text and "PLATFORMIO_CORE_DIR=.pio-core" in text
    assert str(tmp_path) in text and ".venv/bin/pio" in text
    assert not (tmp_path / ".pio").exists()  # nothing was built

    monkeypatch.setenv(gsim.SIM_ENV, str(tmp_path / "nope"))
    with pytest.raises(gt.SimNotBuilt, match=gsim.SIM_ENV):
        registry.open_port("sim")


def test_serial_transport_on_a_pty():
    """SerialTransport reads what is there at once, waits at most its timeout, and
    reports a vanished far end as DeviceDisconnected."""
    master, slave = os.openpty()
    t = gt.SerialTransport(os.ttyname(slave))
    try:
        t0 = time.monotonic()
        assert t.read(100, 0.05) == b""
        assert 0.04 <= time.monotonic() - t0 < 0.5
        os.write(master, b"abc")
        assert t.read(100, 1.0) == b"abc"
        t.write(b"xyz")
        assert os.read(master, 10) == b"xyz"
        os.close(master)
        master = None
        with pytest.raises(gt.DeviceDisconnected):
            t.read(10, 0.2)
    finally:
        t.close()
        os.close(slave)
        if master is not None:
            os.close(master)
