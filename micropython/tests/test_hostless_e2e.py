"""A host-less trial END TO END inside MicroPython: the plan stored in a store, the runner
booted from it, the virtual participant's scripted IMU samples (tests/data/
hostless_script.json, made on the host by tests/host/make_reference.py with imu_world and
the virtual participant, SIMULATED) fed one by one, the button pressed when the script
pressed it. The trial must end with success when the host-side device's did, the PWM of
every frame must agree with that device's (C++ estimator, float64 reference error, PWM
under the plan's motor calibration) within one count, and the record must be in the
results log, with the log readable after a reboot."""

from graspguide_mp import plan_file as pf
from graspguide_mp import runner as rn
from graspguide_mp import status as st
from graspguide_mp.fake_hal import FakeClock, FakeMotors
from graspguide_mp.lsm6dsox import ACCEL_FULL_SCALE_MPS2, GYRO_FULL_SCALE_RADPS
from graspguide_mp.results_file import ResultsLog
from graspguide_mp.store import MemoryStore
from hostless_helpers import close, load_json


def _plan(sc):
    h = pf.PlanHeader()
    hs = sc["header"]
    name = hs["participant"].encode()
    h.participant = name + b"\0" * (pf.PARTICIPANT_BYTES - len(name))
    h.simulated = True
    h.trial_count = 1
    keys = ("threshold_deg", "hold_s", "timeout_s", "rest_s", "y_axis", "imu_to_hand_wxyz")
    for key in keys + ("pwm_floor", "gain"):
        setattr(h, key, hs[key])
    h.hand_k3 = hs["hand_k3"]
    t = pf.PlanTrial()
    for key, v in sc["trial"].items():
        setattr(t, key, v)
    return pf.Plan(h, [t])


def test_hostless_trial_end_to_end():
    sc = load_json("hostless_script.json")
    assert sc["SIMULATED"]
    plan = _plan(sc)
    store = MemoryStore()
    assert pf.save_plan(store, plan) == pf.OK
    clock = FakeClock(0)
    motors = FakeMotors()
    postures = rn.PrecomputedPostures({1: (st.OK, sc["levels"])})
    r = rn.HostlessRunner(
        motors, clock, store, postures, ACCEL_FULL_SCALE_MPS2, GYRO_FULL_SCALE_RADPS
    )
    assert r.boot() == pf.OK and r.plan is not None
    assert r.start() is None
    host = {}
    for f in sc["host"]["frames"]:
        host[f["sample"]] = f
    success_sample = sc["host"]["success_sample"]
    button_us = sc["button_us"]
    pressed = False
    events = []
    compared = 0
    exact = 0
    worst_err = 0.0
    worst_alpha = 0.0
    success_seen_at = None
    for i, s in enumerate(sc["samples"]):
        t = s[0]
        if not pressed and t > button_us:
            clock.set(button_us)
            r.tick(button_us)
            assert r.phase == rn.PH_WAIT_BUTTON, "the ready pattern is over before the press"
            r.on_button(True, button_us)
            pressed = True
        clock.set(t)
        r.on_sample(s[1:4], s[4:7], t)
        while True:
            e = r.pop_event()
            if e is None:
                break
            events.append(e[0])
            if e[0] == rn.EV_SUCCESS:
                success_seen_at = i
                # The record is stored before the wearer is told (and before the pattern).
                log = ResultsLog(store)
                assert log.mount() == pf.OK and log.records == 1
        if i in host and i < success_sample:
            f = host[i]
            d = max(abs(motors.duty[j] - f["pwm"][j]) for j in range(3))
            assert d <= 1, "sample %d: PWM %r, the host's %r" % (i, list(motors.duty), f["pwm"])
            exact += d == 0
            e = abs(r.error_deg - f["error_deg"])
            worst_err = e if e > worst_err else worst_err
            a = abs(r.alpha - f["alpha"])
            worst_alpha = a if a > worst_alpha else worst_alpha
            compared += 1
    assert compared > 100, compared
    assert sc["header"]["pwm_floor"] != [70, 70, 70, 70], "the script must test a calibration"
    assert worst_err < 1e-6, "error_deg differs from the host's by %g deg" % worst_err
    assert worst_alpha < 1e-6, "alpha differs from the host's by %g" % worst_alpha
    # Off by one only where a duty sits on a rounding edge: rare.
    assert exact >= compared * 99 // 100, "%d of %d PWM frames exact" % (exact, compared)
    assert success_seen_at == success_sample, (success_seen_at, success_sample)
    want = [rn.EV_REST, rn.EV_READY, rn.EV_TRIAL_STARTED, rn.EV_SUCCESS, rn.EV_PLAN_DONE]
    assert events == want, [rn.EVENT_NAMES[e] for e in events]
    assert not r.running() and motors.all_off(), "motors off once the plan is done"

    # After a reboot the record is there, exactly what the trial measured.
    log = ResultsLog(store)
    assert log.mount() == pf.OK and log.records == 1 and log.torn == 0
    status, rec, pid = log.read(0)
    assert status == pf.OK and pid == pf.plan_id(plan)
    assert rec.success and rec.trial.trial_index == 1 and rec.imu_faults == 0
    close(rec.completion_s, sc["host"]["completion_s"], 1e-6, "completion_s")
    assert rec.samples == success_sample - sum(1 for s in sc["samples"] if s[0] <= button_us) + 1
    again = rn.HostlessRunner(
        FakeMotors(), clock, store, postures, ACCEL_FULL_SCALE_MPS2, GYRO_FULL_SCALE_RADPS
    )
    again.boot()
    assert again.start() is None and again.pop_event()[0] == rn.EV_PLAN_DONE


def test_on_board_solver_gives_the_host_levels():
    # The other posture source: the port's own Algorithm 1 on the script's posture must
    # give the levels the C++ core gave the host.
    sc = load_json("hostless_script.json")
    plan = _plan(sc)
    s, levels = rn.SolverPostures().levels(plan.header, plan.trials[0])
    assert s == st.OK
    for j in range(3):
        close(levels[j], sc["levels"][j], 1e-9, "level %d" % j)
