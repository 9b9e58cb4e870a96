"""The board's entry point (MicroPython runs main.py after boot): load the stored plan and
run it with the button, host-less. The defaults are the C++ Feather ESP32 build's
(src/boards/arduino/board_config.h); a board_config.py beside this file may override any
key of CONFIG, e.g.  CONFIG = {"motor_pins": (2, 3, 4, 5), "button_pin": 6}.

A plan deployed as PLAN_PATH (`graspguide mp deploy`, made by `graspguide plan`) is
installed into the store at boot, with the C++ device's rule: refused while the results
log holds another plan's records (download them first), so no record loses its plan.

Per-posture levels: from LEVELS_PATH when the host put one there (`trial_index status m1
m2 m3 [m4]` per line, made by the host's C++ core), else the on-board solver. Whatever
goes wrong, the motors end off."""

from graspguide_mp import hal
from graspguide_mp import plan_file as pf
from graspguide_mp import results_file as rf
from graspguide_mp import runner as rn
from graspguide_mp.store import STORE_BYTES, FileStore, MemoryStore

CONFIG = {
    "motor_pins": (13, 12, 27, 33),
    "button_pin": 32,
    "i2c_id": 0,
    "i2c_scl": 22,  # the Feather's STEMMA QT connector
    "i2c_sda": 23,
    "imu_address": 0x6A,
    "store_path": "/graspguide.bin",
    "store_bytes": STORE_BYTES,
    "levels_path": "/graspguide_levels.txt",
    "plan_path": "/plan.bin",
}

try:
    import board_config

    CONFIG.update(board_config.CONFIG)
except ImportError:
    pass


def _exists(path):
    try:
        open(path).close()
        return True
    except OSError:
        return False


def install_plan(store, path):
    """Installs the plan file at path into store unless the store holds it already.
    Returns what happened, one line for the REPL."""
    if not _exists(path):
        return "no new plan file"
    with open(path, "rb") as f:
        data = f.read()
    staged = MemoryStore(pf.REGION_BYTES)
    if len(data) > pf.REGION_BYTES or not staged.write(0, data):
        return "plan file %s refused: not a plan file (%d bytes)" % (path, len(data))
    status, new = pf.load_plan(staged)
    if status == pf.OLD_LAYOUT:
        return "plan file %s refused: %s" % (path, pf.OLD_LAYOUT_FIX)
    if status != pf.OK:
        return "plan file %s refused: %s" % (path, pf.STORE_STATUS_NAMES[status])
    new_id = pf.plan_id(new)
    status, old = pf.load_plan(store)
    if status == pf.OK and pf.plan_id(old) == new_id:
        return "plan of %s already installed" % new.header.participant_name()
    log = rf.ResultsLog(store)
    mounted = log.mount()
    if mounted != pf.OK:
        return "plan file %s not installed: the log cannot be read (%s)" % (
            path,
            pf.STORE_STATUS_NAMES[mounted],
        )
    if log.holds_other_plan(new_id):
        return (
            "plan file %s not installed: the log holds %d records of another plan; "
            "download them (graspguide mp) and start a new store first" % (path, log.records)
        )
    saved = pf.save_plan(store, new)
    if saved != pf.OK:
        return "plan file %s not installed: %s" % (path, pf.STORE_STATUS_NAMES[saved])
    return "installed the plan of %s (%d trials)" % (
        new.header.participant_name(),
        new.header.trial_count,
    )


def _postures(path):
    if _exists(path):
        print("graspguide: levels from", path, "(precomputed by the host)")
        return rn.PrecomputedPostures.load(path)
    print("graspguide: levels from the on-board solver")
    return rn.SolverPostures()


def matching_postures(postures, plan_id):
    """postures, unless they are levels solved for another plan (a plan.bin that was
    refused, a stale levels file): then the on-board solver."""
    if getattr(postures, "plan_id", plan_id) == plan_id:
        return postures
    print("graspguide: the levels file belongs to another plan: solving on the board")
    return rn.SolverPostures()


def _say(event):
    code, position, trial_index, _ = event
    print("graspguide:", rn.EVENT_NAMES[code], "position", position, "trial", trial_index)


def run(runner, imu, button, clock):
    """The control loop: button edges, IMU samples (the part paces it at 104 Hz), ticks
    between samples, events printed to the REPL. Returns when the run ends."""
    accel = [0.0, 0.0, 0.0]
    gyro = [0.0, 0.0, 0.0]
    while True:
        if button.poll() == hal.EDGE_PRESSED:
            runner.on_button(True, clock.now_us())
        if imu.read_into(accel, gyro):
            runner.on_sample(accel, gyro, clock.now_us())
        else:
            runner.tick(clock.now_us())
        e = runner.pop_event()
        while e is not None:
            _say(e)
            e = runner.pop_event()
        if not runner.running():
            return


def main(config=CONFIG):
    clock = hal.Clock()
    motors = hal.Motors(config["motor_pins"])  # first, so the motors are driven off
    try:
        button = hal.Button(config["button_pin"], clock)
        imu = hal.lsm6dsox_imu(
            config["i2c_id"], config["i2c_scl"], config["i2c_sda"], address=config["imu_address"]
        )
        store = FileStore(config["store_path"], config["store_bytes"])
        print("graspguide:", install_plan(store, config["plan_path"]))
        runner = rn.HostlessRunner(
            motors,
            clock,
            store,
            _postures(config["levels_path"]),
            imu.accel_full_scale_mps2(),
            imu.gyro_full_scale_radps(),
            imu.SIX_AXIS,
        )
        mounted = runner.boot()
        if mounted != pf.OK:
            print("graspguide: the results log cannot be read:", pf.STORE_STATUS_NAMES[mounted])
            return
        if runner.plan is None and runner.plan_status == pf.OLD_LAYOUT:
            print("graspguide: not started:", pf.OLD_LAYOUT_FIX)
            return
        if runner.plan is None:
            print("graspguide: no plan stored in", config["store_path"], "- deploy one first")
            return
        runner.postures = matching_postures(runner.postures, pf.plan_id(runner.plan))
        refused = runner.start()
        if refused is not None:
            print("graspguide: not started:", refused)
        run(runner, imu, button, clock)
    finally:
        motors.off()


if __name__ == "__main__":
    main()
