"""`graspguide stream`: one trial, poses from a source to a device
(graspguide.study.stream_session)."""

from __future__ import annotations

import argparse
import math

from graspguide.cli.common import (
    add_lsl_arguments,
    add_port_arguments,
    signals_interrupt,
)
from graspguide.devices.sim import SIM_PORT

HELP = "run a trial: stream poses from a source to a device"

DESCRIPTION = """\
Run one trial on a device: HELLO, SET_SCENE (from --scene), START_TRIAL (--wrench), then
stream the poses of --source at the source's rate (real time; with --port sim
--virtual-clock as fast as the link allows, the device's clock following the poses'
times) while showing the guidance error, the motors' PWM, the rate achieved and dropped
frames. One POSE is in flight at a time: a source faster than the link carries is paced
to it (each POSE sent is the newest pose, the older ones are skipped, not queued), said
once on stderr with the link's figures (baud rate, frame sizes).
Stops at the TRIAL_RESULT or at the end of the source, and always sends STOP on the way
out (also on Ctrl-C, SIGTERM, SIGHUP or an error).

sources: replay:FILE.csv (columns t_s,qw,qx,qy,qz[,thumb_x,...]; with --tracker the
         values are a tracker's raw export and are converted; a --log session's
         poses.csv, or its folder as replay:DIR, replays the poses it sent),
         synthetic[:rate=240,duration=10,seed=0] (a scripted hand that turns to align the
         scene's force with gravity),
         plugin:MODULE:CLASS[:ARG] (a live tracker: a graspguide.sources.poses.TrackerAdapter
         subclass that reads the lab's tracker SDK),
         participant[:seed=N,PARAMS] (the virtual participant as a closed loop: it feels
         the motors and turns the hand, as in `graspguide trial`),
         lsl:name=NAME[,type=MoCap,body=Hand,markers=Thumb;Index;Middle,hold=0.2,
         tol_mm=2.0,...] (a live LSL MoCap stream: the hand's rigid body and fingertip
         markers; `--source lsl --list` lists the streams seen; docs/lab-streams.md).
A run is SIMULATED -- said at the start, on the result line, in the panel, the log and
the LSL streams, by the rule `graspguide trial` follows -- when its source is (the
participant, synthetic, a replayed file) or its device is (--port sim, promini-sim, qemu).

The panel names the motors after the fingers (thumb, index, middle, palm) and shows the
trial's state (waiting, running, holding, success, timeout, stopped) and the hold
progress against the scene's threshold ("below 3.0 deg for 0.31/0.50 s"); plain lines
when the output is not a terminal. The last panel (or line) comes after STOP: the final
state (stopped on Ctrl-C) and what the device answered of the motors ("motors off (STOP
acknowledged, device stopped)").

--lsl publishes two Lab Streaming Layer streams, NAME-Telemetry (error_deg, alpha,
pwm_thumb..pwm_palm, status, trial_time_s per TELEMETRY) and NAME-Markers (JSON strings:
session_start, trial_start, trial_end, study_end), for LabRecorder; docs/lab-streams.md
describes them and lsl_api.cfg."""

EPILOG = """\
examples:
  graspguide stream --port sim --virtual-clock --scene tools/examples/scene_paper_3.toml \\
      --wrench 0.3,-1.2,-0.8 --source synthetic --log runs/s1
  graspguide stream --port /dev/ttyACM0 --scene my_scene.toml --wrench -1,0,-2 \\
      --source replay:poses.csv --trial-id 3
  graspguide stream --port sim --scene tools/examples/scene_paper_3.toml \\
      --wrench 0.3,-1.2,-0.8 --source participant:seed=2 --lsl GraspGuide --lsl-wait 30

exit status: 0 when the trial ended (success or failure) or the source ended, 1 on a link
error or when LSL cannot be used (liblsl missing, no network interface), 2 on a usage
error (bad scene, wrench, source or --lsl name), 130 on Ctrl-C, SIGTERM or SIGHUP
(STOP is sent and the log's end record written first)."""


def wrench_arg(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--wrench must be fx,fy,fz or fx,fy,fz,mx,my,mz (numbers), got {text!r}"
        ) from None
    if len(values) not in (3, 6) or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(
            f"--wrench must be 3 or 6 finite numbers (fx,fy,fz[,mx,my,mz]), got {text!r}"
        )
    return values + [0.0] * (6 - len(values))


