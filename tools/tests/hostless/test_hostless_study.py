"""The simulated host-less study: the IMU world's signals, and whole
host-less runs on the real simulated device (`pio run -e sim`): a participant's study
finishes and analyses; a SIGKILL of the device mid-study loses no completed trial record;
the run resumes. SIMULATED throughout."""

from __future__ import annotations

import io
import json
import math
import signal
import subprocess
import sys

import numpy as np
import pytest
from conftest import small_protocol_toml, subprocess_env

from graspguide.hostless import runner as hr
from graspguide.hostless.imu_world import IDEAL_IMU, ImuWorld
from graspguide.imu.synthetic import STANDARD_GRAVITY_MPS2, ImuNoise
from graspguide.link import client as dv
from graspguide.link.transport import LinkError
from graspguide.protocol import study_protocol as pf
from graspguide.sources.trial_sources import open_runner_source
from graspguide.study.progress import Progress

RATE_HZ = 100.0


# --------------------------------------------------------------------------------------
# Quaternions computed here independently of the world's rotation matrices (q v q*).
# --------------------------------------------------------------------------------------
def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def qconj(q):
    return np.array([q[0], -q[1], -q[2], -q[3]])


def rotate(q, v):
    """v rotated by the unit quaternion q: q v q*."""
    return qmul(qmul(q, np.concatenate([[0.0], v])), qconj(q))[1:]


def axis_angle(axis, angle_rad):
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    return np.concatenate([[math.cos(angle_rad / 2)], math.sin(angle_rad / 2) * a])


# A mount that is no symmetry of the problem: IMU axes turned 70 deg about (1, 2, 3).
MOUNT = axis_angle([1.0, 2.0, 3.0], math.radians(70.0))
# A tilted hand pose.
TILT = axis_angle([0.3, -1.0, 0.2], math.radians(40.0))


