"""What `graspguide trial` shows while it runs: trial n of N, the condition, the live
error."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import Any, TextIO

from graspguide.protocol.study_protocol import PlannedTrial


class Progress:
    """Trial n of N, the condition and the live error: one rewritten line on a terminal,
    plain lines (one per trial; every ``period_s`` of a real-time trial) otherwise."""

    def __init__(self, out: TextIO | None = None, tty: bool | None = None, period_s: float = 5.0):
        self.out = out or sys.stdout
        self.tty = self.out.isatty() if tty is None else tty
        self.period_s = period_s
        self._last = 0.0
        self._next_t = 0.0
        self._head = ""

    def line(self, text: str) -> None:
        if self.tty:
            self.out.write("\r\x1b[K")
        print(text, file=self.out, flush=True)

    def trial_start(
        self, trial: PlannedTrial, total: int, sessions: int, left_s: float | None = None
    ) -> None:
        sess = "familiarization" if trial.familiarization else f"session {trial.session}/{sessions}"
        self._head = (
            f"[{trial.trial_index}/{total}] {sess} {trial.modality} k={trial.k} {trial.wrench_id}"
        )
        if left_s is not None:
            self._head += f" ({format_duration(left_s)} left)"
        self._next_t = self.period_s
        if self.tty:
            self.out.write(f"\r\x1b[K{self._head} ...")
            self.out.flush()

    def frame(
        self,
        t_s: float,
        error_deg: float,
        pwm: Sequence[int],
        real_time: bool,
        solver_ok: bool = True,  # for views that judge the hold (live_view.TrialPanel)
    ) -> None:
        if self.tty:
            now = time.monotonic()
            if now - self._last >= 0.1:
                self._last = now
                self.out.write(
                    f"\r\x1b[K{self._head} t={t_s:6.2f}s error={error_deg:6.2f}deg pwm={list(pwm)}"
                )
                self.out.flush()
        elif real_time and t_s >= self._next_t:
            self._next_t = t_s + self.period_s
            print(
                f"{self._head} t={t_s:6.2f}s error={error_deg:6.2f}deg", file=self.out, flush=True
            )

    def trial_end(self, record: dict[str, Any]) -> None:
        outcome = (
            f"success {record['completion_s']:.2f} s"
            if record["success"]
            else f"failure ({record['completion_s']:g} s)"
        )
        self.line(f"{self._head} {outcome}, final error {record['final_error_deg']:.2f} deg")


def format_duration(s: float) -> str:
    """``~1 h 05 min``, ``~12 min``, ``~40 s``: an estimate, rounded as one."""
    s = max(0.0, float(s))
    if s < 60:
        return f"~{s:.0f} s"
    minutes = int(round(s / 60))
    if minutes < 60:
        return f"~{minutes} min"
    return f"~{minutes // 60} h {minutes % 60:02d} min"


def time_left_s(
    remaining: int, durations_s: Sequence[float], rest_s: float, timeout_s: float
) -> float:
    """The time the ``remaining`` trials (the one starting now included) should take: the
    mean duration of the trials done so far (the protocol's timeout while there is none)
    each, and a rest between two of them."""
    per = sum(durations_s) / len(durations_s) if durations_s else float(timeout_s)
    return remaining * per + max(0, remaining - 1) * rest_s


__all__ = ["Progress", "format_duration", "time_left_s"]
