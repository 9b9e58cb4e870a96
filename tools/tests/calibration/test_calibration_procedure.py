"""The calibration procedure without a device (graspguide.calibration): the staircases
find the virtual observer's known detection point, matching finds its known gain, over
many seeds; catch trials expose a yes-sayer; bad settings and impossible measurements are
clear errors. The truth is always the observer's parameters, never a number written
here."""

from __future__ import annotations

import math
import random
import statistics

import pytest

from graspguide.calibration.detection import Detection
from graspguide.calibration.matching import Matching, MatchingSettings, matching_gain
from graspguide.calibration.session import (
    CalibrationFailed,
    CalibrationSettings,
    run_procedure,
)
from graspguide.calibration.staircase import Staircase, StaircaseSettings, target_probability
from graspguide.calibration.virtual_observer import (
    FingerSensitivity,
    VirtualObserver,
    parse_participant_source,
)
from graspguide.core.motor_calibration import GAIN_RANGE
from graspguide.core.reference import PWM_RANGE

SEEDS = range(100)
FINGERS = ("thumb", "index", "middle")


class NoDevice:
    """A stimulator that presents nothing: the observer answers from the PWM alone."""

    def __init__(self) -> None:
        self.stimuli: list[tuple[str, int]] = []

    def detection(self, finger: str, pwm: int) -> None:
        self.stimuli.append((finger, pwm))

    def pair(self, first: tuple[str, int], second: tuple[str, int]) -> None:
        self.stimuli += [first, second]


def _detect(observer: VirtualObserver, finger: str, settings: StaircaseSettings, seed: int):
    det = Detection(settings, 0.2, random.Random(seed))
    while not det.done:
        det.answer(observer.detect(finger, det.next_trial().pwm))
    return det


@pytest.mark.parametrize("down", [2, 3])
def test_staircase_converges_on_the_observers_point(down):
    """1-up-2-down tracks P(yes) = 70.7 %, 1-up-3-down 79.4 % (Levitt 1971): the estimate
    lands on the observer's own inverse psychometric function at that probability.
    Tolerance (300 staircases): mean error within 1.5 counts (no bias), RMS within 4
    counts, 95 % within 8 counts; every staircase converges."""
    settings = StaircaseSettings(start=150, down=down)
    errors = []
    for seed in SEEDS:
        obs = VirtualObserver(seed)
        for finger in FINGERS:
            det = _detect(obs, finger, settings, seed)
            assert det.staircase.converged, (seed, finger)
            truth = obs.detection_point(finger, target_probability(down))
            errors.append(det.threshold() - truth)
    rms = math.sqrt(statistics.fmean(e * e for e in errors))
    within = sum(abs(e) <= 8 for e in errors) / len(errors)
    print(
        f"1-up-{down}-down: mean {statistics.fmean(errors):+.2f}, RMS {rms:.2f}, "
        f"{within:.1%} within 8 counts, worst {max(errors, key=abs):+.1f}"
    )
    assert abs(statistics.fmean(errors)) <= 1.5
    assert rms <= 4.0
    assert within >= 0.95


def test_matching_recovers_the_observers_gain():
    """Matching alone, given the observer's true floors: the PSE is the observer's
    (mean within 1 count, RMS within 4) and the gain its magnitude ratio (mean relative
    error within 2 %, RMS within 6 %, 95 % within 10 %), 200 matches."""
    pse_err, gain_err = [], []
    ref_pwm = 162
    for seed in SEEDS:
        obs = VirtualObserver(seed)
        rng = random.Random(seed)
        t_ref = obs.fingers["index"].threshold_pwm
        for finger in ("thumb", "middle"):
            t = obs.fingers[finger].threshold_pwm
            m = Matching(MatchingSettings(), round(t), t + ref_pwm - t_ref, rng)
            while not m.done:
                trial = m.next_trial()
                comparison, reference = (finger, trial.comparison_pwm), ("index", ref_pwm)
                pair = (
                    (comparison, reference) if trial.comparison_first else (reference, comparison)
                )
                which = obs.compare(finger, *pair)
                m.answer((which == 1) == trial.comparison_first)
            assert m.converged
            pse_err.append(m.pse() - obs.true_pse(finger, "index", ref_pwm))
            gain = matching_gain(m.pse(), t, ref_pwm, t_ref)
            gain_err.append(gain / obs.true_gain(finger, "index") - 1)
    rms_pse = math.sqrt(statistics.fmean(e * e for e in pse_err))
    rms_gain = math.sqrt(statistics.fmean(e * e for e in gain_err))
    print(
        f"PSE error mean {statistics.fmean(pse_err):+.2f} RMS {rms_pse:.2f}; gain relative "
        f"error mean {statistics.fmean(gain_err):+.3f} RMS {rms_gain:.3f}"
    )
    assert abs(statistics.fmean(pse_err)) <= 1.0 and rms_pse <= 4.0
    assert abs(statistics.fmean(gain_err)) <= 0.02 and rms_gain <= 0.06
    assert sum(abs(e) <= 0.10 for e in gain_err) / len(gain_err) >= 0.95


