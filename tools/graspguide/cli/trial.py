"""`graspguide trial`: one participant's trials of a study protocol
(graspguide.study.runner)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import (
    DEFAULT_REST_S,
    add_port_arguments,
    add_protocol_argument,
    call_with_options,
    quaternion_arg,
    rest_s_arg,
    signals_interrupt,
)

HELP = "run a participant's trials of a study protocol (resumable; NASA-TLX after each session)"

DESCRIPTION = """\
Run one participant's trials of a study protocol (docs/study.md) on a device: the plan
(familiarization, then one session per contact count x modality, in the participant's
counterbalanced order) is derived from --protocol and --participant; each trial is
SET_SCENE (when the condition changes), START_TRIAL, poses streamed from --source until
the TRIAL_RESULT. Progress: trial n of N, the condition and the live error (plain lines
when stdout is not a terminal). After each session the six NASA-TLX scales (MD, TD, PD,
PE, EF, FR; integers 1-21) are asked on stdin, or read from --tlx, or -- for a simulated
source without --tlx -- recorded as absent (null), never invented.

Writes OUT/study.json, OUT/PID/trials.jsonl (one fsync'ed line per completed trial),
OUT/PID/tlx.jsonl, OUT/PID/frames/trial-NNNN.csv, OUT/PID/plan.json, OUT/PID/runs.jsonl.
Run the same command again after a crash or Ctrl-C: completed trials are skipped, none
is lost or repeated. STOP is sent on every way out.

sources: participant[:PARAMS] (the virtual participant, closed loop), synthetic[:...] and
         replay:FILE.csv (open loop; the last pose is held until the device ends the
         trial), plugin:MODULE:CLASS[:ARG] (a sources.TrackerAdapter -- a live tracker, a
         person -- or a closed-loop class with begin_trial/step).
With --port sim the simulated device runs on its virtual clock for simulated sources (a
90 s trial takes about a second).

--hostless (with --port sim and a simulated closed-loop source): the study runs on the
simulated device with no host: the plan is uploaded and stored in the device's store
(--store, default OUT/PID/device-store.bin), the device runs each trial after a rest
(--rest-s) and a button press, from the IMU samples of a simulated hand that the virtual
participant moves; the device's log is then downloaded into OUT (docs/hostless.md).
SIMULATED, like every simulated source. Run again to resume: the device skips the trials
it has records of.

--tlx FILE: JSON Lines, one object per session, e.g.
  {"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}
  (optional "participant", "modality", "k" are checked against the plan)."""

EPILOG = """\
examples:
  graspguide trial --protocol protocols/paper.toml --participant U1 --port sim \\
      --source participant --out runs/pilot
  graspguide trial --protocol protocols/paper.toml --participant U1 --port sim \\
      --source participant --hostless --out runs/hostless
  graspguide trial --protocol protocols/paper.toml --participant U3 --port /dev/ttyACM0 \\
      --source plugin:my_lab.vicon:ViconHand --out runs/study --tlx u3_tlx.jsonl

exit status: 0 when every trial and questionnaire is done, 1 on a link or run error, 2 on
a usage error (bad protocol, participant, source or TLX file), 130 on Ctrl-C (run the
same command again to resume)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_protocol_argument(p, required=True)
    p.add_argument(
        "--participant",
        required=True,
        metavar="PID",
        help="participant id ending in a number (U1, U2, ...): picks the counterbalanced order",
    )
    add_port_arguments(p, required=True)
    p.add_argument(
        "--source",
        required=True,
        metavar="SOURCE",
        help="participant[:PARAMS], synthetic[:...], replay:FILE.csv or plugin:MODULE:CLASS[:ARG]",
    )
    p.add_argument(
        "--out",
        default="study",
        metavar="DIR",
        help="study folder (default ./study); the participant's files go to DIR/PID/",
    )
    p.add_argument(
        "--tlx",
        metavar="FILE",
        default=None,
        help="NASA-TLX answers, JSON Lines, one object per session (see above)",
    )
    p.add_argument(
        "--hostless",
        action="store_true",
        help="run the study host-less on the simulated device (--port sim): plan stored on "
        "the device, trials started by a simulated button, the hand seen through a "
        "simulated IMU; the device's log downloaded into OUT",
    )
    p.add_argument(
        "--store",
        metavar="FILE",
        default=None,
        help="with --hostless: the simulated device's non-volatile store, kept across runs "
        "(default OUT/PID/device-store.bin)",
    )
    p.add_argument(
        "--rest-s",
        type=rest_s_arg,
        default=None,
        metavar="S",
        help=f"with --hostless: rest before each trial's ready pattern, seconds "
        f"(default {DEFAULT_REST_S:g})",
    )
    p.add_argument(
        "--imu-to-hand",
        type=quaternion_arg,
        default=None,
        metavar="W,X,Y,Z",
        help="with --hostless: how the simulated IMU sits on the hand, the rotation from its "
        "axes to the hand's (default 1,0,0,0); declared in the plan and used by the world",
    )


@signals_interrupt()  # SIGTERM and SIGHUP end the run like Ctrl-C: STOP; trials are kept
def run(args: argparse.Namespace) -> int:
    if args.hostless:
        from graspguide.hostless.runner import hostless_trial_command

        if args.rest_s is None:
            args.rest_s = DEFAULT_REST_S
        return call_with_options(hostless_trial_command, args)
    if args.store is not None or args.rest_s is not None or args.imu_to_hand is not None:
        from graspguide.exit_codes import EXIT_USAGE, report

        report("trial", "--store, --rest-s and --imu-to-hand go with --hostless only")
        return EXIT_USAGE
    from graspguide.study.runner import trial_command

    return call_with_options(trial_command, args)
