"""The host-less runner's ways out, inside MicroPython, on the fakes: no plan, an IMU fault
in a trial (motors off at once, counted in the record), a dead IMU (the trial still ends
at its timeout), a full log, a failed append, a resumed run, a posture the source cannot
give, and the levels file."""

import math

from graspguide_mp import plan_file as pf
from graspguide_mp import results_file as rf
from graspguide_mp import runner as rn
from graspguide_mp import status as st
from graspguide_mp.fake_hal import CutStore, FakeClock, FakeMotors
from graspguide_mp.store import MemoryStore
from hostless_helpers import make_plan

G = 9.80665
PERIOD_US = 10000


class Rig:
    """A runner on fakes, a plan already stored, samples of a hand held still."""

    def __init__(self, plan, store=None, table=None, timeout_s=None):
        if timeout_s is not None:
            plan.header.timeout_s = timeout_s
        self.plan = plan
        self.store = store if store is not None else MemoryStore()
        assert pf.save_plan(self.store, plan) == pf.OK
        levels = table
        if levels is None:
            levels = {t.trial_index: (st.OK, [0.5, 0.7, 0.3, 0.2][: t.k]) for t in plan.trials}
        self.clock = FakeClock(0)
        self.motors = FakeMotors()
        self.r = rn.HostlessRunner(
            self.motors, self.clock, self.store, rn.PrecomputedPostures(levels), 78.4, 34.9
        )
        self.t = 0
        self.i = 0
        self.events = []
        w = plan.trials[0].wrench
        n = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        self.aligned = [-G * w[0] / n, -G * w[1] / n, -G * w[2] / n]  # error 0
        self.off = [0.0, 0.0, G]  # gravity along -z: far from the force

    def sample(self, accel=None):
        # A live part's noise: never the same reading twice (no stuck fault).
        a = accel if accel is not None else self.aligned
        j = self.i % 7
        self.t += PERIOD_US
        self.i += 1
        self.clock.set(self.t)
        self.r.on_sample([a[0] + j * 1e-4, a[1], a[2]], [1e-4 * (j - 3), 0.0, 0.0], self.t)
        self._drain()

    def silence(self, us):
        end = self.t + us
        while self.t < end:
            self.t += PERIOD_US
            self.clock.set(self.t)
            self.r.tick(self.t)
            self._drain()

    def _drain(self):
        while True:
            e = self.r.pop_event()
            if e is None:
                return
            self.events.append(rn.EVENT_NAMES[e[0]])

    def until(self, name, accel=None, limit=20000):
        n = len(self.events)
        for _ in range(limit):
            if name in self.events[n:]:
                return
            self.sample(accel)
        raise AssertionError("no %s event; got %r" % (name, self.events))

    def to_trial(self):
        self.until("ready", self.off)
        self.r.on_button(True, self.t)
        self._drain()
        assert self.r.phase == rn.PH_TRIAL

    def records(self):
        log = rf.ResultsLog(self.store)
        assert log.mount() == pf.OK
        return [log.read(i)[1] for i in range(log.records)]


def test_no_plan_is_refused():
    clock = FakeClock(0)
    motors = FakeMotors()
    r = rn.HostlessRunner(motors, clock, MemoryStore(), rn.PrecomputedPostures({}), 78.4, 34.9)
    assert r.boot() == pf.OK
    assert r.start() == rn.REFUSED_NO_PLAN and not r.running()
    assert motors.writes == 0


def test_button_only_counts_when_ready():
    rig = Rig(make_plan(1))
    rig.r.boot()
    rig.r.start()
    rig.r.on_button(True, 0)
    assert rig.r.phase == rn.PH_REST, "a press during the rest starts nothing"
    rig.until("ready", rig.off)
    rig.r.on_button(False, rig.t)
    assert rig.r.phase == rn.PH_WAIT_BUTTON, "a release starts nothing"
    assert rig.r.start() == rn.REFUSED_NOT_ALLOWED


