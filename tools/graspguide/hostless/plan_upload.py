"""One participant's study plan as the PLAN_BEGIN and PLAN_TRIAL messages a host-less
device stores (docs/protocol.md): the runner's plan (study_protocol.plan) in the wire's
units and enums, refused with a clear error where the wire cannot hold it."""

from __future__ import annotations

import math
from collections.abc import Sequence

from graspguide.core.motor_calibration import MotorCalibration
from graspguide.link.client import (
    CONSTRAINT_NAMES,
    MODE_NAMES,
    POLICY_NAMES,
    calibration_message,
    to_f32,
)
from graspguide.link.messages import (
    CONFIG_HASH_SIZE,
    MAX_PLAN_TRIALS,
    PARTICIPANT_ID_SIZE,
    PlanBegin,
    PlanTrial,
    WrenchClass,
)
from graspguide.protocol.study_protocol import (
    PlannedTrial,
    Protocol,
    draw_familiarization_wrenches,
    draw_wrenches,
    plan,
)

# PLAN_BEGIN.rest_s's range (the schema's): the device refuses anything else.
REST_S_RANGE = (0.0, 600.0)
# How far |imu_to_hand_wxyz| may be from 1: a rotation, not a typo.
QUAT_NORM_TOLERANCE = 1e-3
# PLAN_TRIAL's integer fields are u8/u16 on the wire.
U8_MAX = 0xFF
U16_MAX = 0xFFFF
# Postures the plan carries (PLAN_BEGIN.hand_k3 / hand_k4).
POSTURE_CONTACTS = {3: 3, 4: 4}
WRENCH_CLASSES = {"single": WrenchClass.SINGLE, "multi": WrenchClass.MULTI, "": WrenchClass.NONE}
# Wrench ids of the plan: W01.. for the sessions, F01.. for familiarization.
WRENCH_PREFIX = {False: "W", True: "F"}


def planned_trials(protocol: Protocol, participant: str) -> list[PlannedTrial]:
    """The participant's plan exactly as StudyRunner draws it."""
    return plan(
        protocol,
        participant,
        draw_wrenches(protocol),
        draw_familiarization_wrenches(protocol),
    )


def config_hash_prefix(protocol: Protocol) -> tuple[int, ...]:
    """The first CONFIG_HASH_SIZE bytes of the protocol's sha256 (study.json config_hash)."""
    return tuple(bytes.fromhex(protocol.config_hash)[:CONFIG_HASH_SIZE])


def wrench_number(trial: PlannedTrial) -> int:
    """The number in the trial's wrench id (W07 -> 7, F02 -> 2); ValueError if the id
    is not the plan's form or the number does not fit PLAN_TRIAL.wrench_number."""
    prefix = WRENCH_PREFIX[bool(trial.familiarization)]
    wid = trial.wrench_id
    if not (wid.startswith(prefix) and wid[1:].isdigit()):
        raise ValueError(
            f"trial {trial.trial_index}: wrench_id {wid!r} is not {prefix}<number> "
            "(the plan names its wrenches W01.., familiarization F01..)"
        )
    n = int(wid[1:])
    if not 1 <= n <= U8_MAX:
        raise ValueError(
            f"trial {trial.trial_index}: wrench_id {wid!r}: a host-less plan numbers its "
            f"wrenches 1..{U8_MAX}; lower [wrenches] count (or [familiarization] trials) "
            "in the protocol file"
        )
    return n


def _posture(protocol: Protocol, k: int, used: bool) -> tuple[tuple[float, ...], ...]:
    contacts = protocol.hands.get(k)
    if contacts is None:
        if used:
            raise ValueError(
                f"the plan has {k}-contact trials but the protocol has no [hand.k{k}]: add it"
            )
        # A posture no trial uses: zeros, never read by the device.
        return ((0.0, 0.0, 0.0),) * POSTURE_CONTACTS[k]
    return tuple(tuple(to_f32(v) for v in c) for c in contacts)


def _check_participant(participant: str) -> None:
    printable = participant.isascii() and participant.isprintable()
    if not participant or len(participant) > PARTICIPANT_ID_SIZE or not printable:
        raise ValueError(
            f"participant {participant!r}: a host-less plan holds a printable ASCII id of 1.."
            f"{PARTICIPANT_ID_SIZE} characters (PLAN_BEGIN.participant); use a shorter id "
            "such as U1"
        )


def _check_rotation(imu_to_hand_wxyz: Sequence[float]) -> tuple[float, ...]:
    q = tuple(float(v) for v in imu_to_hand_wxyz)
    if len(q) != 4 or not all(math.isfinite(v) for v in q):
        raise ValueError(
            f"imu_to_hand_wxyz must be 4 finite numbers (w, x, y, z), got {imu_to_hand_wxyz!r}"
        )
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > QUAT_NORM_TOLERANCE:
        raise ValueError(
            f"imu_to_hand_wxyz {q} has norm {norm:.6g}: give a unit quaternion (the rotation "
            "from the IMU's axes to the hand's)"
        )
    return tuple(to_f32(v) for v in q)


