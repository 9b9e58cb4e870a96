"""`graspguide calibrate`: a participant's per-finger perceptual calibration, a PWM floor
and a gain per thimble (graspguide.calibration.command)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import (
    add_port_arguments,
    int_arg,
    positive_float,
    signals_interrupt,
)

HELP = "measure a participant's per-finger PWM floor and gain (staircase + matching)"

DESCRIPTION = """\
Per-finger perceptual calibration (docs/calibration.md). For each finger of --fingers, a
detection threshold: the thimble buzzes for --stimulus-s at a PWM set by a 1-up-2-down
staircase (--rule 3: 1-up-3-down), with catch trials (no stimulus) mixed in; the
participant says whether they felt it. Then each other finger is matched to --reference:
the reference buzzes at --reference-pwm and the finger at a comparison PWM, in random
order, and the participant says which felt stronger (two interleaved 1-up-1-down
staircases, from above and below). The floor is the threshold (never below --min-floor,
the PWM where the motors start); the gain makes the finger's point of subjective equality
the duty the reference level maps to:
  gain_i = (PSE_i - floor_i) / (reference_pwm - floor_reference).

The operator types the participant's answers: y/n, 1/2; anything else is asked again; q
(or Ctrl-C) stops at once with the motors off and nothing written. --source participant
lets the virtual participant answer instead (a model, labelled SIMULATED in the output and
the file; its stimuli last 0.01 s, not real time). The result goes to
OUT/PID/calibration.json (the study folder of `graspguide trial --out`), with every trial,
the staircases' reversals and the false-alarm rate; an existing file is kept unless
--force. --apply also sends it to the device (SET_CALIBRATION)."""

EPILOG = """\
examples:
  graspguide calibrate --participant U1 --port /dev/ttyACM0 --out study --operator AB
  graspguide calibrate --participant U1 --port sim --source participant:seed=3 --out runs/sim
  graspguide calibrate --participant P07 --port /dev/ttyUSB0 --fingers thumb,index \\
      --reference index --rule 3 --apply --force

exit status: 0 calibrated and stored, 1 on a link or disk error or a finger that could not
be measured, 2 on a usage error (a bad option, an existing file without --force), 130 when
the operator quit (q), on Ctrl-C, SIGTERM or SIGHUP (motors off, nothing written)."""


def _catch_rate(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 <= v <= 0.5:
        raise argparse.ArgumentTypeError(f"must be in 0..0.5, got {text}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    from graspguide.calibration import session as s

    add_port_arguments(p, required=True)
    p.add_argument("--participant", required=True, metavar="PID", help="U1, U2, P07, ...")
    p.add_argument(
        "--out",
        default="study",
        metavar="DIR",
        help="study folder (default ./study, as `graspguide trial`); the file is "
        "DIR/PID/calibration.json",
    )
    p.add_argument(
        "--fingers",
        default=",".join(s.DEFAULT_FINGERS),
        metavar="LIST",
        help="fingers to calibrate, of thumb,index,middle,palm (default "
        f"{','.join(s.DEFAULT_FINGERS)}); the others keep floor 70, gain 1",
    )
    p.add_argument(
        "--reference",
        default=s.DEFAULT_REFERENCE,
        metavar="FINGER",
        help=f"the finger the others are matched to (gain 1; default {s.DEFAULT_REFERENCE})",
    )
    p.add_argument(
        "--source",
        default="operator",
        metavar="SOURCE",
        help="who answers: operator (default: the operator types a person's answers) or "
        "participant[:seed=N,false_alarm=P,lapse=P,weber=W] (the virtual participant, "
        "SIMULATED)",
    )
    p.add_argument(
        "--apply",
        action="store_true",
        help="also send the result to the device (SET_CALIBRATION)",
    )
    p.add_argument("--force", action="store_true", help="replace an existing calibration.json")
    p.add_argument(
        "--operator",
        default=None,
        metavar="NAME",
        help="who ran it, for the file (default: the login name)",
    )
    p.add_argument(
        "--stimulus-s",
        type=positive_float,
        default=s.DEFAULT_STIMULUS_S,
        metavar="S",
        help=f"how long each stimulus lasts (default {s.DEFAULT_STIMULUS_S:g})",
    )
    p.add_argument(
        "--gap-s",
        type=positive_float,
        default=s.DEFAULT_GAP_S,
        metavar="S",
        help=f"pause between the two stimuli of a matching pair (default {s.DEFAULT_GAP_S:g})",
    )
    p.add_argument(
        "--reference-pwm",
        type=int_arg(1, 255),
        default=s.DEFAULT_REFERENCE_PWM,
        metavar="PWM",
        help=f"the reference finger's level in matching (default {s.DEFAULT_REFERENCE_PWM}, "
        "the middle of the paper's 70..255)",
    )
    p.add_argument(
        "--min-floor",
        type=int_arg(0, 254),
        default=s.DEFAULT_MIN_FLOOR,
        metavar="PWM",
        help=f"the lowest floor: where the motors start turning (default "
        f"{s.DEFAULT_MIN_FLOOR}, the paper's motors)",
    )
    p.add_argument(
        "--rule",
        type=int_arg(2, 3),
        default=2,
        metavar="N",
        help="detection staircase 1-up-N-down: 2 tracks 70.7 %% detected (default), "
        "3 tracks 79.4 %%",
    )
    p.add_argument(
        "--reversals",
        type=int_arg(4, 40),
        default=12,
        metavar="N",
        help="detection reversals before a finger's staircase stops (default 12; the "
        "threshold averages the last N-4, at least 2)",
    )
    p.add_argument(
        "--catch-rate",
        type=_catch_rate,
        default=s.DEFAULT_CATCH_RATE,
        metavar="P",
        help=f"share of detection trials with no stimulus (default {s.DEFAULT_CATCH_RATE:g})",
    )
    p.add_argument(
        "--seed",
        type=int_arg(0, 2**31 - 1),
        default=None,
        metavar="N",
        help="seed of the trial order (catch trials, matching order); default: random "
        "(the virtual participant's seed when simulated); stored in the file",
    )
    p.add_argument(
        "--no-headroom",
        action="store_true",
        help="keep the matched gains as they are, even when a finger's strongest cue then "
        "passes PWM 255 and clips (default: every gain scaled by one factor so none does)",
    )


@signals_interrupt()  # SIGTERM and SIGHUP stop like Ctrl-C: motors off, nothing written
def run(args: argparse.Namespace) -> int:
    from graspguide.calibration.command import calibrate_command

    return calibrate_command(
        participant=args.participant,
        port=args.port,
        baud=args.baud,
        timeout=args.timeout,
        out=args.out,
        fingers=args.fingers,
        reference=args.reference,
        source=args.source,
        apply=args.apply,
        force=args.force,
        operator=args.operator,
        stimulus_s=args.stimulus_s,
        gap_s=args.gap_s,
        reference_pwm=args.reference_pwm,
        min_floor=args.min_floor,
        rule=args.rule,
        reversals=args.reversals,
        catch_rate=args.catch_rate,
        seed=args.seed,
        no_headroom=args.no_headroom,
    )
