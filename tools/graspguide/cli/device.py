"""`graspguide device`: a host-less device's stored plan and results log
(graspguide.hostless): `plan` stores a participant's plan, `run` starts it, `log`
downloads the records, `info` shows them, `erase` empties the log."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from graspguide.cli.common import (
    DEFAULT_REST_S,
    add_action,
    add_port_arguments,
    add_protocol_argument,
    quaternion_arg,
    rest_s_arg,
)
from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, fail, report

HELP = "a host-less device's plan and results log: store a plan, run it, download, show, erase"

DESCRIPTION = """\
A host-less device (docs/hostless.md) stores one participant's study plan and
appends one checksummed record per completed trial to its non-volatile results log.

  plan   store one participant's plan of --protocol on the device (checked there: every
         trial solved once), with --imu-to-hand (how the IMU sits on the hand) and
         --rest-s and the participant's --calibration (the calibration.json of
         `graspguide calibrate`: a PWM floor and gain per motor, applied to every
         trial; default the paper's mapping); refused while the log holds another
         plan's records
  run    start the stored plan now (a board with a plan also starts it at power-up);
         the wearer then works through it with the button, no host needed
  log    download every record into OUT/<participant>/ in the runner's folder format
         (trials.jsonl, tlx.jsonl with scales null, device_log.json), so
         `graspguide analyze OUT` reads it unchanged; downloading again gives the same
         records; a folder holding another participant's or protocol's trials is refused
  info   print LOG_INFO: the plan (participant, simulated, config_hash, trials) and the
         log (records, capacity, torn records, running)
  erase  delete every record (the plan stays); needs --yes. Download first.

--port sim starts the simulated device on the store file --store FILE (its
non-volatile memory: the plan and the log of an earlier simulated run)."""

EPILOG = """\
examples:
  graspguide device plan --port /dev/ttyACM0 --protocol protocols/paper.toml \\
      --participant U3 --imu-to-hand 0.7071,0,0,0.7071 --calibration runs/U3/calibration.json
  graspguide device run --port /dev/ttyACM0
  graspguide device log --port /dev/ttyACM0 --out runs/hostless
  graspguide device info --port sim --store runs/hostless/U1.store
  graspguide device erase --port /dev/ttyACM0 --yes

exit status: 0 done, 1 on a link or disk error or a device without a plan, 2 on a usage
error (a folder holding another study, erase without --yes, --port sim without --store)."""

ACTIONS = ("plan", "run", "log", "info", "erase")

# Each action's --help: (one line for `device --help`, what it does, its examples).
_ACTION_HELP: dict[str, tuple[str, str, str]] = {
    "plan": (
        "store a participant's plan on the device",
        """\
Store one participant's study plan of --protocol on the device. The device checks it
(every trial solved once) before it keeps it, together with --imu-to-hand (how the IMU
sits on the hand), --rest-s and the participant's --calibration (the calibration.json of
`graspguide calibrate`: a PWM floor and gain per motor, applied to every trial; default
the paper's mapping). Refused while the log holds another plan's records: download
them (`graspguide device log`) and erase them first.""",
        """\
  graspguide device plan --port /dev/ttyACM0 --protocol protocols/paper.toml \\
      --participant U3 --imu-to-hand 0.7071,0,0,0.7071 --calibration runs/U3/calibration.json
  graspguide device plan --port sim --store runs/hostless/U1.store \\
      --protocol protocols/paper.toml --participant U1 --simulated""",
    ),
    "run": (
        "start the stored plan (HOSTLESS_RUN)",
        """\
Start the stored plan now (a board with a plan also starts it at power-up). The wearer
then works through its trials with the button, no host needed; trials that already have
a record are not run again. Prints how many trials have a record.""",
        """\
  graspguide device run --port /dev/ttyACM0
  graspguide device run --port sim --store runs/hostless/U1.store""",
    ),
    "log": (
        "download the results log into OUT/<participant>/",
        """\