def test_success_then_plan_done():
    rig = Rig(make_plan(2))
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    rig.until("success")
    k = rig.plan.trials[0].k
    assert list(rig.motors.duty[:k]) == [rn.PATTERN_DUTY] * k, "the success pattern plays"
    rig.to_trial()
    rig.until("plan_done")
    assert rig.events == [
        "rest",
        "ready",
        "trial_started",
        "success",
        "rest",
        "ready",
        "trial_started",
        "success",
        "plan_done",
    ], rig.events
    recs = rig.records()
    assert [r.trial.trial_index for r in recs] == [1, 2]
    assert all(r.success and r.imu_faults == 0 for r in recs)
    assert not rig.r.running() and rig.motors.all_off()


def test_imu_fault_in_a_trial_stops_the_motors_and_is_counted():
    rig = Rig(make_plan(1))
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    for _ in range(5):
        rig.sample(rig.off)
    assert not rig.motors.all_off(), "guiding"
    rig.sample([100.0, 0.0, 0.0])  # beyond +-8 g: a corrupted transfer
    assert rig.motors.all_off() and rig.r.frame_status == st.IMU_OUT_OF_RANGE
    # As hostless_app.h: the fault's onset is an IMU_FAULT event, once.
    assert rig.events.count("imu_fault") == 1
    for _ in range(9):
        rig.sample(rig.off)
        assert rig.motors.all_off(), "motors stay off until recovery"
    rig.sample(rig.off)
    assert not rig.motors.all_off(), "back on after 10 good samples"
    rig.until("success")
    rec = rig.records()[0]
    assert rec.success and rec.imu_faults == 1


def test_dead_imu_still_ends_the_trial_at_its_timeout():
    rig = Rig(make_plan(1), timeout_s=1.0)
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    rig.sample(rig.off)
    assert not rig.motors.all_off()
    rig.silence(150000)
    assert rig.motors.all_off() and "imu_fault" in rig.events, "stale: motors off"
    rig.silence(1000000)
    assert "timeout" in rig.events
    rec = rig.records()[0]
    assert not rec.success and rec.completion_s == 1.0 and rec.imu_faults == 1
    assert rec.samples == 1


def test_log_full_refuses_and_stops():
    store = MemoryStore(pf.REGION_BYTES + rf.SLOT_BYTES)
    rig = Rig(make_plan(2), store=store)
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    rig.until("success")
    rig.until("log_full")
    assert not rig.r.running() and rig.motors.all_off()
    rig.r.boot()
    assert rig.r.start() == rn.REFUSED_LOG_FULL


def test_failed_append_stops_with_motors_off():
    store = CutStore(64 * 1024)
    rig = Rig(make_plan(1), store=store)
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    store.budget = 10  # the power goes mid-record
    rig.until("storage_failed")
    assert not rig.r.running() and rig.motors.all_off()
    assert "success" not in rig.events, "never told success without a stored record"
    store.budget = -1
    assert rig.records() == []


def test_resume_starts_at_the_first_trial_without_a_record():
    rig = Rig(make_plan(3))
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    rig.until("success")
    rig.r.stop()  # power off during the next rest
    assert rig.motors.all_off()
    rig.r.boot()
    rig.r.start()
    assert rig.r.position == 1
    rig.to_trial()
    rig.until("success")
    assert [r.trial.trial_index for r in rig.records()] == [1, 2]


def test_posture_the_source_cannot_give():
    rig = Rig(make_plan(1), table={})
    rig.r.boot()
    assert rig.r.start() is None
    rig._drain()
    assert rig.events == ["storage_failed"] and not rig.r.running()
    bad = Rig(make_plan(1), table={1: (st.RANK_DEFICIENT, None)})
    bad.r.boot()
    bad.r.start()
    bad._drain()
    assert bad.events == ["storage_failed"] and bad.motors.all_off()


def test_levels_file():
    path = "/tmp/graspguide_mp_levels_test.txt"
    with open(path, "w") as f:
        f.write("# trial_index status levels\n1 ok 0.5 0.25 0.125\n2 rank_deficient\n")
    p = rn.PrecomputedPostures.load(path)
    assert p.table[1] == (st.OK, [0.5, 0.25, 0.125])
    assert p.table[2] == (st.RANK_DEFICIENT, None)
    for bad in ("1 ok 0.5\n", "x ok 1 2 3\n", "1 no_such_status 1 2 3\n"):
        with open(path, "w") as f:
            f.write(bad)
        try:
            rn.PrecomputedPostures.load(path)
        except ValueError as e:
            assert "line 1" in str(e), str(e)
        else:
            raise AssertionError("a bad levels line was taken: %r" % bad)


