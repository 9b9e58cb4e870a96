"""The one pose loop: poses to a device in a started trial, TELEMETRY back, until the trial
ends (TRIAL_RESULT) or the poses do. `graspguide stream`, `graspguide trial` and the demo
all run their trials through :meth:`PoseLoop.run`.

What varies is given, not re-implemented:

* where the poses come from (:class:`OpenLoopPoses`: samples that ignore the motors;
  :class:`LockstepPoses`: ``step(t_s, pwm)`` of a closed-loop source, fed the previous
  TELEMETRY's PWM; :class:`PipelinedPoses`: ``act``/``feel`` of a source that separates
  them, up to ``window`` POSEs in flight, bit for bit the lockstep poses);
* the clock: the virtual one (the POSE's timestamp is the pose's trial time, plus
  ``base_us``, so a simulated device runs as fast as the link allows) or real time (each
  pose waits for its time; with ``newest`` an open-loop source is paced to the link:
  each POSE is the newest pose due, the older ones are skipped, never queued, and
  ``on_skip`` hears of each skip);
* what is done with each pose and its TELEMETRY (``on_send``, ``on_frame``: the logs,
  the live view; ``on_frames``: the same for a whole batch at once, the frame CSV);
* when to give up without a TRIAL_RESULT (``limit_s`` of trial time on the virtual
  clock, ``wall_limit_s`` in real time): :class:`TrialOverrun`.

STOP is the caller's job, as are SET_SCENE and START_TRIAL.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

# Imported once here, not per pose: run() and _send() are the per-frame path.
from graspguide.link.client import DeviceError, LinkTimeout, host_time_us
from graspguide.link.messages import TELEMETRY_FLAG_TRIAL_RUNNING, Error, ErrorCode

Pose = tuple[float, Sequence[float], Any]  # (t_s, quat w, x, y, z, contacts or None)
Stamped = tuple[float, int, Sequence[float], Any]  # (t_s, POSE timestamp, quat, contacts)


class PoseLoopError(Exception):
    """The trial cannot go on; the message says why (the caller names the trial)."""


class TrialOverrun(PoseLoopError):
    """No TRIAL_RESULT by the limit: ``t_s`` of trial time, ``wall_s`` of wall time."""

    def __init__(self, t_s: float, wall_s: float, real_time: bool):
        super().__init__(f"no TRIAL_RESULT after {wall_s:.1f} s")
        self.t_s = t_s
        self.wall_s = wall_s
        self.real_time = real_time


class Diverged(PoseLoopError):
    """A pose sent ahead would not be the lockstep one (the caller runs the trial again
    in lockstep)."""


@dataclass(slots=True)
class Frame:
    """One POSE sent and its TELEMETRY."""

    index: int  # the pose's number in the trial, 0, 1, ...
    t_s: float
    t_us: int
    quat: Sequence[float]
    contacts: Any
    tel: Any


@dataclass
class LoopResult:
    trial_result: Any  # the TRIAL_RESULT, or None (the poses ended first)
    frames: int  # TELEMETRY received
    sent: int  # POSEs sent (one more than frames when the device refused the last)
    skipped: int  # poses skipped in real time for a newer one (the link's pace)
    t_s: float  # the last frame's trial time
    last_tel: Any  # the last TELEMETRY, or None
    ended: bool  # the device said the trial ended


# --------------------------------------------------------------------------------------
# Where the poses come from
# --------------------------------------------------------------------------------------
class OpenLoopPoses:
    """Samples ``(t_s, quat, contacts)`` that do not depend on the motors."""

    window = 1

    def __init__(self, samples: Iterable[Pose]):
        self._it: Iterator[Pose] = iter(samples)
        self._ahead: list[Pose] = []  # samples read to look past the next one

    def _peek(self, n: int) -> list[Pose]:
        while len(self._ahead) < n:
            for sample in self._it:
                self._ahead.append(sample)
                break
            else:
                break
        return self._ahead[:n]

    def skip_stale(self, now_s: float) -> int:
        """Skips every sample a later one of which is due by ``now_s`` (trial time), so
        that the next one is the newest due; returns how many were skipped."""
        skipped = 0
        while len(self._peek(2)) == 2 and self._ahead[1][0] <= now_s:
            self._ahead.pop(0)
            skipped += 1
        return skipped

    def next_batch(self, index: int) -> list[Pose]:
        if self._peek(1):
            t_s, quat, contacts = self._ahead.pop(0)
            return [(t_s, [float(x) for x in quat], contacts)]
        return []

    def feel(self, index: int, t_s: float, pwm: Sequence[int]) -> None:
        pass


class LockstepPoses:
    """A closed-loop source: pose i is ``step(i / rate_hz, pwm of TELEMETRY i-1)`` (zeros
    for i = 0), one POSE in flight."""

    window = 1

    def __init__(self, step: Callable[[float, list[int]], Sequence[float]], rate_hz: float, k: int):
        self.step = step
        self.rate_hz = rate_hz
        self.pwm: list[int] = [0] * k

    def next_batch(self, index: int) -> list[Pose]:
        t_s = index / self.rate_hz
        return [(t_s, [float(x) for x in self.step(t_s, list(self.pwm))], None)]

    def feel(self, index: int, t_s: float, pwm: Sequence[int]) -> None:
        self.pwm = [int(x) for x in pwm[: len(self.pwm)]]


class PipelinedPoses:
    """A closed-loop source that separates feeling from acting (``feel``/``act``, the
    virtual participant: docs/participant.md, "feel and act"), ``window`` POSEs in flight.

    Lockstep: ``quat_i = model.step(t_i, pwm of TELEMETRY i-1)``, which is
    ``model.feel(t_{i-1}, pwm of TELEMETRY i-1)`` then ``model.act(t_i)``. Here, in
    batches: the poses i .. i+window-1 are ``model.act(t)`` with the TELEMETRY up to i-1
    felt, the batch goes out in one write (:meth:`DeviceClient.pose_batch`), and each
    answer is felt as it comes, in order. The model guarantees that act(t) depends only
    on PWM felt a reaction time before t, so with window <= ``model.max_lead(rate)``
    every pose equals, bit for bit, the lockstep one, with one model step per pose and no
    copy; the device handles POSEs one after the other (the answer to one does not
    depend on the later ones), so it answers as in lockstep. An act() too far ahead
    raises the model's ``lag_error``, turned into :class:`Diverged`: a broken source
    cannot give a wrong record."""

    def __init__(
        self, model: Any, rate_hz: float, k: int, window: int, lag_error: type[BaseException]
    ):
        self.act = model.act
        self._feel = model.feel
        self.rate_hz = rate_hz
        self.k = k
        self.window = window
        self.lag_error = lag_error

    def next_batch(self, index: int) -> list[Pose]:
        batch: list[Pose] = []
        try:
            for j in range(index, index + self.window):
                t = j / self.rate_hz
                batch.append((t, tuple(map(float, self.act(t))), None))
        except self.lag_error as e:
            raise Diverged(f"pose {index + len(batch)} could not be acted ahead: {e}") from None
        return batch

    def feel(self, index: int, t_s: float, pwm: Sequence[int]) -> None:
        try:
            self._feel(t_s, pwm[: self.k])
        except ValueError as e:
            raise PoseLoopError(
                f"pose {index}: the model refused the TELEMETRY's PWM: {e}"
            ) from None


#: Most POSEs ever in flight.
MAX_PIPELINE = 32


def pipeline_window(model: Any, pose_rate_hz: float) -> int:
    """How many POSEs a closed-loop source may have in flight (1 = lockstep).

    A source that separates feeling from acting (callable ``feel``, ``act`` and
    ``max_lead``, like the virtual participant: docs/participant.md, "feel and act") is
    pipelined ``model.max_lead(pose_rate_hz)`` poses deep (at most MAX_PIPELINE); for
    the virtual participant floor(reaction_time_s * rate) - 1, 20 at 0.21 s and 100 Hz
    (its pose at t depends only on PWM felt a reaction time earlier). Any other source
    runs in lockstep."""
    if not all(callable(getattr(model, name, None)) for name in ("feel", "act", "max_lead")):
        return 1
    try:
        n = int(model.max_lead(float(pose_rate_hz)))
    except Exception:
        return 1
    return max(1, min(MAX_PIPELINE, n))


# --------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------
@dataclass(eq=False)
class PoseLoop:
    """Runs one started trial on ``client`` (see the module's docstring)."""

    client: Any
    virtual_clock: bool
    base_us: int = 0
    # Real time, open loop: each POSE is the newest pose due (see OpenLoopPoses.skip_stale):
    # a link slower than the source gets the freshest hand, never a growing queue.
    newest: bool = False
    limit_s: float | None = None
    wall_limit_s: float | None = None
    on_send: Callable[[int, float, Sequence[float], Any], None] | None = None
    on_frame: Callable[[Frame], None] | None = None
    # Each time ``newest`` skips poses: how many (the first call says the loop paces).
    on_skip: Callable[[int], None] | None = None
    # Once per batch: (index of its first pose, the poses sent, their TELEMETRY), for
    # the frames received (the batch's up to the one that ended the trial, or up to
    # the one the loop failed on); in order, after their on_frame, all before run()
    # returns or raises. A batch's call comes once the next batch's POSEs are written
    # (pipelined), so what it does (the frame CSV) overlaps the device's work.
    on_frames: Callable[[int, list[Stamped], list[Any]], None] | None = None
    sent: int = field(default=0, init=False)
    frames: int = field(default=0, init=False)
    skipped: int = field(default=0, init=False)
    wall0: float = field(default_factory=time.monotonic, init=False)

    def _stamp(self, t_s: float) -> int:
        """The POSE timestamp of trial time t_s, after waiting for it in real time."""
        if self.virtual_clock:
            return (self.base_us + int(round(t_s * 1e6))) & 0xFFFFFFFF
        wait = self.wall0 + t_s - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        return host_time_us()

    def _stamp_batch(self, batch: list[Pose]) -> list[Stamped]:
        """The batch's poses with their POSE timestamps, each given to on_send."""
        if self.virtual_clock:  # _stamp's arithmetic, for the whole batch at once
            base_us = self.base_us
            stamped = [
                (t, (base_us + int(round(t * 1e6))) & 0xFFFFFFFF, quat, contacts)
                for t, quat, contacts in batch
            ]
        else:
            stamped = [(t, self._stamp(t), quat, contacts) for t, quat, contacts in batch]
        if self.on_send is not None:
            for t, t_us, quat, contacts in stamped:
                self.on_send(t_us, t, quat, contacts)
        return stamped

    def _send(self, stamped: list[Stamped], on_written: Callable[[], None]) -> list[Any] | None:
        """The answers to the stamped poses, or None when the device refused the only one
        because the trial had already ended (its TRIAL_RESULT is queued). ``on_written``
        is called once the poses are written (pipelined) or before (one pose)."""
        client = self.client
        if len(stamped) > 1:
            answers = client.pose_batch(
                [(t_us, q) for _, t_us, q, _ in stamped], on_written=on_written
            )
            self.sent += len(stamped)
            return answers
        on_written()
        _, t_us, quat, contacts = stamped[0]
        try:
            tel = client.pose(t_us, quat, contacts)
        except DeviceError as e:
            client.drain(0.05)
            if e.code == ErrorCode.NOT_ALLOWED_IN_STATE and client.trial_results:
                self.sent += 1
                return None
            raise
        self.sent += 1
        return [tel]

    def run(self, poses: Any) -> LoopResult:
        """The trial until it ends or ``poses`` run out; raises PoseLoopError, LinkError."""
        client = self.client
        lockstep = poses.window <= 1
        on_frame = self.on_frame
        on_frames = self.on_frames
        feel = poses.feel
        running_flag = TELEMETRY_FLAG_TRIAL_RUNNING
        # trial time beyond which to give up, on the virtual clock (real time: the wall)
        limit_s = self.limit_s if self.virtual_clock and self.limit_s is not None else None
        index = 0
        t_s = 0.0
        last_tel = None
        ended = False
        # The frames of the batch before, for on_frames once the next batch is written.
        pending: list[tuple[int, list[Stamped], list[Any]]] = []
        pace = self.newest and not self.virtual_clock and hasattr(poses, "skip_stale")

        def write_pending() -> None:
            while pending:
                assert on_frames is not None  # only then is anything pending
                on_frames(*pending.pop(0))

        try:
            while not ended:
                if pace:
                    n = poses.skip_stale(time.monotonic() - self.wall0)
                    if n:
                        self.skipped += n
                        if self.on_skip is not None:
                            self.on_skip(n)
                batch = poses.next_batch(index)
                if not batch:
                    break
                stamped = self._stamp_batch(batch)
                answers = self._send(stamped, write_pending)
                if answers is None:
                    ended = True
                    break
                received = 0
                try:
                    for j, ((t_s, t_us, quat, contacts), tel) in enumerate(zip(stamped, answers)):
                        if isinstance(tel, Error):
                            raise PoseLoopError(
                                f"the device refused pose {index + j} "
                                f"({ErrorCode(tel.code).name.lower()}) while the trial was running"
                            )
                        received = j + 1
                        last_tel = tel
                        if on_frame is not None:
                            on_frame(Frame(index + j, t_s, t_us, quat, contacts, tel))
                        running = int(tel.flags) & running_flag
                        if not running or (lockstep and client.trial_results):
                            # The trial ended with this pose; the rest of the batch was refused.
                            for rest in answers[j + 1 :]:
                                if not isinstance(rest, Error):
                                    raise PoseLoopError(
                                        "the device answered a POSE after the trial ended"
                                    )
                            ended = True
                            break
                        if limit_s is not None:
                            if t_s > limit_s:
                                raise TrialOverrun(t_s, time.monotonic() - self.wall0, False)
                        elif self.wall_limit_s is not None and not self.virtual_clock:
                            wall = time.monotonic() - self.wall0
                            if wall > self.wall_limit_s:
                                raise TrialOverrun(t_s, wall, True)
                        feel(index + j, t_s, tel.pwm)
                finally:
                    self.frames += received
                    if on_frames is not None and received:
                        pending.append((index, stamped[:received], answers[:received]))
                index += len(batch)
        finally:
            write_pending()
        if ended and not client.trial_results:
            # the pose that ended the trial: its TRIAL_RESULT follows the TELEMETRY
            try:
                client.trial_results.appendleft(client.wait_trial_result(client.timeout))
            except LinkTimeout:
                pass
        if not client.trial_results:
            client.drain(0.05)
        result = client.trial_results.popleft() if client.trial_results else None
        return LoopResult(result, self.frames, self.sent, self.skipped, t_s, last_tel, ended)


__all__ = [
    "PoseLoop",
    "PoseLoopError",
    "TrialOverrun",
    "Diverged",
    "Frame",
    "Stamped",
    "LoopResult",
    "OpenLoopPoses",
    "LockstepPoses",
    "PipelinedPoses",
    "pipeline_window",
    "MAX_PIPELINE",
]
