"""The NASA-TLX questionnaire after each session: its six scales, asked on a terminal or
read from a --tlx file, checked against the participant's plan."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any, TextIO

from graspguide.protocol.study_protocol import Session
from graspguide.run_errors import RunnerError

TLX_SCALES = ("MD", "TD", "PD", "PE", "EF", "FR")
TLX_NAMES = {
    "MD": "Mental Demand",
    "TD": "Temporal Demand",
    "PD": "Physical Demand",
    "PE": "Performance",
    "EF": "Effort",
    "FR": "Frustration",
}
TLX_MIN, TLX_MAX = 1, 21
# Each scale's question and the words at its two ends (NASA Task Load Index manual; Hart
# & Staveland 1988): Performance runs the other way, 1 = perfect .. 21 = failure.
TLX_QUESTIONS = {
    "MD": "How mentally demanding was the task?",
    "TD": "How hurried or rushed was the pace of the task?",
    "PD": "How physically demanding was the task?",
    "PE": "How successful were you in accomplishing what you were asked to do?",
    "EF": "How hard did you have to work to accomplish your level of performance?",
    "FR": "How insecure, discouraged, irritated, stressed, and annoyed were you?",
}
TLX_ANCHORS = {sc: ("very low", "very high") for sc in TLX_SCALES}
TLX_ANCHORS["PE"] = ("perfect", "failure")


def tlx_scale_text(scale: str) -> str:
    """One scale as the participant sees it: name, question, the two anchors."""
    low, high = TLX_ANCHORS[scale]
    return (
        f"{scale} ({TLX_NAMES[scale]}): {TLX_QUESTIONS[scale]}  "
        f"{TLX_MIN} = {low} .. {TLX_MAX} = {high}"
    )


def check_tlx_value(scale: str, value: Any) -> int:
    """An integer 1..21, else ValueError saying what is wrong."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(
            f"{scale} ({TLX_NAMES[scale]}) must be an integer {TLX_MIN}..{TLX_MAX}, got {value!r}"
        )
    if not TLX_MIN <= value <= TLX_MAX:
        raise ValueError(
            f"{scale} ({TLX_NAMES[scale]}) must be in {TLX_MIN}..{TLX_MAX}, got {value}"
        )
    return int(value)


def load_tlx_file(
    path: str, participant: str, sessions: Sequence[Session]
) -> dict[int, dict[str, int]]:
    """``--tlx FILE``: JSON Lines, one object per session: ``{"session": 1, "MD": 5,
    "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}``, optionally ``"participant"``,
    ``"modality"`` and ``"k"`` (checked against the plan when present). Blank lines are
    skipped. Returns session -> scales; RunnerError (usage) naming the line otherwise."""
    by_session = {s.session: s for s in sessions}
    out: dict[int, dict[str, int]] = {}
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise RunnerError(f"--tlx {path}: cannot read it: {e.strerror}", usage=True) from None
    except UnicodeDecodeError:
        raise RunnerError(f"--tlx {path}: not UTF-8 text", usage=True) from None
    allowed = set(TLX_SCALES) | {"session", "participant", "modality", "k"}
    for no, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        where = f"--tlx {path}:{no}"
        try:
            obj = json.loads(line)
        except ValueError as e:
            raise RunnerError(
                f"{where}: not JSON ({e}); one object per line such as "
                '{"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, '
                '"FR": 3}',
                usage=True,
            ) from None
        if not isinstance(obj, dict):
            raise RunnerError(f"{where}: must be a JSON object", usage=True)
        unknown = sorted(set(obj) - allowed)
        if unknown:
            raise RunnerError(
                f"{where}: unknown key {unknown[0]!r}; keys: session, "
                f"{', '.join(TLX_SCALES)} (and optionally participant, "
                "modality, k)",
                usage=True,
            )
        s = obj.get("session")
        if isinstance(s, bool) or not isinstance(s, int) or s not in by_session:
            raise RunnerError(
                f"{where}: session must be one of this participant's sessions "
                f"1..{len(sessions)}, got {s!r}",
                usage=True,
            )
        if s in out:
            raise RunnerError(f"{where}: session {s} is given twice", usage=True)
        if "participant" in obj and obj["participant"] != participant:
            raise RunnerError(
                f"{where}: participant {obj['participant']!r} is not "
                f"{participant!r}: is this the right file?",
                usage=True,
            )
        sess = by_session[s]
        if "modality" in obj and obj["modality"] != sess.modality:
            raise RunnerError(
                f"{where}: session {s} of {participant} is {sess.modality}, "
                f"the file says {obj['modality']!r}",
                usage=True,
            )
        if "k" in obj and obj["k"] != sess.k:
            raise RunnerError(
                f"{where}: session {s} of {participant} has k = {sess.k}, the "
                f"file says {obj['k']!r}",
                usage=True,
            )
        missing = [sc for sc in TLX_SCALES if sc not in obj]
        if missing:
            raise RunnerError(
                f"{where}: missing {', '.join(missing)} (the six scales "
                f"{', '.join(TLX_SCALES)}, integers {TLX_MIN}..{TLX_MAX})",
                usage=True,
            )
        scales = {}
        for sc in TLX_SCALES:
            try:
                scales[sc] = check_tlx_value(sc, obj[sc])
            except ValueError as e:
                raise RunnerError(f"{where}: {e}", usage=True) from None
        out[s] = scales
    return out