def add_arguments(p: argparse.ArgumentParser) -> None:
    # --port, --scene and --wrench are required but for --list: run() checks them
    add_port_arguments(p, required=False)
    p.add_argument(
        "--scene",
        metavar="SCENE.toml",
        help="scene file (tools/examples/scene_paper_3.toml shows the format)",
    )
    p.add_argument(
        "--wrench",
        type=wrench_arg,
        metavar="FX,FY,FZ[,MX,MY,MZ]",
        help="the virtual object's wrench in the object frame: force in N, "
        "moment about the contacts' centroid in N m; negative values as "
        "they are: --wrench -1,0,0 (a moment of more than 10 hand spans "
        "times the force is refused: it looks like N mm)",
    )
    p.add_argument(
        "--source",
        required=True,
        metavar="SOURCE",
        help="replay:FILE.csv, replay:FILE.xdf[#name=STREAM], "
        "synthetic[:rate=240,duration=10,seed=0], "
        "plugin:MODULE:CLASS[:ARG] or participant[:seed=N,PARAMS] (SIMULATED)",
    )
    p.add_argument(
        "--tracker",
        metavar="NAME",
        default=None,
        help="the replay file is a raw tracker export in this convention: "
        "vicon, optitrack, leap, world, or UNITS/UP/HANDEDNESS/ORDER such "
        "as mm/y/right/xyzw (default: already in this project's world)",
    )
    p.add_argument(
        "--log",
        metavar="DIR",
        default=None,
        help="write the session folder DIR (scene.json, device.json, "
        "config.json, poses.csv, telemetry.csv, results.jsonl)",
    )
    p.add_argument(
        "--record",
        metavar="FILE.xdf",
        default=None,
        help="record the run as an XDF file (LabRecorder's format): the poses sent "
        "(MoCap), the TELEMETRY and the markers, on the poses' trial time; replay it "
        "with --source replay:FILE.xdf (docs/lab-streams.md). An existing file is "
        "never overwritten",
    )
    p.add_argument(
        "--trial-id",
        type=int,
        default=1,
        metavar="N",
        help="START_TRIAL trial id, 0..65535 (default 1)",
    )
    p.add_argument(
        "--virtual-clock",
        action="store_true",
        help="with --port sim: the device's clock follows the poses' times, so "
        "the trial runs as fast as possible",
    )
    p.add_argument(
        "--list",
        action="store_true",
        help="with --source lsl[:wait=S]: list the LSL streams seen within S seconds "
        "(default 2): name, type, source_id, channels, rate, host; then exit",
    )
    add_lsl_arguments(p)


def list_streams(parser: argparse.ArgumentParser, source: str) -> int:
    """`stream --source lsl --list`: the LSL streams seen, one line each."""
    from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, report
    from graspguide.sources.lsl_inlet import list_lsl_streams, parse_spec, stream_table
    from graspguide.sources.poses import SourceError

    kind, _, rest = source.partition(":")
    if kind != "lsl":
        parser.error(f"--list is for --source lsl (lists the LSL streams), not {kind!r}")
    try:
        wait = parse_spec(rest).wait_s if "wait=" in rest else 2.0
        rows = list_lsl_streams(wait)
    except SourceError as e:
        report("stream", e)
        return EXIT_FAILURE
    if not rows:
        print(f"no LSL stream seen within {wait:g} s (docs/lab-streams.md: lsl_api.cfg)")
        return EXIT_OK
    print(stream_table(rows))
    return EXIT_OK


@signals_interrupt()  # SIGTERM and SIGHUP end the trial like Ctrl-C: STOP, end record
def run(args: argparse.Namespace) -> int:
    from graspguide.study.stream_session import stream_command

    parser = args.command_parser
    if args.list:
        return list_streams(parser, args.source)
    missing = [
        flag
        for flag, value in (
            ("--port/-p", args.port),
            ("--scene", args.scene),
            ("--wrench", args.wrench),
        )
        if value is None
    ]
    if missing:
        parser.error(f"the following arguments are required: {', '.join(missing)}")
    if args.virtual_clock and args.port != SIM_PORT:
        parser.error("--virtual-clock is for --port sim (a board's clock is its own)")
    if args.lsl_wait and args.lsl is None:
        parser.error("--lsl-wait is for --lsl (add --lsl [NAME])")
    if not 0 <= args.trial_id <= 0xFFFF:
        parser.error(f"--trial-id must be in 0..65535, got {args.trial_id}")
    return stream_command(
        scene=args.scene,
        wrench=args.wrench,
        source=args.source,
        tracker=args.tracker,
        port=args.port,
        baud=args.baud,
        timeout=args.timeout,
        log=args.log,
        trial_id=args.trial_id,
        virtual_clock=args.virtual_clock,
        lsl=args.lsl,
        lsl_wait=args.lsl_wait,
        record=args.record,
    )
