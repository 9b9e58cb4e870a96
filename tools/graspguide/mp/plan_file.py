"""The plan file a MicroPython board reads (``plan.bin``; ``graspguide plan``, ``graspguide mp
deploy``): the host-less plan region, optionally followed by each trial's motor levels
precomputed by the C++ core, for boards too slow to solve a posture themselves.

Layout, little-endian throughout:

1. **The plan region** exactly as ``plan_store.h`` writes it at offset 0 of a device's store
   (not padded to its 8,192 bytes): the 16-byte preamble (u32 magic ``"GGPL"``, u16 layout
   version 2, u16 reserved 0, u32 payload length, u32 CRC-32 of the payload), then the
   payload: the 168-byte header (PLAN_BEGIN's fields in order, ending with the
   participant's calibration: u8 pwm_floor[4], f32 gain[4]) and one 35-byte trial per
   planned trial (PLAN_TRIAL's fields without ``position``). Layout 1 (no calibration) is
   refused by the board, never misread.
2. **The levels block** (optional; absent when the file ends after the payload):

   ======  =====  ==========================================================
   offset  type   field
   ======  =====  ==========================================================
   0       u32    magic ``"GGLV"`` (0x564C4747)
   4       u16    layout version (1)
   6       u16    trial count (the plan's)
   8       u32    plan id: the CRC-32 of the plan payload above, so levels
                  are never applied to another plan
   12      32 B   per trial, in plan order: u8 status code (graspguide_cue/
                  status.h; 0 ok), u8 k, u16 reserved 0, f32 levels[4]
                  (0 beyond k), f32 force_unit[3] (f̂, the unit force in the
                  hand frame)
   12+32n  u32    CRC-32 of every byte of the block before it
   ======  =====  ==========================================================

The CRC-32 is zlib's (storage_crc.h). Levels are solved in double precision and rounded to
float32, as the board stores them."""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

from graspguide.core.motor_calibration import MotorCalibration
from graspguide.link.client import CONSTRAINT_NAMES, MODE_NAMES, POLICY_NAMES
from graspguide.link.messages import PlanBegin, PlanTrial

PLAN_MAGIC = 0x4C504747  # "GGPL"
PLAN_LAYOUT_VERSION = 2  # 2: the header ends with the calibration
PLAN_PREAMBLE = struct.Struct("<IHHII")
PLAN_HEADER_BYTES = 168
PLAN_TRIAL_BYTES = 35

LEVELS_MAGIC = 0x564C4747  # "GGLV"
LEVELS_LAYOUT_VERSION = 1
LEVELS_HEADER = struct.Struct("<IHHI")
LEVELS_TRIAL = struct.Struct("<BBH4f3f")
LEVELS_CRC = struct.Struct("<I")
MAX_MOTORS = 4

_POLICY = {v: k for k, v in POLICY_NAMES.items()}
_MODE = {v: k for k, v in MODE_NAMES.items()}
_CONSTRAINTS = {v: k for k, v in CONSTRAINT_NAMES.items()}


class PlanSolveError(ValueError):
    """A planned trial the core cannot solve (the board would refuse the plan too)."""


@dataclass(frozen=True)
class TrialLevels:
    """One trial's precomputed posture: what the board would otherwise solve."""

    status: str
    status_code: int
    k: int
    levels: tuple[float, ...]  # MAX_MOTORS, float32-rounded, 0 beyond k
    force_unit: tuple[float, float, float]


def plan_payload(begin: PlanBegin, trials: Sequence[PlanTrial]) -> bytes:
    """The plan's stored bytes: the header, then each trial (their link payloads, which
    plan_store.h stores field by field in the same order, without PLAN_TRIAL's position)."""
    if begin.trial_count != len(trials):
        raise ValueError(
            f"PLAN_BEGIN says trial_count {begin.trial_count} but {len(trials)} trials were given"
        )
    header = begin.pack()
    assert len(header) == PLAN_HEADER_BYTES
    parts = [header]
    for t in trials:
        body = t.pack()[2:]  # drop the u16 position: the store keeps trials in order
        assert len(body) == PLAN_TRIAL_BYTES
        parts.append(body)
    return b"".join(parts)


def plan_id(payload: bytes) -> int:
    """The plan's id, as the device computes it: the CRC-32 of its payload."""
    return zlib.crc32(payload) & 0xFFFFFFFF


def plan_region(payload: bytes) -> bytes:
    """The preamble and the payload, as save_plan leaves them at offset 0 of the store."""
    pre = PLAN_PREAMBLE.pack(PLAN_MAGIC, PLAN_LAYOUT_VERSION, 0, len(payload), plan_id(payload))
    return pre + payload


def _status_code(status: str) -> int:
    from graspguide.core import solver

    return list(solver.STATUS_NAMES).index(status)


