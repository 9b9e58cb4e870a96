"""One `graspguide stream` trial: SET_SCENE, START_TRIAL, the source's poses through the
pose loop (:mod:`graspguide.study.pose_loop`) into the session log, the live view and the
observers (:mod:`graspguide.records.events`: the LSL streams), until the TRIAL_RESULT
or the end of the source; :func:`stream_command` is the whole command (scene, source,
device, log, LSL, STOP on every way out, the result line).

The source is open loop (replay, synthetic, a tracker: the hand moves whatever the motors
do) or the virtual participant (``participant[:seed=N,PARAMS]``, SIMULATED), a closed loop
run as `graspguide trial` runs it: lockstep, or pipelined on the virtual clock
(:class:`graspguide.study.pose_loop.PipelinedPoses`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import Any, TextIO

from graspguide.devices.session import DeviceSession
from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, fail, report
from graspguide.link.messages import ErrorCode
from graspguide.link.transport import LinkError
from graspguide.records import events as ev
from graspguide.study.pose_loop import (
    Frame,
    LockstepPoses,
    OpenLoopPoses,
    PipelinedPoses,
    PoseLoop,
    PoseLoopError,
    pipeline_window,
)

# The virtual participant starts each trial here (a protocol's default [trial] start_quat).
START_QUAT = [1.0, 0.0, 0.0, 0.0]
# A closed-loop trial without a TRIAL_RESULT this long after the scene's timeout is an
# error (the device should have ended it), as in `graspguide trial`.
RESULT_MARGIN_S = 2.0
# The stream is paced to the link (and says so) once, this long into the trial, more than
# this share of the source's poses were skipped for newer ones.
PACED_AFTER_S = 0.5
PACED_SHARE = 0.1


def open_participant(spec: str) -> Any:
    """The virtual participant of ``participant[:seed=N,key=val,...]`` as a closed-loop
    source (:class:`graspguide.sources.trial_sources.ClosedLoopSource`); ``seed`` (default
    0) seeds it, the other keys are its parameters. Raises SourceError."""
    from graspguide.participant.model import VirtualParticipant
    from graspguide.run_errors import RunnerError
    from graspguide.sources.poses import SourceError
    from graspguide.sources.trial_sources import ClosedLoopSource, check_participant_keys

    _, _, rest = spec.partition(":")
    try:
        check_participant_keys(rest, seed=True)
    except ValueError as e:
        raise SourceError(f"--source {spec}: {e}") from None
    seed = 0
    params = []
    for item in filter(None, (x.strip() for x in rest.split(","))):
        key, _, value = item.partition("=")
        if key.strip() == "seed":
            try:
                seed = int(value)
            except ValueError:
                raise SourceError(
                    f"--source {spec}: seed must be an integer (seed=3), got {value.strip()!r}"
                ) from None
        else:
            params.append(item)
    try:
        return ClosedLoopSource(VirtualParticipant.from_spec(",".join(params), seed), spec)
    except (ValueError, TypeError, RunnerError) as e:
        raise SourceError(f"--source {spec}: {e}") from None


def run_stream(
    client,
    scene,
    wrench,
    source,
    trial_id: int = 1,
    virtual_clock: bool = False,
    log=None,
    view=None,
    *,
    observers: Sequence[ev.TrialObserver] = (),
    progress=None,
    link: dict[str, Any] | None = None,
    notice: TextIO | None = None,
) -> dict[str, Any]:
    """One trial on ``client`` (after HELLO): SET_SCENE, START_TRIAL, the source's poses
    (in real time unless ``virtual_clock``), until TRIAL_RESULT or the end of the source.
    ``source`` is an open-loop source or a ClosedLoopSource (:func:`open_participant`).
    An open-loop source faster than the link is paced to it: each POSE is the newest
    pose due, the older ones are skipped (never queued), which ``notice`` (stderr) hears
    once with why (``link``: :func:`link_capacity`). Each TELEMETRY goes to the log,
    ``progress`` (a live_view.TrialProgress), the view and the ``observers`` (trial_start
    and trial_end events too). Returns a summary dict; raises LinkError, PoseLoopError.
    STOP is the caller's job."""
    closed = bool(getattr(source, "closed_loop", False))
    source_rate = float(getattr(source, "rate_hz", None) or 0.0)
    client.set_scene(**scene.set_scene_kwargs())
    client.start_trial(trial_id, wrench)
    client.trial_results.clear()
    for o in observers:
        o.on_event(ev.TRIAL_START, trial_index=trial_id)
    status: dict[str, Any] = {
        "t_s": 0.0,
        "error_deg": float("nan"),
        "pwm": [0] * 4,
        "rate_hz": 0.0,
        "source_rate_hz": source_rate,
        "sent": 0,
        "received": 0,
        "dropped": 0,
        "skipped": 0,
        "paced": False,
    }

    def on_skip(n: int) -> None:
        # A hiccup skips a few poses too (the newest one goes, no backlog is caught up);
        # the link's pace is a steady share of them skipped.
        if status["paced"] or time.monotonic() - loop.wall0 < PACED_AFTER_S:
            return
        if loop.skipped > PACED_SHARE * (loop.skipped + loop.sent):
            status["paced"] = True
            print(pacing_notice(source_rate, link), file=notice or sys.stderr, flush=True)

    def on_frame(frame: Frame) -> None:
        tel = frame.tel
        if log is not None:
            log.telemetry(tel)
        for o in observers:
            o.on_telemetry(frame.t_s, tel.error_deg, tel.alpha, tel.pwm, int(tel.solver_status))
        if progress is not None:
            progress.frame(frame.t_s, tel.error_deg, tel.solver_status == ErrorCode.OK)
        elapsed = max(time.monotonic() - loop.wall0, 1e-9)
        status.update(
            t_s=frame.t_s,
            error_deg=tel.error_deg,
            pwm=list(tel.pwm),
            rate_hz=loop.sent / elapsed,
            sent=loop.sent,
            received=loop.frames,
            dropped=client.device_frames_lost + client.host_bad_frames,
            skipped=loop.skipped,
        )
        if view is not None:
            view.update(status)

    # observers that keep the poses too (the XDF recorder) hear each POSE as it is sent
    pose_observers = [o for o in observers if callable(getattr(o, "on_pose", None))]

    def send_to_all(t_us: int, t_s: float, q: Sequence[float], c: Any) -> None:
        if log is not None:
            log.pose(t_us, t_s, q, c is not None)
        for o in pose_observers:
            o.on_pose(t_s, q, c)

    on_send = send_to_all if log is not None or pose_observers else None
    if closed:
        model = source.model
        model.begin_trial(
            contacts=[list(c) for c in scene.contacts],
            y_axis=list(scene.y_axis),
            wrench=list(wrench),
            policy=scene.policy,
            mode=scene.mode,
            start_quat=list(START_QUAT),
        )
        window = pipeline_window(model, source.rate_hz) if virtual_clock else 1
        poses: Any = (
            PipelinedPoses(model, source.rate_hz, scene.k, window, _feel_lag_error())
            if window > 1
            else LockstepPoses(model.step, source.rate_hz, scene.k)
        )
        # the device ends the trial at its timeout: past that, something is wrong
        loop = PoseLoop(
            client,
            virtual_clock,
            limit_s=scene.timeout_s + RESULT_MARGIN_S,
            wall_limit_s=scene.timeout_s + 10 * RESULT_MARGIN_S,
            on_send=on_send,
            on_frame=on_frame,
        )
    else:
        poses = OpenLoopPoses(source)
        loop = PoseLoop(
            client,
            virtual_clock,
            # a live tracker's next sample is its newest (looking past it would wait for
            # the one after): the others are paced to the link here
            newest=not getattr(source, "live", False),
            on_send=on_send,
            on_frame=on_frame,
            on_skip=on_skip,
        )
    done = loop.run(poses)
    result = done.trial_result
    if result is not None and log is not None:
        log.result(result)
    if progress is not None:
        if result is not None:
            progress.result(bool(result.success))
        else:
            progress.stop()
    for o in observers:
        if result is not None:
            o.on_event(
                ev.TRIAL_END,
                trial_index=trial_id,
                success=bool(result.success),
                completion_s=float(result.completion_s),
                first_entry_s=float(result.first_entry_s),
                final_error_deg=float(result.final_error_deg),
            )
        else:
            o.on_event(ev.TRIAL_END, trial_index=trial_id, success=None, reason="source ended")
    elapsed = max(time.monotonic() - loop.wall0, 1e-9)
    status.update(
        rate_hz=done.sent / elapsed,
        sent=done.sent,
        received=done.frames,
        skipped=done.skipped,
        dropped=client.device_frames_lost + client.host_bad_frames,
    )
    if view is not None:
        view.update(status, force=True)
    return {
        "trial_result": result,
        "sent": done.sent,
        "received": done.frames,
        "dropped": status["dropped"],
        "skipped": done.skipped,
        "paced": status["paced"],
        "rate_hz": status["rate_hz"],
        "source_rate_hz": source_rate,
        "virtual_clock": virtual_clock,
        "elapsed_s": elapsed,
        "last_error_deg": None if done.last_tel is None else done.last_tel.error_deg,
    }


