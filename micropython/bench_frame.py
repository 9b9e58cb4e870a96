"""The per-frame step's cost on this interpreter: IMU sample -> gravity estimator -> error
and alpha -> PWM, alone ("step") and as the runner does it in a trial ("runner": also the
IMU health rule, the mounting rotation, the trial and the motor write).

    micropython micropython/bench_frame.py [FRAMES]

Prints, per variant, the median time per frame over batches of 100 frames (time.ticks_us),
and the heap allocated per frame (gc.mem_alloc() delta over FRAMES frames with gc
disabled). Variants: the plain bytecode, and frame.py's hot functions compiled with
@micropython.native and with @micropython.viper (the source with the decorator put
before them, exec'd, where the port has those emitters). Run it on a board the same way
(mpremote run) for that board's figures."""

import gc
import math
import sys
import time

try:
    import micropython
except ImportError:
    micropython = None

sys.path.insert(0, (__file__.rsplit("/", 1)[0] if "/" in __file__ else "."))

from graspguide_mp import frame  # noqa: E402
from graspguide_mp import plan_file as pf  # noqa: E402
from graspguide_mp import runner as rn  # noqa: E402
from graspguide_mp import status as st  # noqa: E402
from graspguide_mp.fake_hal import FakeClock, FakeMotors  # noqa: E402
from graspguide_mp.store import MemoryStore  # noqa: E402

HOT = (
    "def alignment_to_gravity",
    "def alignment_from_gravity",
    "def pwm_from_plan",
    "def asin_deg_ratio",
    "    def update(self, accel, gyro, dt_s)",
    "    def on_sample(self, accel, gyro, time_ticks)",
)
PERIOD_US = 10000
BATCH = 100


def _samples(n):
    """n IMU samples of a hand turning slowly, made before timing (lists of floats)."""
    out = []
    for i in range(n):
        a = 0.3 * math.sin(i * 0.01)
        b = 0.2 * math.cos(i * 0.013)
        accel = [
            9.80665 * math.sin(a),
            9.80665 * math.sin(b),
            9.80665 * math.cos(a) + 1e-4 * (i % 5),
        ]
        gyro = [0.003 * math.cos(i * 0.01), -0.0026 * math.sin(i * 0.013), 1e-4 * (i % 3)]
        out.append((accel, gyro))
    return out


def _variant(emitter):
    """frame.py with its hot functions compiled by emitter ("native"/"viper"), as a
    module-like object; None when the port cannot."""
    if emitter is None:
        return frame
    path = (__file__.rsplit("/", 1)[0] if "/" in __file__ else ".") + "/graspguide_mp/frame.py"
    with open(path) as f:
        lines = f.read().split("\n")
    out = []
    for line in lines:
        for h in HOT:
            if line.startswith(h):
                out.append(line[: len(line) - len(line.lstrip())] + "@micropython." + emitter)
        out.append(line)
    g = {"__name__": "frame_" + emitter}
    try:
        exec("\n".join(out), g)
    except Exception as e:  # SyntaxError/ValueError: the emitter is not built in
        print("  (%s: not available here: %s)" % (emitter, e))
        return None

    class M:
        pass

    m = M()
    for k, v in g.items():
        setattr(m, k, v)
    return m


def bench_step(fr, samples):
    est = fr.GravityEstimator()
    plan = fr.PwmPlan([0.45, 0.65, 0.61], 3)
    f_hat = [0.0, -0.6, -0.8]
    out = [0.0, 0.0]
    scratch = [0.0, 0.0, 0.0]
    duty = bytearray(4)
    est.update(samples[0][0], samples[0][1], 0.01)

    def step(a, g):
        est.update(a, g, 0.01)
        fr.alignment_from_gravity(est.gravity, f_hat, out, scratch)
        fr.pwm_from_plan(plan, out[1], duty)

    return _measure(step, samples)


def bench_runner(fr, samples):
    saved = rn.frame
    rn.frame = fr  # the runner's calls go to the variant under test
    try:
        plan = pf.Plan(pf.PlanHeader(), [pf.PlanTrial()])
        h = plan.header
        h.participant = b"BENCH\0\0\0"
        h.trial_count = 1
        h.threshold_deg = 0.0  # never succeeds: every frame is a guiding one
        h.timeout_s = 1800.0
        h.rest_s = 0.0
        h.hand_k3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.04], [-0.01, 0.1, 0.04]]
        t = plan.trials[0]
        t.trial_index = t.session_trial = 1
        t.mode = frame.MODE_V
        t.wrench = [0.0, -0.6, -0.8, 0.001, 0.0, 0.002]
        store = MemoryStore(pf.REGION_BYTES + 4096)
        pf.save_plan(store, plan)
        clock = FakeClock(0)
        r = rn.HostlessRunner(
            FakeMotors(),
            clock,
            store,
            rn.PrecomputedPostures({1: (st.OK, [0.45, 0.65, 0.61])}),
            78.4,
            34.9,
        )
        r.boot()
        r.start()
        now = [0]

        def feed(a, g):
            now[0] += PERIOD_US
            clock.t_us = now[0]
            r.on_sample(a, g, now[0])

        for i in range(120):  # rest, ready pattern, IMU recovery
            feed(samples[i][0], samples[i][1])
        r.on_button(True, now[0])
        assert r.phase == rn.PH_TRIAL
        result = _measure(feed, samples)
        if r.phase != rn.PH_TRIAL or r.frame_status != st.OK:
            raise AssertionError("the runner left its trial: not a guiding frame")
        return result
    finally:
        rn.frame = saved


def _measure(fn, samples):
    n = len(samples)
    per_batch = []
    for b in range(0, n - BATCH + 1, BATCH):
        t0 = time.ticks_us()
        for i in range(b, b + BATCH):
            s = samples[i]
            fn(s[0], s[1])
        per_batch.append(time.ticks_diff(time.ticks_us(), t0) / BATCH)
    per_batch.sort()
    median_us = per_batch[len(per_batch) // 2]
    gc.collect()
    gc.disable()
    try:
        before = gc.mem_alloc()
        for i in range(n):
            s = samples[i]
            fn(s[0], s[1])
        alloc = gc.mem_alloc() - before
    finally:
        gc.enable()
    return median_us, alloc / n


def main(frames=1000):
    samples = _samples(frames)
    impl = sys.implementation
    print(
        "bench_frame: %s %s, %d frames, float %s"
        % (
            impl.name,
            ".".join(str(x) for x in impl.version[:3]),
            frames,
            "double" if 1.0 + 2.0**-40 != 1.0 else "single",
        )
    )
    for emitter in (None, "native", "viper"):
        fr = _variant(emitter)
        if fr is None:
            continue
        name = emitter or "bytecode"
        for what, fn in (("step", bench_step), ("runner", bench_runner)):
            us, bytes_per = fn(fr, samples)
            print(
                "  %-8s %-6s median %7.2f us/frame, %7.1f bytes allocated/frame"
                % (name, what, us, bytes_per)
            )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1000)