def solve_levels(begin: PlanBegin, trials: Sequence[PlanTrial]) -> list[TrialLevels]:
    """Each trial's levels and force direction from the C++ core (double precision), on the
    plan's own float32 posture, wrench and y axis. PlanSolveError names the first trial the
    core cannot solve: the board would refuse that plan (docs/hostless.md)."""
    from graspguide.core import solver
    from graspguide.core.posture import solve_posture

    out = []
    for position, t in enumerate(trials):
        contacts = [list(c) for c in (begin.hand_k3 if t.k == 3 else begin.hand_k4)]
        posture = solve_posture(
            contacts[: t.k],
            list(t.wrench),
            policy=_POLICY[t.policy],
            mode=_MODE[t.mode],
            constraints=_CONSTRAINTS[begin.constraints],
            y_axis=begin.y_axis,
        )
        if posture.status != "ok":
            raise PlanSolveError(
                f"trial at position {position} (trial_index {t.trial_index}, k={t.k}): the "
                f"core answers {posture.status}: {solver.status_message(posture.status)}; "
                "the board would refuse this plan too: change its wrench or posture"
            )
        out.append(
            TrialLevels(
                status=posture.status,
                status_code=_status_code(posture.status),
                k=t.k,
                levels=posture.levels,
                force_unit=posture.force_unit,
            )
        )
    return out


def levels_block(payload: bytes, levels: Sequence[TrialLevels]) -> bytes:
    """The optional block after the plan region (module docstring)."""
    body = [LEVELS_HEADER.pack(LEVELS_MAGIC, LEVELS_LAYOUT_VERSION, len(levels), plan_id(payload))]
    for lv in levels:
        body.append(LEVELS_TRIAL.pack(lv.status_code, lv.k, 0, *lv.levels, *lv.force_unit))
    data = b"".join(body)
    return data + LEVELS_CRC.pack(zlib.crc32(data) & 0xFFFFFFFF)


def encode_plan_file(
    begin: PlanBegin, trials: Sequence[PlanTrial], with_levels: bool
) -> tuple[bytes, list[TrialLevels]]:
    """(the file's bytes, the levels it holds). Every trial is solved either way, so a plan
    the board would refuse is refused here, at the desk."""
    payload = plan_payload(begin, trials)
    levels = solve_levels(begin, trials)
    data = plan_region(payload)
    if with_levels:
        data += levels_block(payload, levels)
    return data, levels


__all__ = [
    "LEVELS_HEADER",
    "LEVELS_MAGIC",
    "LEVELS_TRIAL",
    "PLAN_MAGIC",
    "PLAN_PREAMBLE",
    "PlanSolveError",
    "TrialLevels",
    "encode_plan_file",
    "fresh_store",
    "levels_text",
    "plan_file_for",
    "levels_block",
    "plan_id",
    "plan_payload",
    "plan_region",
    "solve_levels",
]


def plan_file_for(
    protocol_path: str,
    participant: str,
    with_levels: bool,
    rest_s: float,
    imu_to_hand_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    simulated: bool = False,
    calibration: MotorCalibration | None = None,
) -> tuple[bytes, list[PlanTrial], list[TrialLevels]]:
    """The plan file of ``participant`` in the protocol file, with the participant's
    ``calibration`` (the identity when None): the same plan ``graspguide device plan``
    uploads (graspguide.hostless.plan_upload)."""
    from graspguide.hostless.plan_upload import plan_messages, planned_trials
    from graspguide.protocol.study_protocol import load_protocol, participant_number

    protocol = load_protocol(protocol_path)
    participant_number(participant)
    trials = planned_trials(protocol, participant)
    begin, plan_trials = plan_messages(
        protocol, participant, trials, simulated, rest_s, imu_to_hand_wxyz, calibration
    )
    data, levels = encode_plan_file(begin, plan_trials, with_levels)
    return data, plan_trials, levels


# The C++ device's default store (GRASPGUIDE_STORE_BYTES) and the port's (store.py).
STORE_BYTES = 64 * 1024


def fresh_store(plan_file: bytes) -> bytes:
    """A new results store holding the plan: the plan region alone. The port's FileStore
    extends a shorter file to its size with 0xFF (erased) bytes, so the board starts with
    what a device's erased store holds after save_plan (this plan, an empty log), and the
    copy to the board is the plan's few KiB, not the whole 64 KiB."""
    length = PLAN_PREAMBLE.unpack_from(plan_file)[3]
    return plan_file[: PLAN_PREAMBLE.size + length]


def levels_text(trials: Sequence[PlanTrial], levels: Sequence[TrialLevels], plan: int) -> str:
    """The port's levels file (micropython/graspguide_mp/runner.py PrecomputedPostures):
    `plan_id XXXXXXXX` (the plan the levels belong to: the board ignores them under any
    other), then one line per trial, `trial_index status m1 .. mk`, the float32 levels
    written exactly (repr of the rounded value parses back to the same float32)."""
    lines = [
        "# trial_index status levels: precomputed by the C++ core (graspguide plan)",
        f"plan_id {plan:08x}",
    ]
    for t, lv in zip(trials, levels, strict=True):
        values = " ".join(repr(v) for v in lv.levels[: lv.k])
        lines.append(f"{t.trial_index} {lv.status} {values}")
    return "\n".join(lines) + "\n"