def test_whole_procedure_recovers_floors_and_gains():
    """The whole procedure (measured floors, then matching on them): floors at the
    observer's 70.7 % point (RMS within 4 counts), gains within 15 % RMS of its magnitude
    ratio (the measured floors' error enters the gain: docs/calibration.md), 60 runs."""
    floor_err, gain_err = [], []
    for seed in range(60):
        obs = VirtualObserver(seed)
        settings = CalibrationSettings(seed=seed, min_floor=0, headroom=False)
        stim = NoDevice()
        result = run_procedure(settings, obs, stim)
        assert len(stim.stimuli) >= len(result.trials)  # every trial presented something
        for finger, r in result.fingers.items():
            floor_err.append(
                r.threshold_pwm - obs.detection_point(finger, settings.detection.target)
            )
            assert result.calibration.pwm_floor[r.motor - 1] == r.pwm_floor
            if finger != "index":
                gain_err.append(r.gain / obs.true_gain(finger, "index") - 1)
        assert result.calibration.gain[1] == 1.0  # the reference
        assert result.calibration.pwm_floor[3] == 70 and result.calibration.gain[3] == 1.0
    rms_floor = math.sqrt(statistics.fmean(e * e for e in floor_err))
    rms_gain = math.sqrt(statistics.fmean(e * e for e in gain_err))
    print(f"floor RMS {rms_floor:.2f} counts, gain RMS {rms_gain:.3f}")
    assert rms_floor <= 4.0
    assert rms_gain <= 0.15


def test_every_trial_is_recorded():
    obs = VirtualObserver(7)
    result = run_procedure(CalibrationSettings(seed=7), obs, NoDevice())
    det = [t for t in result.trials if t["phase"] == "detection"]
    match = [t for t in result.trials if t["phase"] == "matching"]
    assert [t["n"] for t in result.trials] == list(range(1, len(result.trials) + 1))
    for f, r in result.fingers.items():
        mine = [t for t in det if t["finger"] == f]
        assert sum(t["catch"] for t in mine) == r.catch_trials
        assert sum(t["catch"] and t["answer"] == "yes" for t in mine) == r.false_alarms
        assert all(t["pwm"] == 0 for t in mine if t["catch"])
        if f != "index":
            assert {t["staircase"] for t in match if t["finger"] == f} == {
                "from_above",
                "from_below",
            }
    for t in match:
        comparison_first = t["order"] == "comparison_first"
        assert t["comparison_stronger"] == ((t["answer"] == "first") == comparison_first)


def test_same_seed_same_result():
    a = run_procedure(CalibrationSettings(seed=5), VirtualObserver(5), NoDevice())
    b = run_procedure(CalibrationSettings(seed=5), VirtualObserver(5), NoDevice())
    assert a.calibration == b.calibration
    assert [{k: v for k, v in t.items() if k != "t_s"} for t in a.trials] == [
        {k: v for k, v in t.items() if k != "t_s"} for t in b.trials
    ]


def test_a_yes_sayer_shows_in_the_false_alarm_rate():
    honest = run_procedure(CalibrationSettings(seed=1), VirtualObserver(1), NoDevice())
    liar_obs = VirtualObserver(1, false_alarm=0.5)
    liar = run_procedure(CalibrationSettings(seed=1), liar_obs, NoDevice())
    assert liar.false_alarm_rate is not None and honest.false_alarm_rate is not None
    assert liar.false_alarm_rate > 0.3 > honest.false_alarm_rate
    assert any("false-alarm rate" in w for w in liar.warnings)
    assert not any("false-alarm rate" in w for w in honest.warnings)


def test_floor_never_below_the_motor_start():
    """An observer more sensitive than the motor start: the floor is --min-floor."""
    fingers = {f: FingerSensitivity(40.0, 3.0, 1.0) for f in ("thumb", "index", "middle", "palm")}
    obs = VirtualObserver(2, fingers=fingers)
    result = run_procedure(CalibrationSettings(seed=2, min_floor=70), obs, NoDevice())
    for r in result.fingers.values():
        assert r.threshold_pwm < 70 and r.pwm_floor == 70 and r.floor_clamped
    assert sum("below the motor's start" in w for w in result.warnings) == 3


