"""`graspguide trial`: one participant's trials of a study protocol
(graspguide.study.runner)."""

from __future__ import annotations

import argparse
import os
import sys

from graspguide.cli.common import add_port_arguments, fail, signals_interrupt
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE
from graspguide.link.sim import SIM_PORT
from graspguide.link.transport import LinkError

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

--tlx FILE: JSON Lines, one object per session, e.g.
  {"session": 1, "MD": 5, "TD": 3, "PD": 2, "PE": 4, "EF": 6, "FR": 3}
  (optional "participant", "modality", "k" are checked against the plan)."""

EPILOG = """\
examples:
  graspguide trial --protocol protocols/paper.toml --participant U1 --port sim \\
      --source participant --out runs/pilot
  graspguide trial --protocol protocols/paper.toml --participant U3 --port /dev/ttyACM0 \\
      --source plugin:my_lab.vicon:ViconHand --out runs/study --tlx u3_tlx.jsonl

exit status: 0 when every trial and questionnaire is done, 1 on a link or run error, 2 on
a usage error (bad protocol, participant, source or TLX file), 130 on Ctrl-C (run the
same command again to resume)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--protocol",
        required=True,
        metavar="FILE",
        help="study protocol (protocols/paper.toml; format in docs/study.md)",
    )
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


@signals_interrupt()  # SIGTERM and SIGHUP end the run like Ctrl-C: STOP; trials are kept
def run(args: argparse.Namespace) -> int:
    from graspguide.link.client import DeviceClient
    from graspguide.link.transport import open_port
    from graspguide.study.errors import RunnerError
    from graspguide.study.progress import Progress
    from graspguide.study.runner import StudyRunner, summary_lines
    from graspguide.study.study_protocol import (
        ProtocolFileError,
        load_protocol,
        participant_number,
        session_order,
    )
    from graspguide.study.tlx import load_tlx_file
    from graspguide.study.trial_sources import open_runner_source

    def usage(message: str) -> int:
        print(f"graspguide trial: error: {message}", file=sys.stderr)
        return EXIT_USAGE

    try:
        protocol = load_protocol(args.protocol)
        participant_number(args.participant)
        source = open_runner_source(args.source, protocol, args.participant)
        runner_tlx = None
        if args.tlx is not None:
            runner_tlx = load_tlx_file(
                args.tlx, args.participant, session_order(protocol, args.participant)
            )
    except ProtocolFileError as e:
        return usage(str(e))
    except RunnerError as e:
        return usage(str(e))
    virtual_clock = args.port == SIM_PORT and source.simulated and not source.live
    kwargs = {"virtual_clock": True} if virtual_clock else {}

    transport = None
    code = EXIT_OK
    runner = None
    try:
        try:
            transport = open_port(args.port, baudrate=args.baud, **kwargs)
        except LinkError as e:
            return fail("trial", e)
        client = DeviceClient(transport, timeout=args.timeout)
        try:
            runner = StudyRunner(
                protocol,
                args.participant,
                args.out,
                source,
                client,
                virtual_clock,
                tlx=runner_tlx,
                progress=Progress(),
                protocol_file=args.protocol,
                port=args.port,
            )
            result = runner.run()
            print(
                f"{args.participant}: all {result['planned']} trials done ({result['ran']} "
                f"run now, {result['skipped']} from earlier runs); "
                f"{os.path.join(args.out, args.participant)}"
            )
            for line in summary_lines(args.out, args.participant):
                print(line)
        except ProtocolFileError as e:
            code = usage(str(e))
        except RunnerError as e:
            print(f"graspguide trial: error: {e}", file=sys.stderr)
            code = EXIT_USAGE if e.usage else EXIT_FAILURE
        except LinkError as e:
            print(f"graspguide trial: error: {e}", file=sys.stderr)
            code = EXIT_FAILURE
        except KeyboardInterrupt:
            code = EXIT_INTERRUPTED
            done = "" if runner is None else f" after {runner.ran} trials"
            print(
                f"\ngraspguide trial: interrupted{done}; completed trials are saved: run "
                "the same command again to resume",
                file=sys.stderr,
            )
        finally:
            try:
                client.stop()
            except (LinkError, OSError) as e:
                print(f"graspguide trial: STOP failed: {e}", file=sys.stderr)
                code = code or EXIT_FAILURE
            except KeyboardInterrupt:
                pass
    finally:
        if transport is not None:
            transport.close()
    return code