def _ask(ask: Callable[[str], str], prompt: str) -> str:
    try:
        return ask(prompt).strip()
    except EOFError:
        raise RunnerError(
            "the NASA-TLX answers ended (stdin closed); give them with "
            "--tlx FILE and run again (completed trials are kept)"
        ) from None


def _ask_scale(sc: str, ask: Callable[[str], str], out: TextIO, attempts: int) -> int:
    """One scale, asked until the answer is an integer 1..21 (at most ``attempts``)."""
    for _ in range(attempts):
        text = _ask(ask, f"  {sc} ({TLX_NAMES[sc]}) [{TLX_MIN}-{TLX_MAX}]: ")
        try:
            return check_tlx_value(sc, int(text))
        except ValueError as e:
            msg = (
                str(e)
                if text.lstrip("+-").isdigit()
                else f"{sc}: {text!r} is not an integer {TLX_MIN}..{TLX_MAX}"
            )
            print(f"  {msg}; try again", file=out, flush=True)
    raise RunnerError(f"no valid answer for {sc} after {attempts} attempts")


def tlx_answers_text(scales: dict[str, int]) -> str:
    """``MD 5   TD 3   PD 2   PE 4   EF 6   FR 3``: the answers at a glance."""
    return "   ".join(f"{sc} {scales[sc]}" for sc in TLX_SCALES)


REVIEW_PROMPT = (
    "  save these answers? Enter saves; a scale's name (such as MD) asks it again; "
    "r asks all six again: "
)


def ask_tlx(
    session: Session,
    ask: Callable[[str], str],
    out: TextIO,
    attempts: int = 5,
    review: bool = False,
) -> dict[str, int]:
    """The six scales asked one by one (``ask`` is input()); a bad answer is asked again
    (at most ``attempts`` times); EOF raises RunnerError. With ``review`` (someone at a
    terminal) the answers are then shown and saved only once confirmed: a scale's name
    asks it again, ``r`` all six; without it (answers piped in) they are returned as
    given."""
    print(
        f"NASA-TLX for session {session.session} ({session.modality}, k = {session.k}): "
        f"answer each scale with an integer {TLX_MIN}..{TLX_MAX}",
        file=out,
        flush=True,
    )
    scales: dict[str, int] = {}
    todo = list(TLX_SCALES)
    while True:
        for sc in todo:
            print(f"  {tlx_scale_text(sc)}", file=out, flush=True)
            scales[sc] = _ask_scale(sc, ask, out, attempts)
        if not review:
            return scales
        print(f"  answers: {tlx_answers_text(scales)}", file=out, flush=True)
        for _ in range(attempts):
            text = _ask(ask, REVIEW_PROMPT)
            if text.lower() in ("", "y", "yes"):
                return scales
            if text.lower() == "r":
                todo = list(TLX_SCALES)
                break
            if text.upper() in TLX_SCALES:
                todo = [text.upper()]
                break
            print(
                f"  {text!r}: press Enter to save, type a scale ({', '.join(TLX_SCALES)}) "
                "to answer it again, or r for all six",
                file=out,
                flush=True,
            )
        else:
            raise RunnerError(f"the NASA-TLX answers were not confirmed after {attempts} tries")


__all__ = [
    "TLX_SCALES",
    "TLX_NAMES",
    "TLX_MIN",
    "TLX_MAX",
    "TLX_ANCHORS",
    "TLX_QUESTIONS",
    "tlx_scale_text",
    "check_tlx_value",
    "load_tlx_file",
    "ask_tlx",
    "tlx_answers_text",
]