def link_capacity(port: str, transport: Any) -> dict[str, Any] | None:
    """What the wire carries one POSE at a time: its baud rate, the POSE's and the
    TELEMETRY's frame sizes and the POSEs per second they allow (10 bits a byte). None
    for a port whose pseudo-terminal models no wire (the simulated device, QEMU)."""
    from graspguide.devices.qemu_firmware import QEMU_PORT
    from graspguide.devices.sim import SIM_PORT
    from graspguide.link.client import encode_pose_fast
    from graspguide.link.codec import encode_message
    from graspguide.link.messages import Telemetry

    baud = getattr(transport, "baudrate", None)
    if port in (SIM_PORT, QEMU_PORT) or not baud:
        return None
    pose = encode_pose_fast(1, 1, (1.0, 0.0, 0.0, 0.0)) or b""
    tel = Telemetry(
        host_time_us=1,
        error_deg=1.0,
        alpha=1.0,
        pwm=[1, 1, 1, 1],
        constraints_used=0,
        solver_status=ErrorCode.OK,
        iterations=1,
        flags=1,
        compute_time_us=1,
    )
    tel_bytes = len(encode_message(tel, 1))
    wire_s = (len(pose) + tel_bytes) * 10 / float(baud)
    return {
        "baud": int(baud),
        "pose_bytes": len(pose),
        "telemetry_bytes": tel_bytes,
        "wire_ms": wire_s * 1e3,
        "max_hz": 1.0 / wire_s,
    }