def _damage_slot(store, slot):
    """One bit of the slot's record flipped (flash wear): the slot reads torn."""
    store.data[pf.REGION_BYTES + slot * rf.SLOT_BYTES + 12] ^= 0x10


def test_a_damaged_records_trial_runs_again_and_no_trial_runs_twice():
    rig = Rig(make_plan(4))
    rig.r.boot()
    rig.r.start()
    for _ in range(3):
        rig.to_trial()
        rig.until("success")
    rig.r.stop()
    assert [r.trial.trial_index for r in rig.records()] == [1, 2, 3]
    _damage_slot(rig.store, 1)  # trial 2's record goes bad
    rig.r.boot()
    assert rig.r.log.torn == 1 and rig.r.log.records == 2
    rig.events = []
    assert rig.r.start() is None
    rig._drain()
    assert rig.events == ["rest"] and rig.r.position == 1, (rig.events, rig.r.position)
    rig.to_trial()
    rig.until("success")
    rig.until("rest", rig.off)
    assert rig.r.position == 3, "trial 3 has its record: skipped"
    rig.to_trial()
    rig.until("plan_done")
    assert [r.trial.trial_index for r in rig.records()] == [1, 3, 2, 4]
    rig.events = []
    assert rig.r.start() is None
    rig._drain()
    assert rig.events == ["plan_done"] and not rig.r.running()


def test_a_damaged_record_of_a_finished_plan_runs_only_its_trial_again():
    rig = Rig(make_plan(4))
    rig.r.boot()
    rig.r.start()
    for _ in range(4):
        rig.to_trial()
        rig.until("success")
    rig.until("plan_done", rig.off)
    _damage_slot(rig.store, 1)
    rig.r.boot()
    rig.r.start()
    assert rig.r.position == 1, rig.r.position
    rig.to_trial()
    rig.until("plan_done")
    assert [r.trial.trial_index for r in rig.records()] == [1, 3, 4, 2]


def test_a_sample_older_than_the_last_aborts_the_trial_with_no_record():
    rig = Rig(make_plan(1), timeout_s=5.0)
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    for _ in range(5):
        rig.sample(rig.off)
    assert not rig.motors.all_off(), "guiding"
    n = len(rig.events)
    back = (rig.t - 1) & 0x3FFFFFFF  # 1 us before the last sample
    status = rig.r.on_sample(rig.off, [0.0, 0.0, 0.0], back)
    rig._drain()
    assert status == st.TIME_WENT_BACKWARDS, status
    assert rig.motors.all_off()
    assert rig.records() == [] and rig.r.result_pending is None
    assert rig.events[n:] == ["rest"], rig.events[n:]
    assert rig.r.phase == rn.PH_REST
    # The trial runs again from its rest; its record counts only the time it ran.
    rig.to_trial()
    pressed = rig.t
    rig.until("success")
    recs = rig.records()
    assert len(recs) == 1 and recs[0].success
    assert abs(recs[0].completion_s - (rig.t - pressed) * 1e-6) < 0.011, recs[0].completion_s


def test_a_tick_before_the_last_sample_never_advances_the_trial():
    rig = Rig(make_plan(1), timeout_s=5.0)
    rig.r.boot()
    rig.r.start()
    rig.to_trial()
    rig.sample(rig.off)
    rig.r.tick((rig.t - 5) & 0x3FFFFFFF)  # a loop's "now" read before the sample
    for _ in range(20):
        rig.sample(rig.off)
    assert rig.r.phase == rn.PH_TRIAL and rig.records() == []


def test_the_longest_rest_ends_on_time_across_the_ticks_half_period():
    # 600 s is longer than the signed half period of the 2^30 us ticks (537 s).
    rig = Rig(make_plan(1, rest_s=600.0))
    rig.r.boot()
    rig.r.start()
    for _ in range(599):
        rig.t = (rig.t + 1000000) & 0x3FFFFFFF
        rig.r.tick(rig.t)
        rig._drain()
    assert rig.r.phase == rn.PH_REST, "599 s into a 600 s rest"
    for _ in range(3):
        rig.t = (rig.t + 1000000) & 0x3FFFFFFF
        rig.r.tick(rig.t)
        rig._drain()
    assert rig.r.phase != rn.PH_REST, "the rest ended"
