"""The per-frame layer on the ATmega328P: built with avr-gcc (`pio run -e avr_cue`), run
under simavr at 8 MHz, its PWM against the float64 reference on the same inputs, cycle
counts produced for every part; and graspguide.bench.avr_target's parser, baseline rule
and errors on synthetic output. The regression check against tools/perf/avr_baseline.json
is tools/run-tests.sh's "AVR per-frame layer" case."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import REPO_ROOT

from graspguide.bench import avr_target

ROOT = Path(REPO_ROOT)


@pytest.fixture(scope="module")
def measured():
    try:
        avr_target.check_tools()
    except avr_target.AvrToolMissing as e:
        pytest.skip(str(e))
    return avr_target.measure(ROOT)[avr_target.KEY]


def test_the_avr_pwm_equals_the_float64_reference_within_one_count(measured):
    records = avr_target.stimulus()
    frames = sum(r.tag in "QG" for r in records)
    p = measured["pwm_vs_float64"]
    assert p["compared"] == frames > 0
    assert p["max_diff"] <= 1
    assert measured["status_not_ok"] == []


def test_the_error_angle_keeps_float_accuracy_at_0_3_and_180_degrees(measured):
    err = measured["error_vs_float64_deg"]
    for kind in ("near_0", "at_3", "near_180", "random", "other"):
        # float32 inputs and arithmetic: a few 1e-7 radians, far below the 3-degree threshold
        assert 0 <= err[kind] < 1e-3, kind
    assert measured["alpha_vs_float64_max"] < 1e-3


def test_cycle_counts_are_produced_for_every_part(measured):
    parts = measured["cycles"]
    for k in (3, 4):
        for mode in ("C", "V"):
            for kind in ("frame", "frame_from_gravity"):
                s = parts[f"{kind} k{k} {mode}"]
                assert s["n"] == avr_target.RANDOM_ORIENTATIONS + sum(
                    len(a) for a in avr_target.SPECIAL_ANGLES.values()
                )
                assert 0 < s["median"] <= s["max"]
    for part in ("pwm_plan", "trial_start", "trial_update", "watchdog"):
        assert 0 < parts[part]["median"] <= parts[part]["max"]
    # The frame is float arithmetic in software: far more than the bookkeeping around it.
    assert parts["frame k4 V"]["median"] > 10 * parts["watchdog"]["median"]


def test_trial_and_watchdog_behave_as_the_stimulus_was_built(measured):
    # A hold that succeeds, a timeout that fails, a step back in time, a stale stream and
    # the trial's deadline, with host and device clocks wrapping during them.
    assert measured["behaviour_mismatches"] == []


def test_flash_ram_and_stack_fit_the_pro_mini(measured):
    assert 0 < measured["flash_bytes"] <= 30 * 1024
    assert 0 < measured["ram_static_bytes"] + measured["stack_bytes"] <= 1536
    assert 0 < measured["harness_io_flash_bytes"] < measured["flash_bytes"]


def test_the_committed_baseline_reads_and_covers_every_part(measured):
    base = avr_target.load_baseline(ROOT / avr_target.BASELINE)
    assert set(base[avr_target.KEY]) == set(measured["cycles"])


# --------------------------------------------------------------------------------------
# The module's logic on synthetic output
# --------------------------------------------------------------------------------------
def fake_lines(records, cycles=5000, pwm="70 70 70 0", stack=90):
    out = []
    for r in records:
        if r.tag == "S":
            out.append("S 300")
        elif r.tag == "O":
            out.append("O 1")
        elif r.tag in "QG":
            out.append(f"{r.tag} {cycles} 0 3f800000 40000000 {pwm}")
        elif r.tag == "C":
            out.append("C 2000 0")
        elif r.tag in "TW":
            out.append(f"{r.tag} 500 " + " ".join(map(str, r.expect)))
        elif r.tag == "E":
            out.append(f"E {stack}")
    return out


def test_parse_pairs_answers_with_records_and_subtracts_the_mark_cost():
    records = avr_target.stimulus()
    m = avr_target.parse(fake_lines(records), records)
    assert m.overhead == 1
    assert m.stack_bytes == 90
    assert set(m.cycles["frame k4 V"]) == {4999}
    assert m.mismatches == []


def test_parse_rejects_missing_extra_and_misplaced_lines():
    records = avr_target.stimulus()
    lines = fake_lines(records)
    with pytest.raises(avr_target.AvrBadOutput, match="lines for"):
        avr_target.parse(lines[:-2] + lines[-1:], records)
    with pytest.raises(avr_target.AvrBadOutput, match="answers a"):
        avr_target.parse(["W 1 0 0"] + lines[1:], records)
    q = next(i for i, r in enumerate(records) if r.tag == "Q")
    broken = list(lines)
    broken[q] = "Q 5000 0 3f800000"
    with pytest.raises(avr_target.AvrBadOutput, match="9 fields"):
        avr_target.parse(broken, records)


def test_parse_lists_a_trial_outcome_other_than_the_stimulus():
    records = avr_target.stimulus()
    lines = fake_lines(records)
    t = next(i for i, r in enumerate(records) if r.tag == "T")
    lines[t] = "T 500 0 3"  # failed, where the trial must still run
    m = avr_target.parse(lines, records)
    assert len(m.mismatches) == 1 and "(status, state)" in m.mismatches[0]


def summary(median=5000, pwm_diff=0, mismatches=()):
    return {
        avr_target.KEY: {
            "cycles": {"frame k4 V": {"median": median, "max": median + 100, "n": 3}},
            "pwm_vs_float64": {"compared": 3, "max_diff": pwm_diff},
            "status_not_ok": [],
            "behaviour_mismatches": list(mismatches),
        }
    }


def test_check_fails_on_growth_over_ten_percent_only():
    base = {avr_target.KEY: {"frame k4 V": {"median": 5000, "max": 5100}}}
    failed, _ = avr_target.check(summary(5500), base)  # +10 % exactly: allowed
    assert not failed
    failed, lines = avr_target.check(summary(5501), base)
    assert failed and any(line.startswith("REGRESSION") for line in lines)
    failed, lines = avr_target.check(summary(5000), {avr_target.KEY: {}})
    assert not failed and any(line.startswith("new ") for line in lines)


def test_check_fails_on_pwm_disagreement_and_behaviour():
    base = {avr_target.KEY: {"frame k4 V": {"median": 5000, "max": 5100}}}
    assert avr_target.check(summary(pwm_diff=2), base)[0]
    assert not avr_target.check(summary(pwm_diff=1), base)[0]
    assert avr_target.check(summary(mismatches=["line 3: ..."]), base)[0]


def test_baseline_round_trip_and_bad_files(tmp_path):
    path = tmp_path / "avr.json"
    results = summary()
    avr_target.write_baseline(path, results)
    assert avr_target.load_baseline(path) == {
        avr_target.KEY: {"frame k4 V": {"median": 5000, "max": 5100}}
    }
    with pytest.raises(avr_target.AvrTargetError, match="--update-baseline"):
        avr_target.load_baseline(tmp_path / "missing.json")
    path.write_text(json.dumps({avr_target.KEY: {"frame": {"median": "fast"}}}))
    with pytest.raises(avr_target.AvrTargetError, match="not"):
        avr_target.load_baseline(path)


def test_a_missing_toolchain_says_what_to_install(monkeypatch):
    real = shutil.which
    monkeypatch.setattr(shutil, "which", lambda t, *a, **k: None if t == "avr-g++" else real(t))
    with pytest.raises(avr_target.AvrToolMissing, match="gcc-avr"):
        avr_target.check_tools()