def pacing_notice(source_rate_hz: float, link: dict[str, Any] | None) -> str:
    """The one line that says the stream is paced to the link, and why."""
    if link is not None:
        why = (
            f"at {link['baud']} baud a POSE ({link['pose_bytes']} bytes) and its TELEMETRY "
            f"({link['telemetry_bytes']} bytes) take {link['wire_ms']:.1f} ms on the wire: "
            f"at most {link['max_hz']:.0f} POSE/s, less the device's work"
        )
    else:
        why = "the device's answers come slower than the source's poses"
    return (
        f"graspguide stream: pacing to the link: the source gives {source_rate_hz:g} poses/s, "
        f"more than the link carries one POSE at a time ({why}); each POSE sent is the "
        "newest pose, the older ones are skipped, not queued; the rate achieved is shown"
    )


def _feel_lag_error() -> Any:
    from graspguide.participant.model import FeelLagError

    return FeelLagError


def stream_command(
    *,
    scene: str,
    wrench: list[float],
    source: str,
    tracker: str | None,
    port: str,
    baud: int,
    timeout: float,
    log: str | None,
    trial_id: int,
    virtual_clock: bool,
    lsl: str | None = None,
    lsl_wait: float = 0.0,
    record: str | None = None,
) -> int:
    """`graspguide stream`: one trial of the scene file ``scene`` with ``wrench`` on the
    device at ``port``, poses from the source spec ``source``; the session folder ``log``
    when given; LSL outlets named ``lsl`` when given (waiting up to ``lsl_wait`` s for a
    recorder). STOP is sent and the log's end record written on every way out; returns
    the exit code."""
    from graspguide.core.units import moment_unit_problem
    from graspguide.protocol.scene_file import SceneError, config_hash, load_scene
    from graspguide.records.storage import SessionLog
    from graspguide.sources.lab_streams import (
        LabStreamsError,
        LabStreamsUsageError,
        open_lab_streams,
    )
    from graspguide.sources.poses import SourceError, SyntheticSource
    from graspguide.sources.source_spec import open_source
    from graspguide.sources.trial_sources import simulation
    from graspguide.study.live_view import StatusView, TrialProgress

    scene_file, source_spec, log_dir = scene, source, log
    try:
        trial_scene = load_scene(scene_file)
        problem = moment_unit_problem(trial_scene.contacts, wrench)
        if problem:
            raise SceneError(f"--wrench with {scene_file}: {problem}")
        if source_spec.partition(":")[0] == "participant":
            if tracker is not None:
                raise SourceError("--tracker only applies to replay sources, not the participant")
            poses = open_participant(source_spec)
        else:
            poses = open_source(source_spec, tracker=tracker)
        if isinstance(poses, SyntheticSource):
            poses.aim(
                trial_scene.contacts,
                wrench,
                trial_scene.policy,
                trial_scene.constraints,
                trial_scene.y_axis,
            )
    except (SceneError, SourceError) as e:
        report("stream", e)
        return EXIT_USAGE
    why_simulated = simulation(source_spec, bool(poses.simulated), port)
    simulated = why_simulated is not None
    if simulated:
        print(f"graspguide stream: SIMULATED: {why_simulated}", file=sys.stderr, flush=True)
    streams = None
    if lsl:
        try:
            streams = open_lab_streams(
                "stream",
                lsl,
                lsl_wait,
                session="stream",
                nominal_rate_hz=0.0 if virtual_clock else float(poses.rate_hz or 0.0),
                simulated=simulated,
                extra={"scene_config_hash": trial_scene.config_hash(), "source": source_spec},
            )
        except LabStreamsError as e:
            report("stream", e)
            return EXIT_USAGE if isinstance(e, LabStreamsUsageError) else EXIT_FAILURE
    observers: list[ev.TrialObserver] = [streams] if streams is not None else []
    recorder = None
    if record:
        from graspguide.sources.xdf_recording import XdfRecorder

        try:
            recorder = XdfRecorder(
                record,
                session="stream",
                nominal_rate_hz=0.0 if virtual_clock else float(poses.rate_hz or 0.0),
                simulated=simulated,
                extra={"scene_config_hash": trial_scene.config_hash(), "source": source_spec},
            )
        except OSError as e:  # an existing file (never overwritten), an unwritable folder
            if streams is not None:
                streams.close()
            report("stream", e)
            return EXIT_USAGE
        observers.append(recorder)
    try:
        device = DeviceSession("stream", port, baud, timeout, virtual_clock)
    except LinkError as e:
        if streams is not None:
            streams.close()
        if recorder is not None:
            recorder.close()
        return fail("stream", e)
    client = device.client
    session_log = view = None
    code = EXIT_OK
    summary = None
    log_failed = False
    progress = TrialProgress(trial_scene.threshold_deg, trial_scene.hold_s, trial_scene.timeout_s)
    try:
        hello = client.hello()
        config: dict[str, Any] = {"scene": trial_scene.to_dict(), "wrench": wrench}
        config["config_hash"] = config_hash(config)
        config.update(
            source=poses.describe(),
            source_spec=source_spec,
            port=port,
            trial_id=trial_id,
            virtual_clock=virtual_clock,
            scene_file=scene_file,
            simulated=simulated,
            lsl=lsl,
            record=record,
        )
        if log_dir:
            session_log = SessionLog(log_dir)
            session_log.scene(trial_scene.to_dict())
            session_log.device(hello)
            session_log.config(config)
        for o in observers:
            o.on_event(
                ev.SESSION_START,
                config_hash=config["config_hash"],
                source=source_spec,
                simulated=simulated,
                port=port,
                threshold_deg=trial_scene.threshold_deg,
                hold_s=trial_scene.hold_s,
                timeout_s=trial_scene.timeout_s,
            )
        view = StatusView(trial_scene.k, progress, simulated=simulated)
        summary = run_stream(
            client,
            trial_scene,
            wrench,
            poses,
            trial_id,
            virtual_clock,
            session_log,
            view,
            observers=observers,
            progress=progress,
            link=link_capacity(port, device.transport),
        )
    except (LinkError, OSError, PoseLoopError) as e:  # OSError: the log's disk (RecordWriteError)
        code = EXIT_FAILURE
        report("stream", e)
        log_failed = isinstance(e, OSError) and not isinstance(e, LinkError)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        print("graspguide stream: interrupted", file=sys.stderr)
    finally:
        progress.stop()  # no TRIAL_RESULT (Ctrl-C, an error, the source's end): stopped
        try:
            if not device.close():  # STOP, and the device's state as its confirmation
                code = code or EXIT_FAILURE
        finally:
            if view is not None:
                view.finish(device.motors_text())
        if session_log is not None:
            end = {
                "event": "end",
                "exit_code": code,
                "stop_acknowledged": device.stop_acknowledged,
            }
            if summary is not None:
                end.update({k: v for k, v in summary.items() if k != "trial_result"})
            try:
                session_log.result(end)
                session_log.close()
            except OSError as e:  # the records before stay whole (session_log)
                if not log_failed:
                    report("stream", e)
                code = code or EXIT_FAILURE
        if streams is not None:
            try:
                streams.on_event(ev.STUDY_END, exit_code=code)
            finally:
                streams.close()
        if recorder is not None:
            try:
                recorder.on_event(ev.STUDY_END, exit_code=code)
                recorder.close()
            except OSError as e:  # the chunks before stay whole (xdf_writer)
                report("stream", e)
                code = code or EXIT_FAILURE
    if summary is not None:
        print(summary_line(summary, simulated))
    return code


