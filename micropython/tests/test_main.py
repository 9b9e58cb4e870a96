"""main.py's control loop on the fakes (the unix port's machine module has no Pin or PWM,
so main() itself needs a board): button edges, samples and ticks reach the runner, the
loop ends with the plan, and the motors end off."""

import main
from graspguide_mp import plan_file as pf
from graspguide_mp import runner as rn
from graspguide_mp import status as st
from graspguide_mp.fake_hal import FakeButton, FakeClock, FakeImu, FakeMotors
from graspguide_mp.store import MemoryStore
from hostless_helpers import make_plan

G = 9.80665


class PacedImu(FakeImu):
    """A sample every 10 ms of the fake clock (every other read has none, as a part read
    faster than it converts), the hand held at the force's direction; presses the button
    once the runner waits for it."""

    def __init__(self, clock, runner, button, aligned):
        FakeImu.__init__(self)
        self.clock = clock
        self.runner = runner
        self.button = button
        self.aligned = aligned
        self.reads = 0

    def read_into(self, accel, gyro):
        self.reads += 1
        if self.reads > 100000:
            raise AssertionError("the loop did not end")
        if self.runner.phase == rn.PH_WAIT_BUTTON and not self.button._edges:
            self.button.press()
            self.button.release()
        self.clock.advance(5000)
        if self.reads % 2:
            return False
        j = self.reads % 7
        a = self.aligned
        self.next = ([a[0] + j * 1e-4, a[1], a[2]], [1e-4 * (j - 3), 0.0, 0.0])
        return FakeImu.read_into(self, accel, gyro)


def test_main_loop_runs_the_plan():
    plan = make_plan(2)
    store = MemoryStore()
    assert pf.save_plan(store, plan) == pf.OK
    clock = FakeClock(123)
    motors = FakeMotors()
    button = FakeButton()
    table = {t.trial_index: (st.OK, [0.5, 0.7, 0.3, 0.2][: t.k]) for t in plan.trials}
    r = rn.HostlessRunner(motors, clock, store, rn.PrecomputedPostures(table), 78.4, 34.9)
    assert r.boot() == pf.OK and r.start() is None
    w = plan.trials[0].wrench
    n = (w[0] ** 2 + w[1] ** 2 + w[2] ** 2) ** 0.5
    imu = PacedImu(clock, r, button, [-G * w[0] / n, -G * w[1] / n, -G * w[2] / n])
    main.run(r, imu, button, clock)
    assert not r.running() and motors.all_off()
    assert r.log.records == 2
    assert all(r.log.read(i)[1].success for i in range(2))


def _plan_file(plan, path):
    staged = MemoryStore(pf.REGION_BYTES)
    assert pf.save_plan(staged, plan) == pf.OK
    with open(path, "wb") as f:
        f.write(staged.data)


def test_a_deployed_plan_file_is_installed_once_and_never_orphans_records():
    import os

    from graspguide_mp import results_file as rf

    path = "/tmp/graspguide_test_plan_%d.bin" % id(pf)
    store = MemoryStore()
    assert main.install_plan(store, path) == "no new plan file"
    u1 = make_plan(2)
    _plan_file(u1, path)
    try:
        assert main.install_plan(store, path).startswith("installed the plan of U1")
        status, stored = pf.load_plan(store)
        assert status == pf.OK and pf.plan_id(stored) == pf.plan_id(u1)
        assert main.install_plan(store, path) == "plan of U1 already installed"
        # U1 has a record now: U2's plan must wait until the records are downloaded.
        log = rf.ResultsLog(store)
        assert log.mount() == pf.OK
        assert log.append(rf.LogRecord(u1.trials[0]), pf.plan_id(u1)) == pf.OK
        _plan_file(make_plan(2, participant=b"U2"), path)
        said = main.install_plan(store, path)
        assert "holds 1 records of another plan" in said, said
        status, stored = pf.load_plan(store)
        assert pf.plan_id(stored) == pf.plan_id(u1)
        # Not a plan: refused, the stored one stays.
        with open(path, "wb") as f:
            f.write(b"\x00" * 100)
        assert "refused" in main.install_plan(store, path)
        assert pf.plan_id(pf.load_plan(store)[1]) == pf.plan_id(u1)
    finally:
        os.remove(path)


def test_levels_of_another_plan_are_not_used():
    path = "/tmp/graspguide_test_levels_%d.txt" % id(pf)
    plan = make_plan(2)
    pid = pf.plan_id(plan)
    try:
        with open(path, "w") as f:
            f.write("# levels\nplan_id %08x\n1 ok 0.5 0.7 0.3\n2 ok 0.5 0.7 0.3 0.2\n" % pid)
        mine = rn.PrecomputedPostures.load(path)
        assert mine.plan_id == pid and len(mine.table) == 2
        assert main.matching_postures(mine, pid) is mine
        other = main.matching_postures(mine, pid ^ 1)
        assert isinstance(other, rn.SolverPostures)
        with open(path, "w") as f:  # a file that says nothing of its plan: not trusted
            f.write("1 ok 0.5 0.7 0.3\n")
        unknown = rn.PrecomputedPostures.load(path)
        assert unknown.plan_id is None
        assert isinstance(main.matching_postures(unknown, pid), rn.SolverPostures)
    finally:
        import os

        os.remove(path)
