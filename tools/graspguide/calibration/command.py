"""`graspguide calibrate`'s flow: the device opened, the procedure run with the operator's
or the virtual participant's answers, the result printed and stored in
OUT/PID/calibration.json, optionally sent to the device; STOP and the motors off on every
way out, and nothing written unless the procedure completed."""

from __future__ import annotations

import datetime
import getpass
import os
import secrets
import sys
import time
from typing import Any

from graspguide.calibration.calibration_file import (
    SCHEMA,
    calibration_path,
    write_calibration_file,
)
from graspguide.calibration.matching import MatchingSettings
from graspguide.calibration.operator import OperatorResponder
from graspguide.calibration.session import (
    CalibrationAborted,
    CalibrationFailed,
    CalibrationResult,
    CalibrationSettings,
    Responder,
    run_procedure,
)
from graspguide.calibration.staircase import StaircaseSettings
from graspguide.calibration.stimuli import SIMULATED_STIMULUS_S, DeviceStimulator
from graspguide.calibration.virtual_observer import VirtualObserver, parse_participant_source
from graspguide.core.reference import PWM_RANGE
from graspguide.exit_codes import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    fail,
    report,
)

COMMAND = "calibrate"


def _settings(
    fingers: str,
    reference: str,
    reference_pwm: int,
    min_floor: int,
    rule: int,
    reversals: int,
    catch_rate: float,
    stimulus_s: float,
    gap_s: float,
    seed: int,
    headroom: bool = True,
) -> CalibrationSettings:
    use_last = max(2, min(reversals, reversals - 4))
    return CalibrationSettings(
        fingers=tuple(f.strip() for f in fingers.split(",") if f.strip()),
        reference=reference,
        reference_pwm=reference_pwm,
        min_floor=min_floor,
        detection=StaircaseSettings(start=150, down=rule, reversals=reversals, use_last=use_last),
        catch_rate=catch_rate,
        matching=MatchingSettings(),
        stimulus_s=stimulus_s,
        gap_s=gap_s,
        seed=seed,
        headroom=headroom,
    )


def _file_data(
    result: CalibrationResult,
    participant: str,
    operator: str,
    observer: VirtualObserver | None,
    device: dict[str, Any],
    elapsed_s: float,
) -> dict[str, Any]:
    s = result.settings
    return {
        "schema": SCHEMA,
        "participant": participant,
        "simulated": observer is not None,
        "virtual_participant": observer.describe(s.fingers) if observer else None,
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "operator": operator,
        "device": device,
        "settings": s.to_json(),
        "calibration": result.calibration.to_json(),
        "fingers": {f: r.to_json() for f, r in result.fingers.items()},
        "catch_trials": result.catch_trials,
        "false_alarm_rate": result.false_alarm_rate,
        "warnings": result.warnings,
        "trials": result.trials,
        "elapsed_s": round(elapsed_s, 3),
    }


def _summary(result: CalibrationResult, label: str) -> list[str]:
    s = result.settings
    lines = [
        f"{label}: thresholds by 1-up-{s.detection.down}-down ({s.detection.target:.1%} "
        f"detected), gains matched to {s.reference} at PWM {s.reference_pwm}",
        f"  {'finger':<7} motor  threshold  floor    PSE   gain  saturates  false alarms",
    ]
    for f, r in result.fingers.items():
        top = r.pwm_floor + r.gain * PWM_RANGE
        sat = f"|m|>{(255 - r.pwm_floor) / (r.gain * PWM_RANGE):.2f}" if top > 255.5 else "no"
        fa = f"{r.false_alarms}/{r.catch_trials}" if r.catch_trials else "-"
        pse = f"{r.pse_pwm:6.1f}" if r.pse_pwm is not None else "   ref"
        lines.append(
            f"  {f:<7} {r.motor:>5}  {r.threshold_pwm:9.1f}  {r.pwm_floor:5d}  {pse}  "
            f"{r.gain:5.3f}  {sat:>9}  {fa}"
        )
    fa_all = result.false_alarm_rate
    lines.append(
        f"  false-alarm rate {fa_all:.2f} on {result.catch_trials} catch trials"
        if fa_all is not None
        else "  no catch trials"
    )
    lines.append(f"  {len(result.trials)} trials; calibration {result.calibration.to_json()}")
    return lines