def summary_line(summary: dict[str, Any], simulated: bool = False) -> str:
    r = summary["trial_result"]
    tag = "SIMULATED " if simulated else ""
    if r is None:
        return tag + (
            f"no trial result: the source ended first ({rate_text(summary)}, "
            f"last error {summary['last_error_deg']})"
        )
    return tag + (
        f"trial {r.trial_id}: {'success' if r.success else 'failure'} "
        f"completion_s={r.completion_s:.3f} first_entry_s={r.first_entry_s:.3f} "
        f"final_error_deg={r.final_error_deg:.3f} ({rate_text(summary)})"
    )


def rate_text(summary: dict[str, Any]) -> str:
    """``197 poses sent at 67.3 POSE/s, 0 dropped`` and, when paced, the poses skipped (on
    the virtual clock no rate: the wall's pace there says nothing of the link's)."""
    rate = "" if summary.get("virtual_clock") else f" at {summary['rate_hz']:.1f} POSE/s"
    text = f"{summary['sent']} poses sent{rate}, {summary['dropped']} dropped"
    if summary.get("skipped"):
        text += (
            f"; {summary['skipped']} older poses skipped for newer ones of the source's "
            f"{summary['source_rate_hz']:g}/s"
            + (" (paced to the link)" if summary["paced"] else "")
        )
    return text


__all__ = [
    "open_participant",
    "run_stream",
    "stream_command",
    "summary_line",
    "link_capacity",
    "pacing_notice",
]
