"""The host's side of the host-less messages: DeviceClient's plan upload, results log,
host-less run and simulation-only requests against a scripted fake device
(fake_device.FakeDevice); plan_upload.plan_messages from the paper's protocol;
device_log.download_log into the runner's folder format (read back by the analysis);
`graspguide device`. The end-to-end tests at the bottom run the real simulated device."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys

import pytest
from conftest import REPO_ROOT, subprocess_env
from fake_device import FakeDevice, good_device

from graspguide.analysis import paper_tables as analysis
from graspguide.cli import main as cli_main
from graspguide.hostless import device_log as dl
from graspguide.hostless import plan_upload as pu
from graspguide.link import client as gd
from graspguide.link import codec
from graspguide.link import messages as m
from graspguide.protocol.study_protocol import load_protocol
from graspguide.records.trial import HOSTLESS_FIELDS, TRIAL_FIELDS

PAPER = os.path.join(REPO_ROOT, "protocols", "paper.toml")
HOSTLESS_CAPS = m.CAPABILITY_FULL_SOLVE | m.CAPABILITY_HOSTLESS | m.CAPABILITY_SIM_MESSAGES
REST_S = 2.0


@pytest.fixture(scope="module")
def paper():
    protocol = load_protocol(PAPER)
    planned = pu.planned_trials(protocol, "U1")
    begin, trials = pu.plan_messages(protocol, "U1", planned, simulated=True, rest_s=REST_S)
    return protocol, planned, begin, trials


# --------------------------------------------------------------------------------------
# A scripted host-less device
# --------------------------------------------------------------------------------------
def outcome(t: m.PlanTrial, index: int) -> m.LogRecord:
    """A made-up result of a planned trial (every other one a timeout)."""
    success = t.position % 2 == 0
    return m.LogRecord(
        index=index,
        **{f: getattr(t, f) for f in ("trial_index", "session", "session_trial", "k")},
        **{f: getattr(t, f) for f in ("policy", "mode", "familiarization", "single_motor")},
        wrench_class=t.wrench_class,
        wrench_number=t.wrench_number,
        wrench=t.wrench,
        success=success,
        completion_s=5.25 + t.position if success else 90.0,
        first_entry_s=4.5 if success else -1.0,
        final_error_deg=1.25 if success else 30.5,
        samples=1000 + t.position,
        imu_faults=t.position % 3,
    )


class HostlessFake:
    """The device side of the host-less messages, as docs/protocol.md describes them."""

    def __init__(self, caps: int = HOSTLESS_CAPS):
        self.caps = caps
        self.begin: m.PlanBegin | None = None
        self.pending: list[m.PlanTrial] = []
        self.plan: list[m.PlanTrial] = []
        self.stored: m.PlanBegin | None = None
        self.records: list[m.LogRecord] = []
        self.running = False
        self.torn = 0
        self.refuse: dict[tuple[str, int], m.Error] = {}  # (NAME, position) -> ERROR
        self.capacity = 256

    def store(self, begin: m.PlanBegin, trials: list[m.PlanTrial], done: int) -> None:
        self.stored, self.plan = begin, list(trials)
        self.records = [outcome(t, i) for i, t in enumerate(trials[:done])]

    def info(self) -> m.LogInfo:
        b = self.stored
        return m.LogInfo(
            plan_stored=b is not None,
            participant=b.participant if b else "",
            simulated=b.simulated if b else False,
            config_hash=b.config_hash if b else (0,) * 8,
            plan_trials=len(self.plan),
            records=len(self.records),
            capacity=self.capacity,
            torn_records=self.torn,
            running=self.running,
        )

    def __call__(self, msg, seq):
        err = self.refuse.get((msg.NAME, getattr(msg, "position", -1)))
        if err is not None:
            return [dataclasses.replace(err, request_seq=seq)]
        if isinstance(msg, m.Hello):
            reply = good_device(msg, seq)[0]
            return [dataclasses.replace(reply, capabilities=self.caps)]
        if isinstance(msg, m.PlanBegin):
            self.begin, self.pending = msg, []
        elif isinstance(msg, m.PlanTrial):
            if self.begin is None:
                return [m.Error(request_seq=seq, code=m.ErrorCode.NO_PLAN, detail=msg.MSG_ID)]
            self.pending.append(msg)
        elif isinstance(msg, m.PlanCommit):
            assert self.begin is not None and msg.trial_count == len(self.pending)
            self.stored, self.plan, self.begin = self.begin, self.pending, None
        elif isinstance(msg, m.LogInfoGet):
            return [self.info()]
        elif isinstance(msg, m.LogRead):
            if msg.index >= len(self.records):
                return [m.Error(request_seq=seq, code=m.ErrorCode.NO_RECORD)]
            return [self.records[msg.index]]
        elif isinstance(msg, m.LogErase):
            if msg.key != m.LOG_ERASE_KEY:
                return [m.Error(request_seq=seq, code=m.ErrorCode.BAD_PLAN)]
            self.records = []
        elif isinstance(msg, m.HostlessRun):
            self.running = True
        elif isinstance(msg, m.SimImuSample):
            if not self.running:
                return [m.Ack(request_seq=seq)]
            tel = m.Telemetry(host_time_us=msg.time_us, flags=m.TELEMETRY_FLAG_TRIAL_RUNNING)
            if msg.accel_mps2[0] > 0:  # the script's "this sample ends the trial"
                event = m.HostlessEvent(event=m.RunEvent.SUCCESS, position=3, trial_index=4)
                return [event, m.TrialResult(trial_id=4, success=True), tel]
            return [tel]
        elif isinstance(msg, m.Stop):
            self.running = False
        return [m.Ack(request_seq=seq)]


def hostless_client(fake: HostlessFake | None = None) -> gd.DeviceClient:
    c = gd.DeviceClient(FakeDevice(fake or HostlessFake()), timeout=0.2)
    c.hello()
    return c


def sent(c: gd.DeviceClient) -> list:
    return [msg for _, msg in c.transport.received]


# --------------------------------------------------------------------------------------
# plan_messages
# --------------------------------------------------------------------------------------
def test_plan_messages_carry_the_runners_plan(paper):
    protocol, planned, begin, trials = paper
    assert begin.participant == "U1" and begin.simulated is True
    assert bytes(begin.config_hash) == bytes.fromhex(protocol.config_hash)[: m.CONFIG_HASH_SIZE]
    assert begin.trial_count == len(planned) == len(trials)
    assert begin.constraints is gd.CONSTRAINT_NAMES[protocol.constraints]
    assert begin.threshold_deg == gd.to_f32(protocol.threshold_deg)
    assert begin.timeout_s == gd.to_f32(protocol.timeout_s) and begin.rest_s == REST_S
    assert begin.hand_k3 == tuple(tuple(map(gd.to_f32, c)) for c in protocol.hands[3])
    assert begin.hand_k4 == tuple(tuple(map(gd.to_f32, c)) for c in protocol.hands[4])
    classes = {"single": m.WrenchClass.SINGLE, "multi": m.WrenchClass.MULTI, "": 0}
    for i, (t, p) in enumerate(zip(trials, planned)):
        assert t.position == i and t.trial_index == p.trial_index
        assert (t.session, t.session_trial, t.k) == (p.session, p.session_trial, p.k)
        assert (t.policy, t.mode) == (gd.POLICY_NAMES[p.policy], gd.MODE_NAMES[p.mode])
        assert t.familiarization == p.familiarization and t.single_motor == p.single_motor
        assert t.wrench_class == classes[p.wrench_class]
        prefix = "F" if p.familiarization else "W"
        assert p.wrench_id == f"{prefix}{t.wrench_number:02d}"
        assert t.wrench == tuple(map(gd.to_f32, p.wrench))
    # Every message survives the wire unchanged.
    for msg in (begin, *trials):
        frame = codec.check_frame(codec.cobs_decode(codec.encode_message(msg, 1)[:-1]))[1]
        assert codec.message_of(frame) == msg


def test_plan_messages_carry_the_participants_calibration(paper):
    from graspguide.core.motor_calibration import MotorCalibration

    protocol, planned, begin, _ = paper
    assert (begin.pwm_floor, begin.gain) == ((70,) * 4, (1.0,) * 4), "none: the identity"
    # A gain that is not a float32 crosses the wire rounded, as the device will hold it.
    cal = MotorCalibration((60, 0, 254, 70), (0.25, 1.1, 4.0, 1.0))
    calibrated, _ = pu.plan_messages(protocol, "U1", planned, True, REST_S, calibration=cal)
    assert calibrated.pwm_floor == cal.pwm_floor
    assert calibrated.gain == tuple(gd.to_f32(g) for g in cal.gain)
    assert calibrated.gain[1] != 1.1 and abs(calibrated.gain[1] - 1.1) < 1e-7
    assert dataclasses.replace(calibrated, pwm_floor=begin.pwm_floor, gain=begin.gain) == begin
    frame = codec.check_frame(codec.cobs_decode(codec.encode_message(calibrated, 1)[:-1]))[1]
    assert codec.message_of(frame) == calibrated


def _calibrate_record(participant: str, cal: dict) -> dict:
    """A calibration.json as `graspguide calibrate` writes it (its schema), holding ``cal``."""
    from graspguide.calibration.calibration_file import SCHEMA

    return {
        "schema": SCHEMA,
        "participant": participant,
        "date": "2026-11-24T12:00:00+00:00",
        "operator": "test",
        "simulated": True,
        "calibration": cal,
        "fingers": {},
        "trials": [],
        "false_alarm_rate": None,
    }


def test_a_calibration_file_is_read_or_refused_naming_file_and_field(tmp_path):
    from graspguide.calibration import calibration_file as cf
    from graspguide.core.motor_calibration import MotorCalibration

    bare = {"pwm_floor": [60, 80, 70, 70], "gain": [1.5, 0.5, 1, 1]}
    want = MotorCalibration((60, 80, 70, 70), (1.5, 0.5, 1, 1))
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(bare))
    assert cf.read_calibration(str(path)) == want
    # The file `graspguide calibrate` writes, read the same.
    full = tmp_path / "full.json"
    full.write_text(json.dumps(_calibrate_record("U1", bare)))
    assert cf.read_calibration(str(full)) == want
    # OUT/PID/calibration.json is picked up; none means the identity (None).
    (tmp_path / "U1").mkdir()
    assert cf.load_participant_calibration(str(tmp_path), "U1") is None
    full.replace(cf.calibration_path(str(tmp_path), "U1"))
    assert cf.load_participant_calibration(str(tmp_path), "U1") == want
    # Another participant's file in U1's folder is refused, not used.
    (tmp_path / "U1" / "calibration.json").write_text(json.dumps(_calibrate_record("U2", bare)))
    with pytest.raises(ValueError, match="another participant"):
        cf.load_participant_calibration(str(tmp_path), "U1")
    for content, words in [
        ("[1, 2]", "must be an object"),
        ('{"gain": [1, 1, 1, 1]}', "missing pwm_floor"),
        ('{"pwm_floor": [70, 70, 70, 70.5], "gain": [1, 1, 1, 1]}', "pwm_floor[3] (palm)"),
        ('{"pwm_floor": [70, 70, 70, 70], "gain": [1, 1, 0.1, 1]}', "gain[2] (middle)"),
        ("not json", "is not JSON"),
        (json.dumps({**_calibrate_record("U1", bare), "operator": None}), "'operator'"),
    ]:
        bad = tmp_path / "bad.json"
        bad.write_text(content)
        with pytest.raises(ValueError) as e:
            cf.read_calibration(str(bad))
        assert words in str(e.value) and str(bad) in str(e.value), str(e.value)
    with pytest.raises(ValueError, match="does not exist.*graspguide calibrate"):
        cf.read_calibration(str(tmp_path / "missing.json"))


def test_plan_messages_refuse_what_the_device_cannot_hold(paper):
    protocol, planned, _, _ = paper
    with pytest.raises(ValueError, match=rf"1\.\.{m.MAX_PLAN_TRIALS}.*\[wrenches\] count"):
        pu.plan_messages(protocol, "U1", planned * 2, True, REST_S)
    long_id = "U" * m.PARTICIPANT_ID_SIZE + "1"
    long_plan = [dataclasses.replace(t, participant=long_id) for t in planned]
    with pytest.raises(ValueError, match="participant.*characters.*shorter id"):
        pu.plan_messages(protocol, long_id, long_plan, True, REST_S)
    big = [dataclasses.replace(planned[-1], wrench_id="W256")]
    with pytest.raises(ValueError, match=r"W256.*1\.\.255.*\[wrenches\] count"):
        pu.plan_messages(protocol, "U1", big, True, REST_S)
    with pytest.raises(ValueError, match="rest_s must be in"):
        pu.plan_messages(protocol, "U1", planned, True, -1.0)
    with pytest.raises(ValueError, match="imu_to_hand_wxyz.*unit quaternion"):
        pu.plan_messages(protocol, "U1", planned, True, REST_S, (1, 1, 0, 0))
    with pytest.raises(ValueError, match="planned for 'U1', not 'U2'"):
        pu.plan_messages(protocol, "U2", planned, True, REST_S)


# --------------------------------------------------------------------------------------
# DeviceClient: the requests
# --------------------------------------------------------------------------------------
def test_upload_plan_sends_begin_trials_commit_in_order(paper):
    _, _, begin, trials = paper
    fake = HostlessFake()
    c = hostless_client(fake)
    c.upload_plan(begin, trials)
    msgs = sent(c)[1:]
    assert msgs[0] == begin and msgs[1:-1] == trials
    assert msgs[-1] == m.PlanCommit(trial_count=len(trials))
    assert fake.stored == begin and fake.plan == trials
    with pytest.raises(ValueError, match="trial_count is 3 but 100"):
        c.upload_plan(dataclasses.replace(begin, trial_count=3), trials)
    with pytest.raises(ValueError, match="position"):
        c.upload_plan(begin, list(reversed(trials)))


def test_upload_plan_sends_the_calibration_in_plan_begin(paper):
    from graspguide.core.motor_calibration import MotorCalibration

    protocol, planned, _, _ = paper
    cal = MotorCalibration((60, 75, 80, 90), (1.25, 0.75, 2.0, 0.5))
    begin, trials = pu.plan_messages(protocol, "U1", planned, True, REST_S, calibration=cal)
    fake = HostlessFake()
    hostless_client(fake).upload_plan(begin, trials, calibration=cal)
    assert fake.stored.pwm_floor == cal.pwm_floor and fake.stored.gain == cal.gain
    assert fake.stored == begin


def _index(cls, name: str) -> int:
    return [f.name for f in cls.FIELDS].index(name)


@pytest.mark.parametrize(
    "request_name, position, detail, words",
    [
        ("PLAN_BEGIN", -1, _index(m.PlanBegin, "rest_s"), ["'rest_s'", "0..600"]),
        ("PLAN_BEGIN", -1, _index(m.PlanBegin, "hold_s"), ["'hold_s'", "must be in [0, 600] s"]),
        ("PLAN_TRIAL", 5, _index(m.PlanTrial, "k"), ["'k'", "plan position 5", "trial_index 6"]),
        ("PLAN_COMMIT", -1, 7, ["position 7", "upload the whole plan again"]),
    ],
)
def test_upload_refusals_name_the_field_or_trial(paper, request_name, position, detail, words):
    _, _, begin, trials = paper
    fake = HostlessFake()
    fake.refuse[(request_name, position)] = m.Error(code=m.ErrorCode.BAD_PLAN, detail=detail)
    c = hostless_client(fake)
    with pytest.raises(gd.DeviceError) as e:
        c.upload_plan(begin, trials)
    assert e.value.code_name == "bad_plan" and e.value.request == request_name
    for word in words:
        assert word in str(e.value), (word, str(e.value))
    assert fake.stored is None  # nothing committed


def test_commit_of_an_unsolvable_trial_names_its_position(paper):
    _, _, begin, trials = paper
    fake = HostlessFake()
    fake.refuse[("PLAN_COMMIT", -1)] = m.Error(code=m.ErrorCode.COINCIDENT_CONTACTS, detail=42)
    with pytest.raises(gd.DeviceError, match="trial at position 42 cannot be solved"):
        hostless_client(fake).upload_plan(begin, trials)


def test_log_requests(paper):
    _, _, begin, trials = paper
    fake = HostlessFake()
    fake.store(begin, trials, done=3)
    c = hostless_client(fake)
    info = c.log_info()
    assert (info.participant, info.records, info.plan_trials) == ("U1", 3, len(trials))
    assert c.log_read(2) == fake.records[2]
    with pytest.raises(gd.DeviceError, match="no_record"):
        c.log_read(3)
    with pytest.raises(ValueError, match="0..65535"):
        c.log_read(-1)
    c.log_erase()
    assert sent(c)[-1] == m.LogErase(key=m.LOG_ERASE_KEY) and c.log_info().records == 0
    c.hostless_run()
    assert fake.running and isinstance(sent(c)[-1], m.HostlessRun)
    c.sim_button(True)
    assert sent(c)[-1] == m.SimButton(pressed=True)


def test_sim_imu_sample_answers_and_parks_what_the_sample_caused():
    c = hostless_client()
    assert c.sim_imu_sample(10, (0, 0, 9.81), (0, 0, 0)) is None  # no run: ACK
    c.hostless_run()
    tel = c.sim_imu_sample(2**32 + 20, (0, 0, 9.81), (0.1, 0, 0))
    assert tel is not None and tel.host_time_us == 20  # time_us & 0xFFFFFFFF
    assert not c.hostless_events and not c.trial_results
    tel = c.sim_imu_sample(30, (1.0, 0, 9.81), (0, 0, 0))  # the scripted trial end
    assert tel.host_time_us == 30
    assert [e.event for e in c.hostless_events] == [m.RunEvent.SUCCESS]
    assert c.trial_results[0].trial_id == 4 and c.counters()["hostless_events_queued"] == 1
    msg = sent(c)[-1]
    assert msg.time_us == 30 and msg.accel_mps2 == (1.0, 0.0, gd.to_f32(9.81))


def test_sim_only_refusal_and_missing_capability():
    fake = HostlessFake(caps=m.CAPABILITY_FULL_SOLVE)
    fake.refuse[("SIM_BUTTON", -1)] = m.Error(code=m.ErrorCode.SIM_ONLY, detail=m.MsgId.SIM_BUTTON)
    c = hostless_client(fake)
    with pytest.raises(gd.DeviceError, match="SIM_BUTTON is for the simulated device only"):
        c.sim_button(True)
    with pytest.raises(gd.LinkError, match="cannot do a host-less results log.*0x01"):
        c.require_capability(m.CAPABILITY_HOSTLESS, "a host-less results log")


def test_unsolicited_events_are_parked_behind_other_answers():
    fake = HostlessFake()
    event = m.HostlessEvent(event=m.RunEvent.READY, position=0, trial_index=1)

    def respond(msg, seq):
        return [event, *fake(msg, seq)] if isinstance(msg, m.LogInfoGet) else fake(msg, seq)

    c = gd.DeviceClient(FakeDevice(respond), timeout=0.2)
    c.log_info()
    assert c.hostless_events == [event]


# --------------------------------------------------------------------------------------
# download_log
# --------------------------------------------------------------------------------------
def _stored_client(paper, done: int, **fake_args) -> tuple[gd.DeviceClient, HostlessFake]:
    _, _, begin, trials = paper
    fake = HostlessFake(**fake_args)
    fake.store(begin, trials, done)
    return hostless_client(fake), fake


def _lines(path) -> list[dict]:
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f]


def test_download_writes_the_runners_format(paper, tmp_path, capsys):
    protocol, planned, _, trials = paper
    done = 30  # past the familiarization trials, into the sessions
    c, fake = _stored_client(paper, done)
    s = dl.download_log(c, str(tmp_path))
    assert (s.participant, s.records, s.new, s.total) == ("U1", done, done, done)
    assert s.config_hash == protocol.config_hash[:16] and s.torn_records == 0
    recs = _lines(tmp_path / "U1" / "trials.jsonl")
    assert len(recs) == done
    for rec, p, t, stored in zip(recs, planned, trials, fake.records):
        assert set(rec) == set(TRIAL_FIELDS) | set(HOSTLESS_FIELDS)
        for key in ("trial_index", "session", "session_trial", "k", "policy", "mode"):
            assert rec[key] == getattr(p, key), key
        for key in ("modality", "wrench_id", "single_motor", "wrench_class", "familiarization"):
            assert rec[key] == getattr(p, key), key
        assert [gd.to_f32(v) for v in rec["wrench"]] == list(t.wrench)
        assert rec["success"] is stored.success and rec["poses"] == stored.samples
        assert gd.to_f32(rec["completion_s"]) == stored.completion_s
        assert rec["imu_faults"] == stored.imu_faults and rec["hostless"] is True
        assert rec["source"] == "hostless" and rec["wall_s"] is None
        assert rec["participant"] == "U1" and rec["simulated"] is True
        assert rec["config_hash"] == protocol.config_hash[:16]
    meta = json.loads((tmp_path / "U1" / "device_log.json").read_text())
    assert meta["log_info"]["records"] == done and meta["device"]["board"] == "fake"
    # The analysis reads it as it reads the runner's folder.
    frames, tlx = analysis.load([str(tmp_path)])
    assert len(frames) == done and frames["familiarization"].sum() == sum(
        p.familiarization for p in planned[:done]
    )
    sessions = {p.session for p in planned[:done] if p.session >= 1}
    assert set(tlx["session"]) == sessions and tlx["MD"].isna().all()
    assert capsys.readouterr().err == ""


def test_download_again_is_idempotent_and_adds_new_records(paper, tmp_path):
    c, fake = _stored_client(paper, 10)
    dl.download_log(c, str(tmp_path))
    path = tmp_path / "U1" / "trials.jsonl"
    first = path.read_bytes()
    s = dl.download_log(c, str(tmp_path))
    assert path.read_bytes() == first and (s.new, s.total) == (0, 10)
    fake.records = [outcome(t, i) for i, t in enumerate(fake.plan[:15])]
    s = dl.download_log(c, str(tmp_path))
    assert (s.new, s.total) == (5, 15) and path.read_bytes().startswith(first)
    # The device's log erased after the download: the folder keeps its records.
    fake.records = []
    s = dl.download_log(c, str(tmp_path))
    assert (s.records, s.total) == (0, 15)
    assert [r["trial_index"] for r in _lines(path)] == list(range(1, 16))


@pytest.mark.parametrize(
    "change, words",
    [
        ({"participant": "U2"}, "participant 'U2'"),
        ({"config_hash": "00" * 32}, "another protocol"),
        ({"hostless": None, "source": "participant"}, "host-driven trial"),
        ({"simulated": False}, "human trials"),
        ({"success": None}, "another result"),
    ],
)
def test_a_folder_of_another_study_is_refused_and_kept(paper, tmp_path, change, words):
    c, _ = _stored_client(paper, 4)
    dl.download_log(c, str(tmp_path))
    path = tmp_path / "U1" / "trials.jsonl"
    recs = _lines(path)
    recs[0].update(change)
    if "success" in change:
        recs[0]["success"] = not _lines(path)[0]["success"]
    path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    before = path.read_bytes()
    with pytest.raises(dl.DeviceLogError, match=words) as e:
        dl.download_log(c, str(tmp_path))
    assert e.value.usage and path.read_bytes() == before


def test_a_study_folder_of_another_protocol_is_refused(paper, tmp_path):
    c, _ = _stored_client(paper, 2)
    (tmp_path / "study.json").write_text(json.dumps({"config_hash": "ab" * 32}))
    with pytest.raises(dl.DeviceLogError, match="another protocol"):
        dl.download_log(c, str(tmp_path))
    assert not (tmp_path / "U1").exists()


def test_no_plan_torn_records_and_a_damaged_record(paper, tmp_path, capsys):
    c = hostless_client()
    with pytest.raises(dl.DeviceLogError, match="no host-less plan"):
        dl.download_log(c, str(tmp_path))
    c, fake = _stored_client(paper, 3)
    fake.torn = 2
    s = dl.download_log(c, str(tmp_path))
    assert s.torn_records == 2 and "2 torn record(s)" in capsys.readouterr().err
    fake.capacity = 3
    dl.download_log(c, str(tmp_path))
    assert "log is full (3 of 3 records)" in capsys.readouterr().err
    fake.records[1] = dataclasses.replace(fake.records[1], completion_s=float("nan"))
    with pytest.raises(dl.DeviceLogError, match="record 1 .*completion_s"):
        dl.download_log(c, str(tmp_path / "other"))


def test_empty_log_writes_an_empty_folder_the_analysis_refuses_clearly(paper, tmp_path):
    c, _ = _stored_client(paper, 0)
    s = dl.download_log(c, str(tmp_path))
    assert (s.records, s.total, s.plan_trials) == (0, 0, 100)
    assert (tmp_path / "U1" / "trials.jsonl").read_text() == ""
    with pytest.raises(analysis.AnalysisError, match="no trials in"):
        analysis.load([str(tmp_path)])


# --------------------------------------------------------------------------------------
# `graspguide device`
# --------------------------------------------------------------------------------------
@pytest.fixture
def fake_port(monkeypatch, paper):
    """`--port fake` opens a scripted device holding the paper's plan with 6 records."""
    fake = HostlessFake()
    fake.store(paper[2], paper[3], 6)
    opened = []

    def open_port(port, baudrate=115200, **kw):
        assert port == "fake" and not kw
        opened.append(port)
        return FakeDevice(fake)

    monkeypatch.setattr("graspguide.devices.registry.open_port", open_port)
    return fake