def calibrate_command(
    *,
    participant: str,
    port: str,
    baud: int,
    timeout: float,
    out: str,
    fingers: str,
    reference: str,
    source: str,
    apply: bool,
    force: bool,
    operator: str | None,
    stimulus_s: float,
    gap_s: float,
    reference_pwm: int,
    min_floor: int,
    rule: int,
    reversals: int,
    catch_rate: float,
    seed: int | None,
    no_headroom: bool = False,
) -> int:
    from graspguide.devices.session import DeviceSession
    from graspguide.link.transport import LinkError
    from graspguide.protocol.study_protocol import ProtocolFileError, participant_number
    from graspguide.records.storage import RecordWriteError

    try:
        participant_number(participant)
        observer = parse_participant_source(source)
        if seed is None:
            seed = observer.seed if observer else secrets.randbelow(2**31)
        if observer is not None:
            stimulus_s = SIMULATED_STIMULUS_S
        settings = _settings(
            fingers,
            reference,
            reference_pwm,
            min_floor,
            rule,
            reversals,
            catch_rate,
            stimulus_s,
            gap_s,
            seed,
            headroom=not no_headroom,
        )
    except (ProtocolFileError, ValueError) as e:
        return fail(COMMAND, e, EXIT_USAGE)
    path = calibration_path(out, participant)
    if os.path.exists(path) and not force:
        report(COMMAND, f"{path} exists: add --force to measure and replace it")
        return EXIT_USAGE
    label = f"SIMULATED participant {participant}" if observer else f"participant {participant}"
    try:
        session = DeviceSession(COMMAND, port, baud, timeout)
    except LinkError as e:
        return fail(COMMAND, e)
    code = EXIT_FAILURE
    try:
        code = _calibrate(
            session, settings, observer, participant, operator, label, path, apply, force
        )
    except CalibrationAborted as e:
        report(COMMAND, f"{e}: aborted, motors off, nothing written")
        code = EXIT_INTERRUPTED
    except KeyboardInterrupt:
        report(COMMAND, "interrupted: motors off, nothing written")
        code = EXIT_INTERRUPTED
    except CalibrationFailed as e:
        report(COMMAND, f"{e}; nothing written")
        code = EXIT_FAILURE
    except FileExistsError as e:
        report(COMMAND, e.strerror)
        code = EXIT_USAGE
    except (LinkError, RecordWriteError) as e:
        code = fail(COMMAND, e, EXIT_FAILURE)
    finally:
        if not session.close() and code == EXIT_OK:
            code = EXIT_FAILURE
    return code


def _calibrate(
    session: Any,
    settings: CalibrationSettings,
    observer: VirtualObserver | None,
    participant: str,
    operator: str | None,
    label: str,
    path: str,
    apply: bool,
    force: bool,
) -> int:
    client = session.client
    hello = client.hello()
    set_calibration = getattr(client, "set_calibration", None)
    if apply and set_calibration is None:
        report(
            COMMAND,
            "--apply: this graspguide's DeviceClient cannot send a calibration "
            "(no set_calibration); run without --apply",
        )
        return EXIT_USAGE
    board = hello.board.decode() if isinstance(hello.board, bytes) else str(hello.board)
    device = {
        "port": session.transport.name,
        "board": board.rstrip("\x00"),
        "firmware": ".".join(map(str, hello.firmware_version)),
        "protocol_version": hello.protocol_version,
    }
    print(
        f"calibrating {label} on {device['port']} ({device['board']}, firmware "
        f"{device['firmware']}): fingers {','.join(settings.fingers)}, reference "
        f"{settings.reference} at PWM {settings.reference_pwm}, seed {settings.seed}",
        flush=True,
    )
    responder: Responder
    if observer is not None:
        print(
            f"SIMULATED: the virtual participant (seed {observer.seed}) answers; stimuli "
            f"last {SIMULATED_STIMULUS_S:g} s instead of real time and there are no pauses",
            flush=True,
        )
        responder = observer
        stimulator = DeviceStimulator(client, SIMULATED_STIMULUS_S, 0.0, sleep=lambda s: None)
    else:
        print(
            "type the participant's answer after each stimulus: y/n (felt it or not), "
            "1/2 (which of two felt stronger); q quits, nothing is written",
            flush=True,
        )
        responder = OperatorResponder()
        stimulator = DeviceStimulator(client, settings.stimulus_s, settings.gap_s)
    phases: dict[tuple[str, str], int] = {}

    def on_trial(entry: dict[str, Any]) -> None:
        key = (entry["phase"], entry["finger"])
        if key not in phases and observer is not None:
            print(f"  {label}: {entry['phase']} on {entry['finger']} ...", flush=True)
        phases[key] = phases.get(key, 0) + 1

    t0 = time.monotonic()
    result = run_procedure(settings, responder, stimulator, on_trial=on_trial)
    elapsed = time.monotonic() - t0
    for line in _summary(result, label):
        print(line)
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    data = _file_data(result, participant, operator or _login(), observer, device, elapsed)
    write_calibration_file(path, data, force=force)
    print(f"wrote {path}" + (" (SIMULATED participant)" if observer else ""), flush=True)
    if apply:
        assert set_calibration is not None
        set_calibration(result.calibration)
        print(f"applied to {device['port']}: {result.calibration.to_json()}", flush=True)
    return EXIT_OK


def _login() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "unknown"


__all__ = ["calibrate_command"]
