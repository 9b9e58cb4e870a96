"""`graspguide stream`: one trial, poses from a source to a device
(graspguide.study.stream_session)."""

from __future__ import annotations

import argparse
import math
import sys

from graspguide.cli.common import add_port_arguments, fail, signals_interrupt
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE
from graspguide.link.sim import SIM_PORT
from graspguide.link.transport import LinkError

HELP = "run a trial: stream poses from a source to a device"

DESCRIPTION = """\
Run one trial on a device: HELLO, SET_SCENE (from --scene), START_TRIAL (--wrench), then
stream the poses of --source at the source's rate (real time; with --port sim
--virtual-clock as fast as the link allows, the device's clock following the poses'
times) while showing the guidance error, the motors' PWM, the rate and dropped frames.
Stops at the TRIAL_RESULT or at the end of the source, and always sends STOP on the way
out (also on Ctrl-C, SIGTERM, SIGHUP or an error).

sources: replay:FILE.csv (columns t_s,qw,qx,qy,qz[,thumb_x,...]; with --tracker the
         values are a tracker's raw export and are converted),
         synthetic[:rate=240,duration=10,seed=0] (a scripted hand that turns to align the
         scene's force with gravity),
         plugin:MODULE:CLASS[:ARG] (a live tracker: a graspguide.study.sources.TrackerAdapter
         subclass that reads the lab's tracker SDK)."""

EPILOG = """\
examples:
  graspguide stream --port sim --virtual-clock --scene tools/examples/scene_paper_3.toml \\
      --wrench 0.3,-1.2,-0.8 --source synthetic --log runs/s1
  graspguide stream --port /dev/ttyACM0 --scene my_scene.toml --wrench -1,0,-2 \\
      --source replay:poses.csv --trial-id 3

exit status: 0 when the trial ended (success or failure) or the source ended, 1 on a link
error, 2 on a usage error (bad scene, wrench or source), 130 on Ctrl-C, SIGTERM or SIGHUP
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
    add_port_arguments(p, required=True)
    p.add_argument(
        "--scene",
        required=True,
        metavar="SCENE.toml",
        help="scene file (tools/examples/scene_paper_3.toml shows the format)",
    )
    p.add_argument(
        "--wrench",
        required=True,
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
        help="replay:FILE.csv, synthetic[:rate=240,duration=10,seed=0] or "
        "plugin:MODULE:CLASS[:ARG]",
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


@signals_interrupt()  # SIGTERM and SIGHUP end the trial like Ctrl-C: STOP, end record
def run(args: argparse.Namespace) -> int:
    from graspguide.core.units import moment_unit_problem
    from graspguide.link.client import DeviceClient
    from graspguide.link.transport import open_port
    from graspguide.study.live_view import StatusView
    from graspguide.study.records import SessionLog
    from graspguide.study.scene_file import SceneError, config_hash, load_scene
    from graspguide.study.sources import SourceError, SyntheticSource, open_source
    from graspguide.study.stream_session import run_stream

    parser = args.command_parser
    if args.virtual_clock and args.port != SIM_PORT:
        parser.error("--virtual-clock is for --port sim (a board's clock is its own)")
    if not 0 <= args.trial_id <= 0xFFFF:
        parser.error(f"--trial-id must be in 0..65535, got {args.trial_id}")
    try:
        scene = load_scene(args.scene)
        problem = moment_unit_problem(scene.contacts, args.wrench)
        if problem:
            raise SceneError(f"--wrench with {args.scene}: {problem}")
        source = open_source(args.source, tracker=args.tracker)
        if isinstance(source, SyntheticSource):
            source.aim(scene.contacts, args.wrench, scene.policy, scene.constraints, scene.y_axis)
    except (SceneError, SourceError) as e:
        print(f"graspguide stream: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    kwargs = {"virtual_clock": True} if args.virtual_clock else {}
    try:
        transport = open_port(args.port, baudrate=args.baud, **kwargs)
    except LinkError as e:
        return fail("stream", e)
    client = DeviceClient(transport, timeout=args.timeout)
    log = view = None
    code = EXIT_OK
    summary = None
    stop_acked = False
    log_failed = False
    try:
        hello = client.hello()
        config = {"scene": scene.to_dict(), "wrench": args.wrench}
        config["config_hash"] = config_hash(config)
        config.update(
            source=source.describe(),
            source_spec=args.source,
            port=args.port,
            trial_id=args.trial_id,
            virtual_clock=args.virtual_clock,
            scene_file=args.scene,
        )
        if args.log:
            log = SessionLog(args.log)
            log.scene(scene.to_dict())
            log.device(hello)
            log.config(config)
        view = StatusView(scene.k)
        summary = run_stream(
            client, scene, args.wrench, source, args.trial_id, args.virtual_clock, log, view
        )
    except (LinkError, OSError) as e:  # OSError: the session log's disk (RecordWriteError)
        code = EXIT_FAILURE
        print(f"graspguide stream: error: {e}", file=sys.stderr)
        log_failed = isinstance(e, OSError) and not isinstance(e, LinkError)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        print("graspguide stream: interrupted", file=sys.stderr)
    finally:
        if view is not None:
            view.close()
        try:
            client.stop()
            stop_acked = True
        except LinkError as e:
            print(f"graspguide stream: STOP failed: {e}", file=sys.stderr)
            code = code or EXIT_FAILURE
        except KeyboardInterrupt:
            pass
        transport.close()
        if log is not None:
            end = {"event": "end", "exit_code": code, "stop_acknowledged": stop_acked}
            if summary is not None:
                end.update({k: v for k, v in summary.items() if k != "trial_result"})
            try:
                log.result(end)
                log.close()
            except OSError as e:  # the records before stay whole (session_log)
                if not log_failed:
                    print(f"graspguide stream: error: {e}", file=sys.stderr)
                code = code or EXIT_FAILURE
    if summary is not None:
        r = summary["trial_result"]
        if r is None:
            print(
                f"no trial result: the source ended first ({summary['sent']} poses sent, "
                f"last error {summary['last_error_deg']})"
            )
        else:
            print(
                f"trial {r.trial_id}: {'success' if r.success else 'failure'} "
                f"completion_s={r.completion_s:.3f} first_entry_s={r.first_entry_s:.3f} "
                f"final_error_deg={r.final_error_deg:.3f} ({summary['sent']} poses, "
                f"{summary['dropped']} dropped)"
            )
    return code
