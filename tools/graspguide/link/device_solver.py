"""A device as the engine of `graspguide solve --engine device`: each request is one short
trial on the device (the firmware's float and QR route)."""

from __future__ import annotations

from typing import Any

from graspguide.core import solver
from graspguide.core.requests import error_answer, finite_or_none
from graspguide.link.client import DeviceClient, DeviceError, LinkError


class DeviceEngine:
    """Answers `graspguide solve` requests with a device (--engine device): per request
    SET_SCENE (contacts, y_axis, constraints, policy, mode), START_TRIAL (wrench), one
    POSE (orientation), its TELEMETRY, then STOP (motors off).

    The answer has the core's keys that the wire carries: ok, pwm, constraints_used,
    error_deg, iterations, alpha. ``levels``, ``lambda``, ``relevant`` and
    ``fallback_mask`` are not in TELEMETRY and are left out. Bad requests are answered by
    the same checks as the core engine (bad_json, bad_request) on the host; the device's
    refusals and TELEMETRY.solver_status come back with the core's code and message.
    """

    errors: tuple[type[BaseException], ...] = (LinkError,)

    def __init__(self, client: DeviceClient) -> None:
        self.client = client
        self._trial_id = 0
        client.stop()  # a trial left running by an earlier session would refuse SET_SCENE

    def answer(self, kw: dict[str, Any]) -> dict[str, Any]:
        client = self.client
        self._trial_id = (self._trial_id + 1) & 0xFFFF
        k = len(kw["contacts"])
        try:
            try:
                client.set_scene(
                    kw["contacts"],
                    y_axis=kw["y_axis"],
                    constraints=kw["constraints"],
                    policy=kw["policy"],
                    mode=kw["mode"],
                )
                client.start_trial(self._trial_id, kw["wrench"])
                tel = client.pose(quat=kw["orientation"])
            finally:
                client.stop()
        except DeviceError as e:
            return self._device_error(e)
        status = int(tel.solver_status)
        if status != 0:
            return self._device_error(DeviceError("POSE", None, status, 0, source="TELEMETRY"))
        return {
            "ok": True,
            "pwm": [int(p) for p in tel.pwm[:k]],
            "constraints_used": tel.constraints_used.name.lower(),
            "error_deg": finite_or_none(float(tel.error_deg)),
            "iterations": int(tel.iterations),
            "alpha": finite_or_none(float(tel.alpha)),
        }

    @staticmethod
    def _device_error(e: DeviceError) -> dict[str, Any]:
        if e.code_name in solver.STATUS_NAMES:  # a core status: the core's message
            return error_answer(e.code_name, solver.status_message(e.code_name))
        return error_answer(e.code_name, str(e))


__all__ = ["DeviceEngine"]
