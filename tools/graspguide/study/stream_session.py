"""One `graspguide stream` trial: SET_SCENE, START_TRIAL, the source's poses through the
pose loop (:mod:`graspguide.study.pose_loop`) into the session log and the live view,
until the TRIAL_RESULT or the end of the source; :func:`stream_command` is the whole
command (scene, source, device, log, STOP on every way out, the result line)."""

from __future__ import annotations

import sys
import time
from typing import Any

from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, fail, report
from graspguide.link.transport import LinkError
from graspguide.study.device_session import DeviceSession
from graspguide.study.pose_loop import Frame, OpenLoopPoses, PoseLoop


def run_stream(
    client,
    scene,
    wrench,
    source,
    trial_id: int = 1,
    virtual_clock: bool = False,
    log=None,
    view=None,
) -> dict[str, Any]:
    """One trial on ``client`` (after HELLO): SET_SCENE, START_TRIAL, the source's poses
    (paced in real time unless ``virtual_clock``; a pose more than two periods late is
    skipped), until TRIAL_RESULT or the end of the source. Returns a summary dict; raises
    LinkError. STOP is the caller's job."""
    client.set_scene(**scene.set_scene_kwargs())
    client.start_trial(trial_id, wrench)
    client.trial_results.clear()
    status: dict[str, Any] = {
        "t_s": 0.0,
        "error_deg": float("nan"),
        "pwm": [0] * 4,
        "rate_hz": 0.0,
        "sent": 0,
        "received": 0,
        "dropped": 0,
    }

    def on_frame(frame: Frame) -> None:
        tel = frame.tel
        if log is not None:
            log.telemetry(tel)
        elapsed = max(time.monotonic() - loop.wall0, 1e-9)
        status.update(
            t_s=frame.t_s,
            error_deg=tel.error_deg,
            pwm=list(tel.pwm),
            rate_hz=loop.sent / elapsed,
            sent=loop.sent,
            received=loop.frames,
            dropped=loop.late_skipped + client.device_frames_lost + client.host_bad_frames,
        )
        if view is not None:
            view.update(status)

    loop = PoseLoop(
        client,
        virtual_clock,
        skip_late=True,
        period_s=1.0 / source.rate_hz if source.rate_hz else 0.0,
        on_send=None
        if log is None
        else lambda t_us, t_s, q, c: log.pose(t_us, t_s, q, c is not None),
        on_frame=on_frame,
    )
    done = loop.run(OpenLoopPoses(source))
    if done.trial_result is not None and log is not None:
        log.result(done.trial_result)
    if view is not None:
        view.update(status, force=True)
    return {
        "trial_result": done.trial_result,
        "sent": done.sent,
        "received": done.frames,
        "dropped": status["dropped"] if done.sent else done.late_skipped,
        "late_skipped": done.late_skipped,
        "elapsed_s": time.monotonic() - loop.wall0,
        "last_error_deg": None if done.last_tel is None else done.last_tel.error_deg,
    }


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
) -> int:
    """`graspguide stream`: one trial of the scene file ``scene`` with ``wrench`` on the
    device at ``port``, poses from the source spec ``source``; the session folder ``log``
    when given. STOP is sent and the log's end record written on every way out; returns
    the exit code."""
    from graspguide.core.units import moment_unit_problem
    from graspguide.study.live_view import StatusView
    from graspguide.study.records import SessionLog
    from graspguide.study.scene_file import SceneError, config_hash, load_scene
    from graspguide.study.sources import SourceError, SyntheticSource, open_source

    scene_file, source_spec, log_dir = scene, source, log
    try:
        trial_scene = load_scene(scene_file)
        problem = moment_unit_problem(trial_scene.contacts, wrench)
        if problem:
            raise SceneError(f"--wrench with {scene_file}: {problem}")
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
    try:
        device = DeviceSession("stream", port, baud, timeout, virtual_clock)
    except LinkError as e:
        return fail("stream", e)
    client = device.client
    session_log = view = None
    code = EXIT_OK
    summary = None
    log_failed = False
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
        )
        if log_dir:
            session_log = SessionLog(log_dir)
            session_log.scene(trial_scene.to_dict())
            session_log.device(hello)
            session_log.config(config)
        view = StatusView(trial_scene.k)
        summary = run_stream(
            client, trial_scene, wrench, poses, trial_id, virtual_clock, session_log, view
        )
    except (LinkError, OSError) as e:  # OSError: the session log's disk (RecordWriteError)
        code = EXIT_FAILURE
        report("stream", e)
        log_failed = isinstance(e, OSError) and not isinstance(e, LinkError)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        print("graspguide stream: interrupted", file=sys.stderr)
    finally:
        if view is not None:
            view.close()
        if not device.close():
            code = code or EXIT_FAILURE
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
    if summary is not None:
        print(summary_line(summary))
    return code


def summary_line(summary: dict[str, Any]) -> str:
    r = summary["trial_result"]
    if r is None:
        return (
            f"no trial result: the source ended first ({summary['sent']} poses sent, "
            f"last error {summary['last_error_deg']})"
        )
    return (
        f"trial {r.trial_id}: {'success' if r.success else 'failure'} "
        f"completion_s={r.completion_s:.3f} first_entry_s={r.first_entry_s:.3f} "
        f"final_error_deg={r.final_error_deg:.3f} ({summary['sent']} poses, "
        f"{summary['dropped']} dropped)"
    )


__all__ = ["run_stream", "stream_command"]
