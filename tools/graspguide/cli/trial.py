"""`graspguide trial`: one participant's trials of a study protocol
(graspguide.study.runner)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import (
    DEFAULT_REST_S,
    add_lsl_arguments,
    add_port_arguments,
    add_protocol_argument,
    quaternion_arg,
    rest_s_arg,
    signals_interrupt,
)

# Not imported from graspguide.study.runner, so `graspguide --help` stays fast; the
# runner's PERSON_REST_S (tools/tests/test_operator_runner.py checks they agree).
PERSON_REST_S = 5.0

HELP = "run a participant's trials of a study protocol (resumable; NASA-TLX after each session)"

DESCRIPTION = """\
Run one participant's trials of a study protocol (docs/study.md) on a device: the plan
(familiarization, then one session per contact count x modality, in the participant's
counterbalanced order) is derived from --protocol and --participant; each trial is
SET_SCENE (when the condition changes), START_TRIAL, poses streamed from --source until
the TRIAL_RESULT. During each trial the panel of `graspguide stream`: trial n of N and
the condition, the state, the error against the threshold, the hold progress, each
finger's cue level, SIMULATED when the run is (plain lines when stdout is not a
terminal). After each session the six NASA-TLX scales (MD, TD, PD, PE, EF, FR; integers
1-21) are asked on stdin -- on the operator's terminal they are then shown for review and
saved once confirmed (Enter; a scale's name or r asks again); answers piped in are saved
as given -- or read from --tlx, or -- for a simulated source without --tlx -- recorded as
absent (null), never invented.

Writes OUT/study.json, OUT/PID/trials.jsonl (one fsync'ed line per completed trial),
OUT/PID/tlx.jsonl, OUT/PID/frames/trial-NNNN.csv, OUT/PID/plan.json, OUT/PID/runs.jsonl.
Run the same command again after a crash or Ctrl-C: completed trials are skipped, none
is lost or repeated. STOP is sent on every way out.

sources: participant[:PARAMS] (the virtual participant, closed loop), synthetic[:...] and
         replay:FILE.csv or FILE.xdf (open loop; each trial replays the file from its
         start, and its last pose is held until the device ends the trial),
         plugin:MODULE:CLASS[:ARG] (a sources.TrackerAdapter -- a live tracker, a
         person -- or a closed-loop class with begin_trial/step),
         lsl:name=NAME[,...] or natnet:server=IP,body=NAME[,...] (a live LSL MoCap
         stream or Motive's NatNet stream, a person, in real time: the stream runs on
         between trials and each trial takes its samples from its START on; a
         gap in the tracking -- a stall, a lost marker -- sends no POSE, so the device's
         watchdog turns the motors off, and is said on stderr, not taken for a link
         fault; a stream silent for its end= time ends the run, that trial unrecorded
         (run the same command again to resume);
         docs/lab-streams.md, "LSL MoCap source"; docs/trackers.md for NatNet).
With --port sim the simulated device runs on its virtual clock for simulated sources (a
90 s trial takes about a second).

--hostless (with --port sim and a simulated closed-loop source): the study runs on the
simulated device with no host: the plan is uploaded and stored in the device's store
(--store, default OUT/PID/device-store.bin), the device runs each trial after a rest
(--rest-s) and a button press, from the IMU samples of a simulated hand that the virtual
participant moves; the device's log is then downloaded into OUT (docs/hostless.md).
SIMULATED, like every simulated source. Run again to resume: the device skips the trials
it has records of.

With a person (a source that is not SIMULATED, e.g. a tracker plugin, or --operator) and
a terminal: a ready prompt before each trial (Enter starts it), a rest between trials
(--rest-s, default 5 s; 0 for a simulated source), the estimated time left, and the
operator's keys: p pause (STOP; Enter restarts the trial from scratch), r redo and s skip
(each with a typed reason), n a note -- all logged in OUT/PID/events.jsonl. A skipped
trial is not run again on resume and is not a failure for the analysis.
--dry-run walks the plan without a device (no --port, no --source): each session and
trial, the NASA-TLX with its anchors, the best and worst total time. Writes nothing.

--lsl [NAME] publishes the run as two Lab Streaming Layer streams, NAME-Telemetry (error,
alpha, PWM per finger, status per TELEMETRY) and NAME-Markers (session_start, trial_start,
trial_end, pause, redo, skip, note, study_end), for LabRecorder (docs/lab-streams.md).
--record FILE.xdf records the run's poses as sent (MoCap), its TELEMETRY and its markers
in one XDF file, on a session clock (a trial's start offset plus its t_s, since t_s
restarts every trial); docs/lab-streams.md, "Recording and replaying as XDF".

A stored calibration, OUT/PID/calibration.json (graspguide calibrate), is sent to the device
before the first trial (each motor's PWM floor and gain, docs/calibration.md); without one
the device gets the paper's mapping.

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
  graspguide trial --protocol protocols/paper.toml --participant U3 --port /dev/ttyACM0 \\
      --source lsl:name=Hand --out runs/study --tlx u3_tlx.jsonl --record runs/u3.xdf
  graspguide trial --protocol protocols/paper.toml --participant U3 --dry-run --rest-s 10

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
    add_port_arguments(p, required=False)
    p.add_argument(
        "--source",
        metavar="SOURCE",
        help="participant[:PARAMS], synthetic[:...], replay:FILE.csv, replay:FILE.xdf"
        "[#name=STREAM], lsl:name=NAME[,...], natnet:server=IP,body=NAME[,...] or "
        "plugin:MODULE:CLASS[:ARG] "
        "(required unless --dry-run)",
    )
    p.add_argument(
        "--record",
        metavar="FILE.xdf",
        default=None,
        help="record the run as an XDF file (LabRecorder's format): the poses sent (MoCap), "
        "the TELEMETRY and the markers, on a session clock (a trial's start offset plus "
        "its t_s); an existing file is never overwritten",
    )
    p.add_argument(
        "--operator",
        action="store_true",
        help="the ready prompt, rest and operator keys even for a simulated source "
        "(needs a terminal)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print the plan, the NASA-TLX points and the time estimate; no device, "
        "nothing written",
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
        help=f"rest between trials, seconds (default: {DEFAULT_REST_S:g} with --hostless, "
        f"{PERSON_REST_S:g} with a person, 0 for a simulated source)",
    )
    p.add_argument(
        "--imu-to-hand",
        type=quaternion_arg,
        default=None,
        metavar="W,X,Y,Z",
        help="with --hostless: how the simulated IMU sits on the hand, the rotation from its "
        "axes to the hand's (default 1,0,0,0); declared in the plan and used by the world",
    )

    add_lsl_arguments(p)


@signals_interrupt()  # SIGTERM and SIGHUP end the run like Ctrl-C: STOP; trials are kept
def run(args: argparse.Namespace) -> int:
    from graspguide.exit_codes import EXIT_USAGE, report

    if args.dry_run:
        if args.hostless or args.operator or args.record is not None:
            report("trial", "--dry-run goes without --hostless, --operator and --record")
            return EXIT_USAGE
        from graspguide.study.dry_run import dry_run_command

        return dry_run_command(
            protocol=args.protocol, participant=args.participant, rest_s=args.rest_s
        )
    missing = [o for o, v in (("--port", args.port), ("--source", args.source)) if v is None]
    if missing:
        report("trial", f"{' and '.join(missing)} required (or --dry-run to walk the plan)")
        return EXIT_USAGE
    if args.hostless and args.operator:
        report("trial", "--operator goes without --hostless (the device runs those trials)")
        return EXIT_USAGE
    if args.hostless and args.record is not None:
        report(
            "trial",
            "--record goes without --hostless (a host-less device sends nothing during its "
            "trials; its records are downloaded into OUT)",
        )
        return EXIT_USAGE
    if args.hostless and args.lsl is not None:
        report(
            "trial",
            "--lsl goes without --hostless (a host-less device streams nothing during its "
            "trials; its records are read afterwards)",
        )
        return EXIT_USAGE
    if args.hostless:
        from graspguide.hostless.runner import hostless_trial_command

        return hostless_trial_command(
            protocol=args.protocol,
            participant=args.participant,
            source=args.source,
            port=args.port,
            baud=args.baud,
            timeout=args.timeout,
            out=args.out,
            store=args.store,
            rest_s=DEFAULT_REST_S if args.rest_s is None else args.rest_s,
            imu_to_hand=args.imu_to_hand,
            tlx=args.tlx,
        )
    if args.store is not None or args.imu_to_hand is not None:
        report("trial", "--store and --imu-to-hand go with --hostless only")
        return EXIT_USAGE
    from graspguide.study.runner import trial_command

    return trial_command(
        protocol=args.protocol,
        participant=args.participant,
        source=args.source,
        port=args.port,
        baud=args.baud,
        timeout=args.timeout,
        out=args.out,
        tlx=args.tlx,
        rest_s=args.rest_s,
        operator=args.operator,
        lsl=args.lsl,
        lsl_wait=args.lsl_wait,
        record=args.record,
    )