def plan_trial(position: int, trial: PlannedTrial) -> PlanTrial:
    """The PLAN_TRIAL at ``position`` of one planned trial."""
    for name, value, top in (
        ("trial_index", trial.trial_index, U16_MAX),
        ("session", trial.session, U8_MAX),
        ("session_trial", trial.session_trial, U8_MAX),
    ):
        if not 0 <= value <= top:
            raise ValueError(
                f"trial {trial.trial_index}: {name} {value} does not fit a host-less plan "
                f"(0..{top}); plan fewer sessions or wrenches"
            )
    if trial.wrench_class not in WRENCH_CLASSES:
        raise ValueError(
            f"trial {trial.trial_index}: wrench_class {trial.wrench_class!r} is not one of "
            "'single', 'multi', ''"
        )
    if len(trial.wrench) != 6:
        raise ValueError(f"trial {trial.trial_index}: wrench must have 6 numbers")
    return PlanTrial(
        position=position,
        trial_index=trial.trial_index,
        session=trial.session,
        session_trial=trial.session_trial,
        k=trial.k,
        policy=POLICY_NAMES[trial.policy],
        mode=MODE_NAMES[trial.mode],
        familiarization=bool(trial.familiarization),
        single_motor=bool(trial.single_motor),
        wrench_class=WRENCH_CLASSES[trial.wrench_class],
        wrench_number=wrench_number(trial),
        wrench=tuple(to_f32(v) for v in trial.wrench),
    )


def plan_messages(
    protocol: Protocol,
    participant: str,
    planned_trials: Sequence[PlannedTrial],
    simulated: bool,
    rest_s: float,
    imu_to_hand_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    calibration: MotorCalibration | None = None,
) -> tuple[PlanBegin, list[PlanTrial]]:
    """(PLAN_BEGIN, the PLAN_TRIALs in run order) of ``planned_trials`` (the runner's plan
    of ``participant``), carrying the participant's ``calibration`` (the identity, the
    paper's mapping, when None): the device applies it to every trial's PWM. Upload it with
    ``client.upload_plan(begin, trials, calibration=calibration)``. ValueError naming the
    field and the fix for a plan the device cannot hold: more than MAX_PLAN_TRIALS trials,
    an id longer than PARTICIPANT_ID_SIZE, a wrench number beyond 255, a rest out of
    REST_S_RANGE."""
    _check_participant(participant)
    planned = list(planned_trials)
    if not 1 <= len(planned) <= MAX_PLAN_TRIALS:
        raise ValueError(
            f"the plan of {participant} has {len(planned)} trials; a host-less device holds "
            f"1..{MAX_PLAN_TRIALS}: lower [wrenches] count, [conditions] modalities or "
            "contact_counts, or [familiarization] trials in the protocol file"
        )
    for t in planned:
        if t.participant != participant:
            raise ValueError(
                f"trial {t.trial_index} is planned for {t.participant!r}, not {participant!r}"
            )
    lo, hi = REST_S_RANGE
    if not (math.isfinite(rest_s) and lo <= rest_s <= hi):
        raise ValueError(f"rest_s must be in [{lo:g}, {hi:g}] seconds, got {rest_s!r}")
    ks = {t.k for t in planned}
    cal = calibration_message(calibration or MotorCalibration.identity())
    begin = PlanBegin(
        participant=participant,
        simulated=bool(simulated),
        config_hash=config_hash_prefix(protocol),
        trial_count=len(planned),
        constraints=CONSTRAINT_NAMES[protocol.constraints],
        y_axis=tuple(to_f32(v) for v in protocol.y_axis),
        threshold_deg=to_f32(protocol.threshold_deg),
        hold_s=to_f32(protocol.hold_s),
        timeout_s=to_f32(protocol.timeout_s),
        rest_s=to_f32(rest_s),
        hand_k3=_posture(protocol, 3, 3 in ks),
        hand_k4=_posture(protocol, 4, 4 in ks),
        imu_to_hand_wxyz=_check_rotation(imu_to_hand_wxyz),
        pwm_floor=cal.pwm_floor,
        gain=cal.gain,
    )
    return begin, [plan_trial(i, t) for i, t in enumerate(planned)]


__all__ = [
    "plan_messages",
    "plan_trial",
    "planned_trials",
    "config_hash_prefix",
    "wrench_number",
    "REST_S_RANGE",
    "QUAT_NORM_TOLERANCE",
]