def test_headroom_scales_every_gain_alike_so_no_finger_clips():
    """With headroom (the default), no measured finger's strongest duty passes 255, and
    the gains are the matched ones times one factor (the same trials: the scaling comes
    after the measurement), rounded down to 4 decimals."""
    from graspguide.calibration.session import headroom_scale

    scaled_runs = 0
    for seed in range(40):
        raw = run_procedure(
            CalibrationSettings(seed=seed, headroom=False), VirtualObserver(seed), NoDevice()
        )
        cal = run_procedure(CalibrationSettings(seed=seed), VirtualObserver(seed), NoDevice())
        assert [t["answer"] for t in cal.trials] == [t["answer"] for t in raw.trials]
        fingers = list(raw.fingers.values())
        scale = headroom_scale([r.pwm_floor for r in fingers], [r.gain for r in fingers])
        for r in fingers:
            got = cal.fingers[r.finger]
            assert got.pwm_floor == r.pwm_floor
            assert got.pwm_floor + got.gain * PWM_RANGE <= 255 + 1e-9, (seed, r.finger)
            if scale < 1:
                # each rounded down to 4 decimals, the scale and the gain
                tol = 1e-4 * (1 + r.gain) + 1e-12
                assert got.gain == pytest.approx(r.gain * scale, abs=tol), (seed, r.finger)
                assert got.gain_scale < 1
            else:
                assert got.gain == r.gain and got.gain_scale == 1.0
        if scale < 1:
            scaled_runs += 1
            assert any("scaled by" in w for w in cal.warnings)
    assert scaled_runs >= 5  # the observer's fingers do saturate often enough to test it


def test_gain_outside_the_range_is_clipped_with_a_warning():
    fingers = {f: FingerSensitivity(80.0, 3.0, 1.0) for f in ("thumb", "index", "middle", "palm")}
    fingers["thumb"] = FingerSensitivity(80.0, 3.0, 8.0)  # eight times as sensitive
    obs = VirtualObserver(3, fingers=fingers, lapse=0.0)
    result = run_procedure(CalibrationSettings(seed=3), obs, NoDevice())
    thumb = result.fingers["thumb"]
    assert thumb.gain_raw is not None and thumb.gain_raw < GAIN_RANGE[0]
    assert thumb.gain == GAIN_RANGE[0] and thumb.gain_clipped
    assert any(w.startswith("thumb: gain") and "clipped" in w for w in result.warnings)


def test_a_thimble_never_felt_is_an_error():
    fingers = {f: FingerSensitivity(80.0, 3.0, 1.0) for f in ("thumb", "index", "middle", "palm")}
    fingers["middle"] = FingerSensitivity(900.0, 3.0, 1.0)
    obs = VirtualObserver(4, fingers=fingers, false_alarm=0.0, lapse=0.0)
    with pytest.raises(CalibrationFailed, match="middle: .*not felt even at PWM 255"):
        run_procedure(CalibrationSettings(seed=4), obs, NoDevice())


def test_staircase_rules():
    """The transformed up-down rule step by step: down only after `down` positives, up
    after each negative, a reversal where the direction turns, the step halved there."""
    s = Staircase(
        StaircaseSettings(start=100, down=2, initial_step=16, min_step=2, reversals=4, use_last=2)
    )
    s.answer(True)
    assert s.level == 100  # one positive: no step yet
    s.answer(True)
    assert s.level == 84 and not s.reversal_levels
    s.answer(False)
    assert s.reversal_levels == [84] and s.step == 8 and s.level == 92
    with pytest.raises(ValueError, match="staircase down must be 1, 2 or 3"):
        StaircaseSettings(start=100, down=4)
    with pytest.raises(ValueError, match="staircase start must be in 0..255"):
        StaircaseSettings(start=300)
    with pytest.raises(ValueError, match="use_last"):
        StaircaseSettings(start=100, reversals=4, use_last=6)
    assert target_probability(1) == 0.5
    assert target_probability(2) == pytest.approx(math.sqrt(0.5))
    assert target_probability(3) == pytest.approx(0.5 ** (1 / 3))


def test_bad_settings_name_the_option():
    with pytest.raises(ValueError, match="--fingers: unknown finger 'pinky'"):
        CalibrationSettings(fingers=("thumb", "pinky"))
    with pytest.raises(ValueError, match="--reference middle: must be one of --fingers"):
        CalibrationSettings(fingers=("thumb", "index"), reference="middle")
    with pytest.raises(ValueError, match="--fingers: a finger is named twice"):
        CalibrationSettings(fingers=("index", "index"))
    with pytest.raises(ValueError, match="--reference-pwm must be above --min-floor"):
        CalibrationSettings(reference_pwm=60)


def test_source_spec():
    assert parse_participant_source("operator") is None
    obs = parse_participant_source("participant:seed=9,false_alarm=0.1")
    assert obs is not None and obs.seed == 9 and obs.false_alarm == 0.1
    for bad, msg in [
        ("participant:colour=3", "bad option 'colour=3'"),
        ("participant:seed=x", "seed must be a number"),
        ("synthetic", "use 'operator'"),
        ("participant:false_alarm=2", "false_alarm must be in"),
    ]:
        with pytest.raises(ValueError, match=msg):
            parse_participant_source(bad)