Download every record of the device's results log into OUT/<participant>/ in the
runner's folder format (trials.jsonl, tlx.jsonl with scales null, device_log.json), so
`graspguide analyze OUT` reads it unchanged. Downloading again gives the same records;
a folder holding another participant's or protocol's trials is refused.""",
        """\
  graspguide device log --port /dev/ttyACM0 --out runs/hostless
  graspguide device log --port sim --store runs/hostless/U1.store --out runs/hostless
  graspguide analyze runs/hostless""",
    ),
    "info": (
        "print the stored plan and log (LOG_INFO)",
        """\
Print what the device stores (LOG_INFO): the plan (participant, simulated or not,
config_hash, number of trials) and the log (records, capacity, torn records, whether
a plan is running). --json prints it as one JSON object.""",
        """\
  graspguide device info --port /dev/ttyACM0
  graspguide device info --port sim --store runs/hostless/U1.store --json""",
    ),
    "erase": (
        "delete every record of the log (the plan stays)",
        """\
Delete every record of the device's results log for good; the stored plan stays, so the
plan can be run again from its first trial. Needs --yes: download the records first
(`graspguide device log`).""",
        """\
  graspguide device log --port /dev/ttyACM0 --out runs/hostless
  graspguide device erase --port /dev/ttyACM0 --yes""",
    ),
}


def _add_device_arguments(p: argparse.ArgumentParser) -> None:
    add_port_arguments(p, required=True)
    p.add_argument(
        "--store",
        metavar="FILE",
        help="with --port sim: the simulated device's non-volatile store file (required)",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    plan = add_action(sub, "plan", _ACTION_HELP)
    _add_device_arguments(plan)
    add_protocol_argument(plan, required=True)
    plan.add_argument("--participant", required=True, metavar="PID", help="U1, U2, ...")
    plan.add_argument(
        "--imu-to-hand",
        type=quaternion_arg,
        default=(1.0, 0.0, 0.0, 0.0),
        metavar="W,X,Y,Z",
        help="rotation from the IMU's axes to the hand frame, scalar first (README: "
        "mounting the IMU; default 1,0,0,0: the axes coincide)",
    )
    plan.add_argument(
        "--rest-s",
        type=rest_s_arg,
        default=DEFAULT_REST_S,
        metavar="S",
        help=f"rest before each trial's ready pattern (default {DEFAULT_REST_S:g})",
    )
    plan.add_argument(
        "--calibration",
        metavar="FILE",
        help="the participant's calibration.json (`graspguide calibrate`): per-motor PWM "
        "floor and gain, applied to every trial (default: the paper's mapping)",
    )
    plan.add_argument(
        "--simulated",
        action="store_true",
        help="the participant is simulated (default: a person; the records say which)",
    )
    run = add_action(sub, "run", _ACTION_HELP)
    _add_device_arguments(run)
    log = add_action(sub, "log", _ACTION_HELP)
    _add_device_arguments(log)
    log.add_argument("--out", required=True, metavar="DIR", help="the study folder")
    info = add_action(sub, "info", _ACTION_HELP)
    _add_device_arguments(info)
    info.add_argument("--json", action="store_true", help="print one JSON object")
    erase = add_action(sub, "erase", _ACTION_HELP)
    _add_device_arguments(erase)
    erase.add_argument(
        "--yes", action="store_true", help="really erase (the records are gone for good)"
    )


class _Usage(Exception):
    pass


def _open(args: argparse.Namespace) -> tuple[Any, Any]:
    """(transport, client after HELLO) for --port / --store."""
    from graspguide.devices.registry import open_port
    from graspguide.devices.sim import SIM_PORT
    from graspguide.link.client import DeviceClient

    if args.port == SIM_PORT:
        if not args.store:
            raise _Usage(
                "--port sim needs --store FILE: the simulated device's non-volatile store "
                "that holds the plan and the log"
            )
        transport = open_port(args.port, baudrate=args.baud, extra_args=["--store", args.store])
    else:
        if args.store:
            raise _Usage("--store is for --port sim only (a board has its own storage)")
        transport = open_port(args.port, baudrate=args.baud)
    try:
        client = DeviceClient(transport, timeout=args.timeout)
        client.hello()
    except BaseException:
        transport.close()
        raise
    return transport, client


def _print_info(data: dict[str, Any]) -> None:
    rows = [
        ("plan stored", "yes" if data["plan_stored"] else "no"),
        ("participant", data["participant"] or "-"),
        ("simulated", "yes" if data["simulated"] else "no"),
        ("config hash", data["config_hash"]),
        ("plan trials", str(data["plan_trials"])),
        ("records", f"{data['records']} of {data['capacity']}"),
        ("torn records", str(data["torn_records"])),
        ("running", "yes" if data["running"] else "no"),
    ]
    for key, value in rows:
        print(f"{key + ':':<14}{value}")


def _act(args: argparse.Namespace, client: Any) -> int:
    from graspguide.hostless.device_log import download_log, log_info_dict
    from graspguide.link.messages import CAPABILITY_HOSTLESS

    client.require_capability(CAPABILITY_HOSTLESS, "a host-less results log")
    if args.action == "plan":
        return _store_plan(args, client)
    if args.action == "run":
        client.hostless_run()
        info = client.log_info()
        print(
            f"running the plan of {info.participant}: {info.records} of {info.plan_trials} "
            "trials already have a record; the wearer goes on with the button"
        )
        return EXIT_OK
    if args.action == "log":
        s = download_log(client, args.out, err=sys.stderr)
        kind = "SIMULATED participant" if s.simulated else "participant"
        print(
            f"{s.folder}: {s.records} record(s) of {s.plan_trials} planned trials downloaded "
            f"({s.new} new, {s.total} in trials.jsonl) for {kind} {s.participant}, "
            f"config_hash {s.config_hash}; torn records: {s.torn_records}"
        )
        return EXIT_OK
    if args.action == "info":
        data = log_info_dict(client.log_info())
        if args.json:
            print(json.dumps(data))
        else:
            _print_info(data)
        return EXIT_OK
    info = client.log_info()
    client.log_erase()
    print(f"erased {info.records} record(s) of {info.participant or 'no plan'}; the plan stays")
    return EXIT_OK


def _store_plan(args: argparse.Namespace, client: Any) -> int:
    from graspguide.calibration.calibration_file import describe, read_calibration
    from graspguide.hostless.plan_upload import plan_messages, planned_trials
    from graspguide.protocol.study_protocol import load_protocol, participant_number

    cal = read_calibration(args.calibration) if args.calibration else None
    protocol = load_protocol(args.protocol)
    participant_number(args.participant)
    trials = planned_trials(protocol, args.participant)
    begin, plan_trials = plan_messages(
        protocol,
        args.participant,
        trials,
        args.simulated,
        args.rest_s,
        args.imu_to_hand,
        calibration=cal,
    )
    client.upload_plan(begin, plan_trials, calibration=cal)
    kind = "SIMULATED participant" if args.simulated else "participant"
    calibrated = (
        f"calibration {args.calibration}: {describe(cal)}"
        if cal is not None
        else "no calibration (the paper's PWM mapping)"
    )
    print(
        f"stored the plan of {kind} {args.participant}: {len(plan_trials)} trials of "
        f"{args.protocol}, {calibrated}, checked by the device; start it with "
        "`graspguide device run` or by powering the wearable up"
    )
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    from graspguide.hostless.device_log import DeviceLogError
    from graspguide.link.transport import LinkError
    from graspguide.protocol.study_protocol import ProtocolFileError
    from graspguide.records.storage import RecordWriteError
    from graspguide.run_errors import RunnerError

    command = f"device {args.action}"
    if args.action == "erase" and not args.yes:
        report(
            command,
            "erasing deletes every record on the device for good: download them first "
            "(`graspguide device log`), then add --yes",
        )
        return EXIT_USAGE
    try:
        transport, client = _open(args)
    except _Usage as e:
        return fail(command, e, EXIT_USAGE)
    except LinkError as e:
        return fail(command, e)
    try:
        return _act(args, client)
    except (ProtocolFileError, RunnerError, ValueError) as e:
        return fail(command, e, EXIT_USAGE)
    except DeviceLogError as e:
        return fail(command, e, EXIT_USAGE if e.usage else EXIT_FAILURE)
    except (LinkError, RecordWriteError) as e:
        return fail(command, e, EXIT_FAILURE)
    finally:
        transport.close()


__all__ = ["ACTIONS", "add_arguments", "run", "HELP", "DESCRIPTION", "EPILOG"]
