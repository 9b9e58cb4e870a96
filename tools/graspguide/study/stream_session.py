"""One `graspguide stream` trial: SET_SCENE, START_TRIAL, the source's poses through the
pose loop (:mod:`graspguide.study.pose_loop`) into the session log and the live view,
until the TRIAL_RESULT or the end of the source."""

from __future__ import annotations

import time
from typing import Any

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


__all__ = ["run_stream"]