def test_device_log_info_and_erase_commands(fake_port, tmp_path, capsys):
    out = str(tmp_path / "study")
    assert cli_main(["device", "log", "--port", "fake", "--out", out]) == 0
    assert "6 record(s) of 100 planned trials" in capsys.readouterr().out
    assert len(_lines(os.path.join(out, "U1", "trials.jsonl"))) == 6
    assert cli_main(["device", "info", "--port", "fake", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["participant"], info["records"], info["plan_trials"]) == ("U1", 6, 100)
    assert cli_main(["device", "erase", "--port", "fake"]) == 2
    assert "--yes" in capsys.readouterr().err and len(fake_port.records) == 6
    assert cli_main(["device", "erase", "--port", "fake", "--yes"]) == 0
    assert fake_port.records == []


def test_device_command_usage_errors(fake_port, tmp_path, capsys):
    assert cli_main(["device", "info", "--port", "sim"]) == 2
    assert "--store FILE" in capsys.readouterr().err
    assert cli_main(["device", "info", "--port", "fake", "--store", "x"]) == 2
    assert "--port sim only" in capsys.readouterr().err
    (tmp_path / "study.json").write_text(json.dumps({"config_hash": "ab" * 32}))
    assert cli_main(["device", "log", "--port", "fake", "--out", str(tmp_path)]) == 2
    assert "another protocol" in capsys.readouterr().err
    fake_port.stored = None
    assert cli_main(["device", "log", "--port", "fake", "--out", str(tmp_path / "b")]) == 1
    assert "no host-less plan" in capsys.readouterr().err


def test_device_command_is_registered():
    r = subprocess.run(
        [sys.executable, "-m", "graspguide", "device", "log", "--help"],
        capture_output=True,
        env=subprocess_env(),
        cwd=REPO_ROOT,  # not tools/: `-m graspguide` must find the installed package
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    for word in ("--port", "--out", "--store"):
        assert word in r.stdout.decode(), word


# --------------------------------------------------------------------------------------
# The real simulated device (--store FILE: its non-volatile memory)
# --------------------------------------------------------------------------------------
def sim_client(store) -> gd.DeviceClient:
    from graspguide.devices.sim import SimulatedDevice

    device = SimulatedDevice(virtual_clock=True, extra_args=["--store", str(store)]).start()
    c = gd.DeviceClient(device, timeout=2.0)
    c.hello()
    return c


def test_sim_stores_the_paper_plan_across_restarts(paper, tmp_path, capsys):
    protocol, _, begin, trials = paper
    store = tmp_path / "U1.store"
    with sim_client(store) as c:
        caps = c.device_info.capabilities
        assert caps & m.CAPABILITY_HOSTLESS and caps & m.CAPABILITY_SIM_MESSAGES
        assert not c.log_info().plan_stored
        with pytest.raises(dl.DeviceLogError, match="no host-less plan"):
            dl.download_log(c, str(tmp_path / "none"))
        with pytest.raises(gd.DeviceError, match="'rest_s'"):
            c.upload_plan(dataclasses.replace(begin, rest_s=pu.REST_S_RANGE[1] * 2), trials)
        c.upload_plan(begin, trials)
    with sim_client(store) as c:  # a power cycle: the plan is still there
        info = c.log_info()
        assert info.plan_stored and info.participant == "U1" and info.simulated
        assert (info.plan_trials, info.records, info.running) == (len(trials), 0, False)
        assert bytes(info.config_hash).hex() == protocol.config_hash[:16]
    out = tmp_path / "study"
    args = ["--port", "sim", "--store", str(store)]
    assert cli_main(["device", "info", *args, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["plan_trials"] == len(trials)
    assert cli_main(["device", "log", *args, "--out", str(out)]) == 0
    assert "0 record(s) of 100 planned trials" in capsys.readouterr().out
    assert (out / "U1" / "trials.jsonl").read_text() == ""
    with pytest.raises(analysis.AnalysisError, match="no trials in"):
        analysis.load([str(out)])


def test_device_plan_and_run_commands_on_the_sim(tmp_path, capsys):
    store = tmp_path / "U2.store"
    args = ["--port", "sim", "--store", str(store)]
    plan = ["device", "plan", *args, "--protocol", PAPER, "--participant", "U2"]
    # A mounting that is no rotation, and a bad participant id: refused before anything.
    with pytest.raises(SystemExit) as refused:
        cli_main([*plan, "--imu-to-hand", "0,0,0,0"])
    assert refused.value.code == 2 and "not all zero" in capsys.readouterr().err
    assert cli_main([*plan[:-1], "Bob"]) == 2
    assert "ending with a number" in capsys.readouterr().err
    quarter_turn = "0.70710678,0,0,0.70710678"
    assert cli_main([*plan, "--simulated", "--rest-s", "1.5", "--imu-to-hand", quarter_turn]) == 0
    assert "100 trials" in capsys.readouterr().out
    with sim_client(store) as c:
        info = c.log_info()
        assert (info.participant, info.simulated, info.plan_trials) == ("U2", True, 100)
        assert not info.running
    assert cli_main(["device", "run", *args]) == 0
    assert "0 of 100 trials already have a record" in capsys.readouterr().out
    # The same participant's plan again is accepted (nothing recorded yet), a person's too.
    assert cli_main(plan) == 0
    assert "stored the plan of participant U2" in capsys.readouterr().out


def test_sim_hostless_run_answers_samples_with_telemetry(paper, tmp_path):
    _, _, begin, trials = paper
    with sim_client(tmp_path / "U1.store") as c:
        assert c.sim_imu_sample(1000, (0, 0, 9.81), (0, 0, 0)) is None  # no run: ACK
        c.upload_plan(dataclasses.replace(begin, rest_s=0.0), trials)
        c.hostless_run()
        assert c.log_info().running
        t_us = 2000
        tel = c.sim_imu_sample(t_us, (0, 0, 9.81), (0, 0, 0))
        assert tel is not None and tel.host_time_us == t_us
        c.stop()
        assert not c.log_info().running


SAMPLE_PERIOD_US = 10_000  # the world's IMU at 100 Hz
SHORT_TIMEOUT_S = 1.0  # every trial of the short plan times out after this
GRAVITY_MPS2 = 9.81


def test_sim_records_download_and_analyse(paper, tmp_path):
    """Three session trials run host-less on the simulated device (a hand held still, a
    little sensor noise so the IMU is not stuck), the button pressed at each ready
    pattern; the downloaded log holds their records and the analysis reads them."""
    protocol, planned, begin, trials = paper
    first = next(i for i, p in enumerate(planned) if not p.familiarization)
    short = [dataclasses.replace(t, position=i) for i, t in enumerate(trials[first : first + 3])]
    begin = dataclasses.replace(
        begin, trial_count=3, timeout_s=SHORT_TIMEOUT_S, hold_s=0.2, rest_s=0.0
    )
    max_samples = 3 * 4 * int(SHORT_TIMEOUT_S * 1e6 / SAMPLE_PERIOD_US)  # ample
    with sim_client(tmp_path / "U1.store") as c:
        c.upload_plan(begin, short)
        c.hostless_run()
        t_us, pressed = 0, 0
        for n in range(max_samples):
            t_us += SAMPLE_PERIOD_US
            noise = 1e-3 * (n % 3)
            tel = c.sim_imu_sample(t_us, (noise, 0, GRAVITY_MPS2), (0, noise, 0))
            assert tel is not None and tel.host_time_us == t_us
            last = c.hostless_events[-1].event if c.hostless_events else None
            if last == m.RunEvent.READY and pressed < len(c.hostless_events):
                c.sim_button(True)
                c.sim_button(False)
                pressed = len(c.hostless_events)
            if last == m.RunEvent.PLAN_DONE:
                break
        events = [e.event for e in c.hostless_events]
        assert events[-1] == m.RunEvent.PLAN_DONE, events
        assert events.count(m.RunEvent.TRIAL_STARTED) == 3
        s = dl.download_log(c, str(tmp_path / "out"))
    assert (s.records, s.new, s.torn_records, s.running) == (3, 3, 0, False)
    recs = _lines(tmp_path / "out" / "U1" / "trials.jsonl")
    assert [r["trial_index"] for r in recs] == [t.trial_index for t in short]
    assert [r["wrench_id"] for r in recs] == [p.wrench_id for p in planned[first : first + 3]]
    for r in recs:
        assert r["success"] is False and r["completion_s"] == SHORT_TIMEOUT_S
        assert r["poses"] > 0 and r["hostless"] is True
    frames, tlx = analysis.load([str(tmp_path / "out")])
    assert len(frames) == 3 and not frames["familiarization"].any()
    assert list(tlx["session"]) == [planned[first].session]