def test_a_turn_at_a_known_rate_reads_that_rate_in_imu_axes():
    rate_dps = 90.0  # the fastest turn the virtual participant makes
    axis_hand = np.array([0.2, 0.9, -0.4]) / np.linalg.norm([0.2, 0.9, -0.4])
    world = ImuWorld(RATE_HZ, seed=1, noise=IDEAL_IMU, imu_to_hand_wxyz=MOUNT)
    readings = []
    for i in range(50):
        t = i / RATE_HZ
        # the hand turns about a fixed axis of its own frame: q(t) = TILT * rot(axis, w t)
        q = qmul(TILT, axis_angle(axis_hand, math.radians(rate_dps) * t))
        readings.append(world.sample(t, q).gyro_radps)
    # v_imu = R(mount)^T v_hand, i.e. the inverse rotation of the mount
    expected = rotate(qconj(MOUNT), math.radians(rate_dps) * axis_hand)
    for g in readings[1:]:
        np.testing.assert_allclose(g, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(readings[0], 0.0, atol=0)  # no predecessor: no rotation


def test_at_rest_the_accelerometer_reads_g_up_in_imu_axes():
    world = ImuWorld(RATE_HZ, seed=2, noise=IDEAL_IMU, imu_to_hand_wxyz=MOUNT)
    up_world = np.array([0.0, 0.0, STANDARD_GRAVITY_MPS2])
    # world -> hand is TILT*, hand -> IMU is MOUNT*
    expected = rotate(qconj(MOUNT), rotate(qconj(TILT), up_world))
    for i in range(5):
        s = world.sample(i / RATE_HZ, TILT)
        np.testing.assert_allclose(s.accel_mps2, expected, rtol=0, atol=1e-9)
        np.testing.assert_allclose(s.gyro_radps, 0.0, atol=1e-12)
    assert abs(np.linalg.norm(expected) - STANDARD_GRAVITY_MPS2) < 1e-9
    # not the hand's axes: the mount is really applied
    assert np.linalg.norm(expected - rotate(qconj(TILT), up_world)) > 1.0


def test_with_the_default_noise_the_means_are_the_bias_and_gravity():
    noise = ImuNoise()
    world = ImuWorld(RATE_HZ, seed=3, noise=noise, imu_to_hand_wxyz=MOUNT)
    n = 6000  # 60 s: the arm's 0.2-2 Hz translation averages out
    samples = [world.sample(i / RATE_HZ, TILT) for i in range(n)]
    gyro = np.array([s.gyro_radps for s in samples])
    accel = np.array([s.accel_mps2 for s in samples])
    gyro_sigma = math.radians(noise.gyro_noise_dps_rthz) * math.sqrt(RATE_HZ / 2)
    # bias in the IMU's own axes; the mean of n samples is within 5 sigma / sqrt(n)
    np.testing.assert_allclose(
        gyro.mean(axis=0), np.radians(noise.gyro_bias_dps), atol=5 * gyro_sigma / math.sqrt(n)
    )
    assert np.all(gyro.std(axis=0) > 0.5 * gyro_sigma)  # the noise is there
    up_imu = rotate(qconj(MOUNT), rotate(qconj(TILT), [0.0, 0.0, STANDARD_GRAVITY_MPS2]))
    np.testing.assert_allclose(accel.mean(axis=0), up_imu, atol=0.1)
    assert np.all(accel.std(axis=0) > 0.05)  # the arm's translation and the noise


def test_the_cli_states_the_runners_defaults():
    from graspguide.cli import common

    assert common.DEFAULT_REST_S == hr.DEFAULT_REST_S


def test_the_world_refuses_bad_input():
    with pytest.raises(ValueError, match="imu_to_hand_wxyz"):
        ImuWorld(RATE_HZ, seed=0, imu_to_hand_wxyz=(2.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="rate_hz"):
        ImuWorld(0.0, seed=0)
    world = ImuWorld(RATE_HZ, seed=0)
    world.sample(0.0, (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="increase"):
        world.sample(0.0, (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="hand orientation"):
        world.sample(0.01, (float("nan"), 0.0, 0.0, 0.0))
    with pytest.raises(hr.RunnerError, match="--rest-s"):
        hr.check_settings(-1.0, 0.5, (1.0, 0.0, 0.0, 0.0))


def test_the_hand_returns_to_the_start_within_the_gyro_range():
    start = np.array([1.0, 0.0, 0.0, 0.0])
    ret = hr._HandReturn(axis_angle([1.0, 0.0, 0.0], math.radians(150.0)), start, 10.0)
    world = ImuWorld(RATE_HZ, seed=0, noise=IDEAL_IMU)
    peak = 0.0
    t = 10.0
    while t < ret.end_s + 0.05:
        peak = max(peak, np.linalg.norm(world.sample(t, ret.at(t)).gyro_radps))
        t += 1 / RATE_HZ
    np.testing.assert_allclose(ret.at(ret.end_s), start)
    assert math.degrees(peak) <= hr.HAND_RETURN_PEAK_DPS * 1.01


# --------------------------------------------------------------------------------------
# On the simulated device
# --------------------------------------------------------------------------------------
# A short protocol: one contact count, the four modalities, two wrenches each (8 trials),
# a 60 s timeout (V trials succeed in it), and one familiarization trial (session 0 goes
# through the log too).
SHORT = small_protocol_toml("hostless-short", seed=11, familiarization_trials=1)
REST_S = 0.3


def short_protocol(tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SHORT)
    return str(path), pf.load_protocol(str(path))


def read_lines(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f]


def gg(*args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "graspguide", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=subprocess_env(),
    )


def test_one_participants_hostless_study_finishes_and_analyses(tmp_path):
    path, protocol = short_protocol(tmp_path)
    out = tmp_path / "study"
    r = gg(
        "trial",
        "--protocol",
        path,
        "--participant",
        "U1",
        "--port",
        "sim",
        "--source",
        "participant",
        "--hostless",
        "--rest-s",
        str(REST_S),
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "SIMULATED" in r.stdout
    planned = pf.plan(protocol, "U1")
    trials = read_lines(out / "U1" / "trials.jsonl")
    assert sorted(t["trial_index"] for t in trials) == [t.trial_index for t in planned]
    assert all(t["simulated"] and t["hostless"] for t in trials)
    assert all(t["poses"] > 0 for t in trials)  # IMU samples the device used
    assert (out / "U1" / "device-store.bin").is_file()
    assert (out / "study.json").is_file() and (out / "U1" / "plan.json").is_file()
    tlx = read_lines(out / "U1" / "tlx.jsonl")
    assert len(tlx) == protocol.sessions_per_participant
    assert all(line["scales"] is None for line in tlx)
    world = read_lines(out / "U1" / "world.jsonl")  # the true error beside the device's
    assert sorted(w["trial_index"] for w in world) == [t.trial_index for t in planned]
    for w in world:
        assert w["simulated"]
        assert abs(w["device_final_error_deg"] - w["true_final_error_deg"]) <= 3.0
    runs = read_lines(out / "U1" / "runs.jsonl")
    assert runs[0]["event"] == "start" and runs[0]["hostless"] and runs[0]["simulated"]
    assert runs[-1]["event"] == "end" and runs[-1]["outcome"] == "complete"

    a = gg("analyze", str(out))
    assert a.returncode == 0, a.stdout + a.stderr

    # Run again: nothing left to run; the same records are downloaded again.
    again = gg(
        "trial",
        "--protocol",
        path,
        "--participant",
        "U1",
        "--port",
        "sim",
        "--source",
        "participant",
        "--hostless",
        "--out",
        str(out),
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert "0 run now" in again.stdout
    assert read_lines(out / "U1" / "trials.jsonl") == trials


class _KillAfter:
    """A DeviceClient that SIGKILLs the simulated device ``samples_later`` IMU samples
    after the ``n``-th TRIAL_RESULT: in the middle of the next rest or trial."""

    def __init__(self, client, device, n, samples_later):
        self._client = client
        self._device = device
        self._n = n
        self._later = samples_later
        self.results = []
        self.killed = False

    def __getattr__(self, name):
        return getattr(self._client, name)

    def on_result(self, result):
        self.results.append(result)

    def sim_imu_sample(self, *args, **kwargs):
        if len(self.results) >= self._n and not self.killed:
            self._later -= 1
            if self._later <= 0:
                self.killed = True
                self._device.process.send_signal(signal.SIGKILL)
                self._device.process.wait()
        return self._client.sim_imu_sample(*args, **kwargs)


def _f32(x):
    return dv.to_f32(x)


def test_a_sigkill_mid_study_loses_no_completed_trial_record(tmp_path, report_figure):
    from graspguide.devices.sim import SimulatedDevice
    from graspguide.hostless.device_log import download_log

    _, protocol = short_protocol(tmp_path)
    out = tmp_path / "study"
    store = tmp_path / "store.bin"
    quiet = Progress(out=io.StringIO(), tty=False)
    kill_after = 3
    with SimulatedDevice(virtual_clock=True, store=str(store), start=True) as dev:
        client = _KillAfter(dv.DeviceClient(dev, timeout=1.0), dev, kill_after, 150)
        model = open_runner_source("participant", protocol, "U1").model
        with pytest.raises(LinkError):
            hr.run_hostless(
                protocol,
                "U1",
                client,
                str(out),
                model,
                rest_s=REST_S,
                on_trial_result=client.on_result,
                progress=quiet,
                err=io.StringIO(),
            )
        assert client.killed
        seen = list(client.results)
    assert len(seen) >= kill_after

    # The device restarts on the same store, like a board powered up again.
    with SimulatedDevice(virtual_clock=True, store=str(store), start=True) as dev:
        client = dv.DeviceClient(dev, timeout=1.0)
        client.hello()
        info = client.log_info()
        summary = download_log(client, str(out), err=io.StringIO())
        stored = {r["trial_index"]: r for r in read_lines(out / "U1" / "trials.jsonl")}
        for res in seen:
            rec = stored.get(int(res.trial_id))
            assert rec is not None, f"trial {res.trial_id}: its TRIAL_RESULT was seen, no record"
            assert rec["success"] == bool(res.success)
            assert _f32(rec["final_error_deg"]) == _f32(res.final_error_deg)
            assert _f32(rec["first_entry_s"]) == _f32(res.first_entry_s)
            if res.success:
                assert _f32(rec["completion_s"]) == _f32(res.completion_s)
        assert info.records == summary.records >= len(seen)
        assert info.torn_records == 0  # nothing was being written: the kill hit a sample

        # Resume on the restarted device: the rest of the plan, each trial once.
        model = open_runner_source("participant", protocol, "U1").model
        done = hr.run_hostless(
            protocol,
            "U1",
            client,
            str(out),
            model,
            rest_s=REST_S,
            progress=quiet,
            err=io.StringIO(),
        )
    planned = pf.plan(protocol, "U1")
    final = read_lines(out / "U1" / "trials.jsonl")
    assert [r["trial_index"] for r in final] == sorted(t.trial_index for t in planned)
    assert done.before == info.records and done.ran == len(planned) - info.records
    for r in final:  # what was stored before the kill is unchanged
        if r["trial_index"] in stored:
            assert r == stored[r["trial_index"]]
    report_figure(
        "host-less SIGKILL mid-study",
        f"{len(seen)} TRIAL_RESULTs seen before the kill, {info.records} records after the "
        f"restart ({info.torn_records} torn), all {len(final)} planned trials after resuming",
    )


# One V and one C trial, no familiarization: a short run to watch the device's error.
ONE_EACH = small_protocol_toml(
    "hostless-short",
    seed=11,
    timeout_s=30.0,
    modalities=("F+V", "Fperp+C"),
    wrenches=1,
    single_motor=0,
)


def _device_vs_true_error(tmp_path, core, monkeypatch, declare_mount):
    """|device error - true error| at every sample of the ONE_EACH trials, the IMU under
    MOUNT; the plan declares MOUNT, or (declare_mount False) the identity."""
    from graspguide.devices.sim import SimulatedDevice
    from graspguide.link.messages import TELEMETRY_FLAG_TRIAL_RUNNING

    tmp_path.mkdir()
    path = tmp_path / "one_each.toml"
    path.write_text(ONE_EACH)
    protocol = pf.load_protocol(str(path))
    planned = pf.plan(protocol, "U1")
    assert {t.mode for t in planned} == {"C", "V"}
    guides = {}
    for t in planned:
        g = core.Guidance()
        assert (
            g.set_scene(
                [list(c) for c in protocol.hands[t.k]],
                policy=t.policy,
                mode=t.mode,
                y_axis=list(protocol.y_axis),
            )
            == "ok"
        )
        assert g.set_wrench(list(t.wrench)) == "ok"
        guides[t.trial_index] = g
    diffs = []

    def on_sample(t_s, q, tel, trial):
        if trial is not None and tel.flags & TELEMETRY_FLAG_TRIAL_RUNNING:
            true = guides[trial.trial_index].update([float(x) for x in q])
            assert true["status"] == "ok"
            diffs.append(abs(float(tel.error_deg) - true["error_deg"]))

    if not declare_mount:
        from graspguide.hostless import plan_upload

        real = plan_upload.plan_messages

        def wrong_mount(*args, **kwargs):
            kwargs["imu_to_hand_wxyz"] = (1.0, 0.0, 0.0, 0.0)
            return real(*args, **kwargs)

        monkeypatch.setattr(plan_upload, "plan_messages", wrong_mount)
    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        hr.run_hostless(
            protocol,
            "U1",
            dv.DeviceClient(dev),
            str(tmp_path / "out"),
            open_runner_source("participant", protocol, "U1").model,
            imu_to_hand=MOUNT,
            on_sample=on_sample,
            progress=Progress(out=io.StringIO(), tty=False),
        )
    d = np.array(diffs)
    assert len(d) > protocol.pose_rate_hz  # over a second of trial samples were seen
    return d


def test_under_a_tilted_mount_the_devices_error_follows_the_true_error(
    tmp_path, core, monkeypatch, report_figure
):
    """The world and the device agree on the mount (imu_to_hand_wxyz, v_imu = R^T v_hand):
    during the trials the device's error, estimated from the IMU samples, stays within the
    estimator's goal (3 deg max) of the true error of the hand pose the world moved; a
    mount declared wrong does not."""
    d = _device_vs_true_error(tmp_path / "right", core, monkeypatch, True)
    rms, worst = float(np.sqrt(np.mean(d**2))), float(d.max())
    report_figure(
        "host-less |device error - true error|",
        f"RMS {rms:.2f} deg, max {worst:.2f} deg over {len(d)} samples (tilted mount, SIMULATED)",
    )
    assert worst <= 3.0, f"the device's error left the true one by {worst:.2f} deg"
    wrong = _device_vs_true_error(tmp_path / "wrong", core, monkeypatch, False)
    assert wrong.max() > 10.0, "a wrongly declared mount went unnoticed: is the mount used?"


def test_demo_hostless_runs_each_participant_hostless_into_its_own_folder():
    from graspguide.study import demo

    job = demo.HostlessTrialJob("p.toml", "study", "U3", "participant", "U3.log")
    cmd = job.command()
    assert cmd[-1] == "--hostless" and cmd[cmd.index("--participant") + 1] == "U3"
    assert demo.default_out(True).endswith("demo-hostless")
    assert demo.default_out().endswith("demo-study")


def test_ctrl_c_stops_the_run_and_the_same_device_resumes_it(tmp_path):
    from graspguide.devices.sim import SimulatedDevice

    _, protocol = short_protocol(tmp_path)
    out = str(tmp_path / "study")
    quiet = Progress(out=io.StringIO(), tty=False)
    seen = []

    def interrupt_after_two(result):
        seen.append(result)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        client = dv.DeviceClient(dev)
        model = open_runner_source("participant", protocol, "U1").model
        with pytest.raises(KeyboardInterrupt):
            hr.run_hostless(
                protocol,
                "U1",
                client,
                out,
                model,
                rest_s=REST_S,
                on_trial_result=interrupt_after_two,
                progress=quiet,
                err=io.StringIO(),
            )
        info = client.log_info()
        assert not info.running  # STOP was sent
        assert info.records == 2
        # Again on the same device (its clock must not go back): the rest of the plan.
        model = open_runner_source("participant", protocol, "U1").model
        done = hr.run_hostless(
            protocol, "U1", client, out, model, rest_s=REST_S, progress=quiet, err=io.StringIO()
        )
        # Another participant's plan is refused while U1's records are on the device.
        other = open_runner_source("participant", protocol, "U2").model
        with pytest.raises(hr.RunnerError, match="records of another plan.*U1.*erase"):
            hr.run_hostless(protocol, "U2", client, out, other, progress=quiet)
        assert client.log_info().records == done.planned  # nothing of U1's was touched
    assert (done.before, done.ran, done.completed) == (2, done.planned - 2, done.planned)
    final = read_lines(tmp_path / "study" / "U1" / "trials.jsonl")
    assert [r["trial_index"] for r in final] == [t.trial_index for t in pf.plan(protocol, "U1")]
    for res in seen:
        rec = next(r for r in final if r["trial_index"] == res.trial_id)
        assert _f32(rec["final_error_deg"]) == _f32(res.final_error_deg)


def test_an_imu_fault_mid_trial_is_reported_counted_and_the_study_goes_on(tmp_path, monkeypatch):
    """A frozen IMU for 40 samples in the first trial: the device turns the motors off and
    sends imu_fault; the host says so, the trial's record counts it, the study finishes."""
    from graspguide.devices.sim import SimulatedDevice

    _, protocol = short_protocol(tmp_path)
    real_sample = ImuWorld.sample
    frozen: dict[str, object] = {}

    def sample(self, t_s, quat):
        s = real_sample(self, t_s, quat)
        n = frozen.setdefault("n", 0)
        if "trial" in frozen and n < 40:  # in the trial: the same reading, again and again
            frozen["n"] = n + 1
            return frozen.setdefault("s", s)
        return s

    def on_sample(t_s, q, tel, trial):
        if trial is not None:
            frozen["trial"] = True

    monkeypatch.setattr(ImuWorld, "sample", sample)
    said = io.StringIO()
    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        client = dv.DeviceClient(dev)
        model = open_runner_source("participant", protocol, "U1").model
        done = hr.run_hostless(
            protocol,
            "U1",
            client,
            str(tmp_path / "study"),
            model,
            rest_s=REST_S,
            progress=Progress(out=said, tty=False),
            err=io.StringIO(),
            on_sample=on_sample,
        )
    assert frozen["n"] == 40
    assert done.completed == done.planned
    assert "reported an IMU fault at plan position 0" in said.getvalue()
    records = read_lines(tmp_path / "study" / "U1" / "trials.jsonl")
    assert records[0]["imu_faults"] == 1
    assert all(r["imu_faults"] == 0 for r in records[1:])


def test_cli_usage_errors(tmp_path):
    path, _ = short_protocol(tmp_path)
    base = ["trial", "--protocol", path, "--participant", "U1", "--out", str(tmp_path / "o")]
    r = gg(*base, "--port", "sim", "--source", "participant", "--store", "x.bin")
    assert r.returncode == 2 and "--hostless" in r.stderr
    r = gg(*base, "--port", "sim", "--source", "participant", "--imu-to-hand", "0,1,0,0")
    assert r.returncode == 2 and "--hostless" in r.stderr
    r = gg(*base, "--port", "sim", "--source", "participant", "--hostless", "--imu-to-hand", "1,0")
    assert r.returncode == 2 and "--imu-to-hand" in r.stderr
    r = gg(*base, "--port", "/dev/null", "--source", "participant", "--hostless")
    assert r.returncode == 2 and "--port sim" in r.stderr
    r = gg(*base, "--port", "sim", "--source", "synthetic", "--hostless")
    assert r.returncode == 2 and "closed-loop" in r.stderr
    r = gg(*base, "--port", "sim", "--source", "participant", "--hostless", "--rest-s", "nan")
    assert r.returncode == 2 and "--rest-s" in r.stderr


def test_the_plans_calibration_shapes_every_telemetry_pwm(tmp_path, core, report_figure):
    """A plan carrying a participant's calibration: every guided TELEMETRY PWM of the
    simulated host-less run is the float64 reference's floor_i + G (gain_i |m_i|), from the
    C++ core's levels of the plan's (float32) posture and the device's own alpha."""
    from graspguide.core import reference
    from graspguide.core.motor_calibration import MotorCalibration
    from graspguide.devices.sim import SimulatedDevice
    from graspguide.link.messages import TELEMETRY_FLAG_TRIAL_RUNNING

    path = tmp_path / "one_each.toml"
    path.write_text(ONE_EACH)
    protocol = pf.load_protocol(str(path))
    cal = MotorCalibration((55, 90, 64, 120), (1.5, 0.75, 1.25, 2.0))
    levels = {}
    for t in pf.plan(protocol, "U1"):
        g = core.Guidance()
        hand = [[_f32(x) for x in c] for c in protocol.hands[t.k]]
        assert g.set_scene(hand, policy=t.policy, mode=t.mode, y_axis=list(protocol.y_axis)) == "ok"
        assert g.set_wrench([_f32(x) for x in t.wrench]) == "ok"
        levels[t.trial_index] = (g.update([1.0, 0.0, 0.0, 0.0])["levels"], t.mode)
    seen = []

    def on_sample(t_s, q, tel, trial):
        running = tel.flags & TELEMETRY_FLAG_TRIAL_RUNNING
        if trial is not None and running and int(tel.solver_status) == 0:
            lv, mode = levels[trial.trial_index]
            want = reference.pwm_from_levels(np.asarray(lv), mode, float(tel.alpha), cal)
            plain = reference.pwm_from_levels(np.asarray(lv), mode, float(tel.alpha))
            seen.append((list(tel.pwm[: len(lv)]), want, plain))

    with SimulatedDevice(virtual_clock=True, store=str(tmp_path / "s.bin"), start=True) as dev:
        summary = hr.run_hostless(
            protocol,
            "U1",
            dv.DeviceClient(dev),
            str(tmp_path / "out"),
            open_runner_source("participant", protocol, "U1").model,
            on_sample=on_sample,
            progress=Progress(out=io.StringIO(), tty=False),
            calibration=cal,
            calibration_file="(test)",
        )
    assert summary.completed == summary.planned == 2
    assert len(seen) > protocol.pose_rate_hz, "over a second of guided samples"
    worst = max(abs(a - b) for got, want, _ in seen for a, b in zip(got, want))
    exact = sum(got == want for got, want, _ in seen)
    report_figure(
        "host-less calibrated PWM vs reference",
        f"{exact} of {len(seen)} guided TELEMETRY frames equal, worst {worst} count (SIMULATED)",
    )
    # alpha crosses the link as float32: a duty on a rounding edge may differ by one.
    assert worst <= 1 and exact >= len(seen) * 99 // 100, (worst, exact, len(seen))
    assert sum(got != plain for got, _, plain in seen) > len(seen) // 2, "calibration unused?"
    runs = read_lines(tmp_path / "out" / "U1" / "runs.jsonl")
    start = [r for r in runs if r["event"] == "start"][-1]
    assert start["calibration"] == cal.to_json() and start["calibration_file"] == "(test)"


def test_resuming_under_another_calibration_is_refused_naming_both(tmp_path):
    """The stored plan's calibration is the one the study began with: a resume from the same
    folder under another one is refused before anything runs (LOG_INFO cannot show it; the
    folder's runs.jsonl says which one was uploaded)."""
    from graspguide.core.motor_calibration import MotorCalibration
    from graspguide.devices.sim import SimulatedDevice
    from graspguide.run_errors import RunnerError

    path = tmp_path / "one_each.toml"
    path.write_text(ONE_EACH)
    protocol = pf.load_protocol(str(path))
    first = MotorCalibration((55, 90, 64, 120), (1.5, 0.75, 1.25, 2.0))
    store = str(tmp_path / "s.bin")

    def run(cal, where):
        with SimulatedDevice(virtual_clock=True, store=store, start=True) as dev:
            return hr.run_hostless(
                protocol,
                "U1",
                dv.DeviceClient(dev),
                str(tmp_path / "out"),
                open_runner_source("participant", protocol, "U1").model,
                progress=Progress(out=io.StringIO(), tty=False),
                calibration=cal,
                calibration_file=where,
            )

    assert run(first, "first.json").uploaded
    again = run(first, "first.json")
    assert not again.uploaded and again.ran == 0 and again.completed == 2
    with pytest.raises(RunnerError) as e:
        run(MotorCalibration.identity(), None)
    text = str(e.value)
    assert "first.json" in text and "[55, 90, 64, 120]" in text and "[70, 70, 70, 70]" in text
    assert "graspguide device erase" in text
