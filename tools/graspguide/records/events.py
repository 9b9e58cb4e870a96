"""The observer interface a study run reports to: lab streams (LSL), loggers and tests
subscribe to trial events and to each TELEMETRY frame without the runner knowing them."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

# Event names, in the order a run emits them. trial_end carries success and completion_s;
# pause/redo/skip/note carry reason or text; every trial event carries trial_index.
SESSION_START = "session_start"
TRIAL_START = "trial_start"
TRIAL_END = "trial_end"
PAUSE = "pause"
RESUME = "resume"
REDO = "redo"
SKIP = "skip"
NOTE = "note"
STUDY_END = "study_end"

EVENT_NAMES = (SESSION_START, TRIAL_START, TRIAL_END, PAUSE, RESUME, REDO, SKIP, NOTE, STUDY_END)


@runtime_checkable
class TrialObserver(Protocol):
    """Receives a study run's events and its telemetry. Called from the pose loop's thread:
    an observer must return quickly (queue, do not block) or it delays the next pose."""

    def on_event(self, name: str, **fields: Any) -> None: ...

    def on_telemetry(
        self, t_s: float, error_deg: float, alpha: float, pwm: Sequence[int], status: int
    ) -> None: ...
