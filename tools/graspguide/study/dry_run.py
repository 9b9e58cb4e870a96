"""`graspguide trial --dry-run`: a participant's plan walked without a device -- each
session and trial as it would run, where the NASA-TLX is asked, and how long it takes at
best and at worst. Nothing is written (the plan is printed; OUT is not touched)."""

from __future__ import annotations

from collections.abc import Sequence

from graspguide.protocol.study_protocol import (
    PlannedTrial,
    Protocol,
    draw_familiarization_wrenches,
    draw_wrenches,
    plan,
    session_order,
)
from graspguide.protocol.tlx import TLX_SCALES, tlx_scale_text
from graspguide.study.progress import format_duration


def estimate_s(
    protocol: Protocol, trials: Sequence[PlannedTrial], rest_s: float
) -> tuple[float, float]:
    """(best, worst) seconds for ``trials``: every trial ending as soon as it can (a
    success needs the error held under the threshold for hold_s) or at its timeout, and
    a rest between two trials. The NASA-TLX and the operator's pauses are not counted."""
    n = len(trials)
    rests = max(0, n - 1) * rest_s
    return n * protocol.hold_s + rests, n * protocol.timeout_s + rests


def dry_run_lines(protocol: Protocol, participant: str, rest_s: float) -> list[str]:
    """What the dry run prints."""
    trials = plan(
        protocol, participant, draw_wrenches(protocol), draw_familiarization_wrenches(protocol)
    )
    sessions = {s.session: s for s in session_order(protocol, participant)}
    out = [
        f"dry run of {participant}: {len(trials)} trials, {len(sessions)} sessions, "
        f"timeout {protocol.timeout_s:g} s, hold {protocol.hold_s:g} s, "
        f"threshold {protocol.threshold_deg:g} deg, rest {rest_s:g} s between trials "
        "(no device; nothing written)"
    ]
    by_session: dict[int, list[PlannedTrial]] = {}
    for t in trials:
        by_session.setdefault(t.session, []).append(t)
    for sess_no in sorted(by_session):
        rows = by_session[sess_no]
        if sess_no == 0:
            out.append(f"familiarization: {len(rows)} trials")
        else:
            s = sessions[sess_no]
            out.append(
                f"session {sess_no}/{len(sessions)}: {s.modality} k={s.k}, {len(rows)} trials"
            )
        for t in rows:
            out.append(
                f"  trial {t.trial_index}/{len(trials)}: {t.modality} k={t.k} {t.wrench_id} "
                f"({t.wrench_class or 'F'}{', single motor' if t.single_motor else ''})"
            )
        if sess_no >= 1:
            out.append(f"  NASA-TLX for session {sess_no}: {', '.join(TLX_SCALES)}")
            out.extend(f"    {tlx_scale_text(sc)}" for sc in TLX_SCALES)
    best, worst = estimate_s(protocol, trials, rest_s)
    out.append(
        f"estimated time: best {best:.0f} s ({format_duration(best)}), worst {worst:.0f} s "
        f"({format_duration(worst)}), without the NASA-TLX and pauses"
    )
    return out


def dry_run_command(*, protocol: str, participant: str, rest_s: float | None) -> int:
    """Print the dry run; the exit code (2 for a bad protocol or participant)."""
    from graspguide.exit_codes import EXIT_OK, EXIT_USAGE, report
    from graspguide.protocol.study_protocol import (
        ProtocolFileError,
        load_protocol,
        participant_number,
    )
    from graspguide.study.runner import PERSON_REST_S

    try:
        loaded = load_protocol(protocol)
        participant_number(participant)
    except ProtocolFileError as e:
        report("trial", e)
        return EXIT_USAGE
    for line in dry_run_lines(loaded, participant, PERSON_REST_S if rest_s is None else rest_s):
        print(line)
    return EXIT_OK


__all__ = ["estimate_s", "dry_run_lines", "dry_run_command"]
