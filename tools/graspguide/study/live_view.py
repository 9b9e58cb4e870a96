"""The live status of `graspguide stream`: the trial's state and hold progress as the device
judges them (:class:`TrialProgress`), shown as a rich panel on a terminal and as plain
periodic lines otherwise (:class:`StatusView`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import Any, TextIO

from graspguide.core.vocabulary import FINGERS
from graspguide.study.progress import Progress, format_duration

WAITING = "waiting"  # no TELEMETRY yet
RUNNING = "running"  # the error is above the threshold
HOLDING = "holding"  # below the threshold, the hold time not reached yet
SUCCESS = "success"  # TRIAL_RESULT: success
TIMEOUT = "timeout"  # TRIAL_RESULT: failure (the device's timeout)
STOPPED = "stopped"  # ended without a TRIAL_RESULT (source ended, Ctrl-C, an error)
STATES = (WAITING, RUNNING, HOLDING, SUCCESS, TIMEOUT, STOPPED)
FINAL_STATES = (SUCCESS, TIMEOUT, STOPPED)


class TrialProgress:
    """The trial's state from its TELEMETRY, by the device's rule
    (lib/graspguide_cue/src/graspguide_cue/trial.h): holding while error_deg <=
    threshold_deg, the hold counted from the first frame of the current stretch; success
    once it lasted hold_s. Display only: the TRIAL_RESULT decides."""

    def __init__(self, threshold_deg: float, hold_s: float, timeout_s: float):
        self.threshold_deg = float(threshold_deg)
        self.hold_s = float(hold_s)
        self.timeout_s = float(timeout_s)
        self.state = WAITING
        self.entry_t_s: float | None = None
        self.held_s = 0.0
        self.t_s = 0.0

    def frame(self, t_s: float, error_deg: float, solver_ok: bool) -> None:
        if self.state in FINAL_STATES:
            return
        self.t_s = float(t_s)
        # a failed solve reports error 0 and motors off: no progress towards the hold
        if solver_ok and error_deg <= self.threshold_deg:
            if self.entry_t_s is None:
                self.entry_t_s = self.t_s
            self.held_s = self.t_s - self.entry_t_s
            self.state = HOLDING
        else:
            self.entry_t_s = None
            self.held_s = 0.0
            self.state = RUNNING

    def result(self, success: bool) -> None:
        self.state = SUCCESS if success else TIMEOUT

    def stop(self) -> None:
        if self.state not in FINAL_STATES:
            self.state = STOPPED

    def hold_text(self) -> str:
        """``below 3.0 deg for 0.31/0.50 s`` while holding, else what is missing."""
        held = min(self.held_s, self.hold_s)
        if self.state == HOLDING or (self.state == SUCCESS and self.entry_t_s is not None):
            return f"below {self.threshold_deg:.1f} deg for {held:.2f}/{self.hold_s:.2f} s"
        return f"not below {self.threshold_deg:.1f} deg (hold 0.00/{self.hold_s:.2f} s)"


def rate_text(s: dict[str, Any]) -> str:
    """The rate achieved and, when the link paces the source, the source's rate and the
    poses skipped for newer ones."""
    text = f"{s.get('rate_hz', 0.0):7.1f} POSE/s sent"
    if s.get("skipped"):
        text += (
            f" of the source's {s.get('source_rate_hz', 0.0):g}/s ({s['skipped']} older "
            "skipped" + ("; paced to the link)" if s.get("paced") else ")")
        )
    return text


class StatusView:
    """Live status: a rich panel on a terminal, plain periodic lines otherwise (and a line
    at once when the trial ends). ``k`` motors named after FINGERS; ``simulated`` labels
    a SIMULATED run. `graspguide stream` shows one; `graspguide trial` one per trial
    (:class:`TrialPanel`), with ``heading`` rows (trial n of N, the keys) above the
    trial's, ``transient`` (the panel gives way to the trial's outcome line) and drawn
    only on update (``auto_refresh`` off: a note typed meanwhile is not drawn over)."""

    def __init__(
        self,
        k: int,
        progress: TrialProgress,
        out: TextIO | None = None,
        period_s: float = 1.0,
        simulated: bool = False,
        fingers: Sequence[str] = FINGERS,
        *,
        title: str = "graspguide stream",
        heading: Sequence[tuple[str, str]] = (),
        transient: bool = False,
        auto_refresh: bool = True,
        live: bool | None = None,
    ):
        self.out = out or sys.stdout
        self.k = k
        self.progress = progress
        self.fingers = list(fingers[:k])
        self.simulated = simulated
        self.title = title
        self.heading = list(heading)
        self.period_s = period_s
        self.next_t = 0.0
        self.live: Any = None
        self.last: dict[str, Any] = {}  # the last status shown, for finish()
        self.last_draw = 0.0
        self.last_state = progress.state
        if self.out.isatty() if live is None else live:
            try:
                from rich.console import Console
                from rich.live import Live

                self.live = Live(
                    self._render({}),
                    console=Console(file=self.out),
                    refresh_per_second=10,
                    transient=transient,
                    auto_refresh=auto_refresh,
                )
                self.live.start(refresh=True)
            except ImportError:  # pragma: no cover - rich is a dependency
                self.live = None

    def _title(self) -> str:
        return self.title + (" (SIMULATED)" if self.simulated else "")

    def _render(self, s: dict[str, Any], motors: str | None = None) -> Any:
        from rich.table import Table

        p = self.progress
        table = Table(title=self._title(), show_header=False, expand=False)
        for label, text in self.heading:
            table.add_row(label, text)
        table.add_row("state", f"[bold]{p.state}[/bold]")
        table.add_row("time", f"{s.get('t_s', 0.0):7.2f} / {p.timeout_s:g} s")
        table.add_row(
            "error",
            f"{s.get('error_deg', float('nan')):7.2f} deg (threshold {p.threshold_deg:.1f})",
        )
        table.add_row("hold", p.hold_text())
        # Once the device confirmed the motors off, a finger's row says so: the last cue
        # sent is no longer what the wearer feels.
        off = motors is not None and motors.startswith("off")
        for finger, pwm in zip(self.fingers, s.get("pwm", [0] * self.k)):
            if off:
                table.add_row(finger, f"  0 (off; the last cue sent was {pwm})")
                continue
            bar = "#" * (pwm * 30 // 255)
            table.add_row(finger, f"{pwm:3d} [green]{bar:<30}[/green]")
        if "rate_hz" in s:  # the link's figures, where the caller counts them (stream)
            table.add_row("rate", rate_text(s))
            table.add_row("sent / telemetry", f"{s.get('sent', 0)} / {s.get('received', 0)}")
            table.add_row("dropped", str(s.get("dropped", 0)))
        if motors is not None:
            table.add_row("motors", f"[bold]{motors}[/bold]")
        return table

    def line(self, s: dict[str, Any]) -> str:
        """The plain status line of ``s`` (not a terminal): it starts with the time, for
        readers of the lines, and ends with SIMULATED when the run is."""
        p = self.progress
        pwm = " ".join(f"{f}={x:3d}" for f, x in zip(self.fingers, s.get("pwm", [0] * self.k)))
        tag = " SIMULATED" if self.simulated else ""
        text = (
            f"t={s.get('t_s', 0.0):7.2f}s state={p.state} "
            f"error={s.get('error_deg', float('nan')):7.2f}deg "
            f"[{p.hold_text()}] pwm {pwm}"
        )
        if "rate_hz" in s:
            text += f" rate={s['rate_hz']:.1f}/s" + (
                f" (source {s.get('source_rate_hz', 0.0):g}/s, skipped={s['skipped']}"
                + (", paced to the link)" if s.get("paced") else ")")
                if s.get("skipped")
                else ""
            )
            text += f" sent={s.get('sent', 0)} dropped={s.get('dropped', 0)}"
        return text + tag

    def update(self, s: dict[str, Any], force: bool = False) -> None:
        self.last = s
        if self.live is not None:
            now = time.monotonic()
            if force or now - self.last_draw >= 0.1:
                self.live.update(self._render(s), refresh=True)
                self.last_draw = now
            return
        state = self.progress.state
        ended = state != self.last_state and state in FINAL_STATES
        self.last_state = state
        if force or ended or s["t_s"] >= self.next_t:
            self.next_t = s["t_s"] + self.period_s
            print(self.line(s), file=self.out, flush=True)

    def finish(self, motors: str) -> None:
        """The last panel (or line): the trial's final state with what the device said of
        the motors once stopped (``motors``), then the view closed."""
        if self.live is not None:
            self.live.update(self._render(self.last, motors), refresh=True)
            self.close()
            return
        print(f"{self.line(self.last)} motors {motors}", file=self.out, flush=True)

    def close(self) -> None:
        if self.live is not None:
            self.live.stop()
            self.live = None


class TrialPanel(Progress):
    """What `graspguide trial` shows: on a terminal, each trial's :class:`StatusView` --
    the stream's panel, with trial n of N and its condition (and the operator's keys)
    above the fingers' cue levels, the error and the hold progress, SIMULATED in its
    title when the run is -- giving way to the trial's outcome line when it ends; off a
    terminal, :class:`Progress`'s lines, with the panel's fields every ``period_s`` of a
    real-time trial. The lines between trials (prompts, rest, outcome) are Progress's."""

    def __init__(
        self,
        threshold_deg: float,
        hold_s: float,
        timeout_s: float,
        simulated: bool = False,
        keys: str | None = None,
        out: TextIO | None = None,
        tty: bool | None = None,
        period_s: float = 5.0,
    ):
        super().__init__(out, tty, period_s)
        self.threshold_deg = threshold_deg
        self.hold_s = hold_s
        self.timeout_s = timeout_s
        self.simulated = simulated
        self.keys = keys
        self.view: StatusView | None = None
        self.trial_progress: TrialProgress | None = None
        self.status: dict[str, Any] = {}

    def trial_start(
        self, trial: Any, total: int, sessions: int, left_s: float | None = None
    ) -> None:
        self.close()
        sess = "familiarization" if trial.familiarization else f"session {trial.session}/{sessions}"
        what = f"{sess} {trial.modality} k={trial.k} {trial.wrench_id}"
        left = "" if left_s is None else f" ({format_duration(left_s)} left)"
        self._head = f"[{trial.trial_index}/{total}] {what}{left}"
        self._next_t = self.period_s
        self.trial_progress = TrialProgress(self.threshold_deg, self.hold_s, self.timeout_s)
        self.status = {"t_s": 0.0, "error_deg": float("nan"), "pwm": [0] * trial.k}
        heading = [("trial", self._head)]  # [n/N]: trial n of N
        if self.keys:
            heading.append(("keys", self.keys))
        self.view = StatusView(
            trial.k,
            self.trial_progress,
            out=self.out,
            period_s=self.period_s,
            simulated=self.simulated,
            title="graspguide trial",
            heading=heading,
            transient=True,
            auto_refresh=False,
            live=self.tty,
        )

    def frame(
        self,
        t_s: float,
        error_deg: float,
        pwm: Sequence[int],
        real_time: bool,
        solver_ok: bool = True,
    ) -> None:
        view, tp = self.view, self.trial_progress
        if view is None or tp is None:
            return
        tp.frame(t_s, error_deg, solver_ok)
        self.status = {"t_s": t_s, "error_deg": error_deg, "pwm": [int(x) for x in pwm]}
        if view.live is not None:
            view.update(self.status)
        elif real_time and t_s >= self._next_t:
            self._next_t = t_s + self.period_s
            print(f"{self._head} {view.line(self.status)}", file=self.out, flush=True)

    def trial_end(self, record: dict[str, Any]) -> None:
        if self.view is not None and self.trial_progress is not None:
            self.trial_progress.result(bool(record["success"]))
            self.view.update(self.status, force=True)  # the last state, then the outcome
        outcome = (
            f"success {record['completion_s']:.2f} s"
            if record["success"]
            else f"failure ({record['completion_s']:g} s)"
        )
        tag = " SIMULATED" if self.simulated else ""
        self.line(f"{self._head} {outcome}, final error {record['final_error_deg']:.2f} deg{tag}")

    def line(self, text: str) -> None:
        self.close()  # a line never lands inside the panel
        super().line(text)

    def close(self) -> None:
        """The trial's panel gone (idempotent); on every way out of the run."""
        if self.view is not None:
            self.view.close()
            self.view = None


__all__ = ["StatusView", "TrialProgress", "TrialPanel", "STATES", "FINAL_STATES"]
