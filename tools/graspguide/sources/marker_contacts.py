"""Fingertip contacts from motion-capture markers, sample by sample.

A tracker gives the hand's rigid body (position ``t`` and orientation ``R``, hand ->
world) and the world positions ``p`` of the fingertip markers. The contacts the device
needs are in the hand frame: ``c = R^T (p - t)`` (both already in this project's world,
:class:`graspguide.sources.poses.TrackerConvention`).

Three rules shape what is sent (docs/lab-streams.md, "LSL MoCap source"; docs/trackers.md
for NatNet); :class:`HandTracking` applies them for every live tracker source, so a lost
marker or rigid body is treated the same whatever the tracker:

* **Hold, then pause.** A marker that is lost (a NaN coordinate, or flagged occluded by
  the tracker) keeps its last hand-frame position for at most ``hold_s`` seconds of
  sample time after its last valid sample: the contacts stay whole. Past that the
  sample is *paused*: it has no contacts, and the source sends no POSE for it (the
  device's watchdog turns the motors off). When the marker is seen again the contacts
  resume from its new position. A lost marker is never given a made-up position, so a
  contact never jumps to NaN, zero or a guess.
* **The rigid body, the same way.** A lost hand pose (a NaN, a zero quaternion, the
  tracker's tracking-valid flag off) is replaced by the last valid one for at most
  ``hold_s``; the markers cannot be put in the hand frame meanwhile, so they count as
  lost and hold their last hand-frame positions. Past ``hold_s`` the sample is paused.
  Before the body and every marker have been seen once, nothing is sent either.
* **Per-posture re-run.** The device re-runs its per-posture work (the grasp matrix, the
  force distribution) each time a POSE carries contacts. :class:`RerunRule` sends the
  contacts only when one of them moved more than ``tol_m`` from the contacts last sent;
  otherwise the POSE carries none and the device keeps the last ones. Marker noise and
  tremor below the tolerance cost nothing; a real change of grasp is sent. The default,
  2 mm, sits above what 0.3 mm per axis of marker noise makes two samples differ by
  (about 0.7 mm, rarely 2 mm): at 1 mm the noise alone re-runs the work on about
  half the samples. The guidance error does not use the contacts (only the motor
  pattern does), so 2 mm of contact staleness does not move the error the trial sees.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from graspguide.core.rotations import quat_to_matrix
from graspguide.link.messages import POSE_WATCHDOG_MS
from graspguide.sources.poses import Sample

#: The states of a sample (:attr:`ContactsUpdate.state`).
TRACKED, HELD, PAUSED = "tracked", "held", "paused"
#: How long a lost marker or rigid body is bridged by default: a few frames at a
#: tracker's usual 100-240 Hz, short enough that the hand cannot turn far meanwhile.
DEFAULT_HOLD_S = 0.2
#: The per-posture re-run tolerance by default (module docstring).
DEFAULT_TOL_MM = 2.0


@dataclass(frozen=True)
class ContactsUpdate:
    """One sample's contacts: ``state`` is TRACKED (every marker seen), HELD (some marker
    lost for at most hold_s: its last hand-frame position stands in) or PAUSED (a marker
    lost for longer: ``contacts`` is None and nothing may be sent); ``lost`` names the
    markers not seen in this sample, ``lost_for_s`` how long the longest-lost one has
    been gone (0 when none is)."""

    state: str
    contacts: list[list[float]] | None
    lost: tuple[str, ...]
    lost_for_s: float


def hand_frame(quat_wxyz: Sequence[float], position: Sequence[float], points) -> np.ndarray:
    """``R^T (p - t)`` for each row p of ``points`` (world, metres): the points in the
    hand frame of the pose (quat_wxyz, position)."""
    r = quat_to_matrix(quat_wxyz)
    return (np.asarray(points, dtype=float) - np.asarray(position, dtype=float)) @ r


class MarkerContacts:
    """Hand-frame contacts of ``names`` (the markers in the device's contact order:
    thumb, index, middle[, palm]) under the hold rule (module docstring)."""

    def __init__(self, names: Sequence[str], hold_s: float = DEFAULT_HOLD_S):
        if not 3 <= len(names) <= 4:
            raise ValueError(
                f"3 or 4 markers are contacts (thumb, index, middle[, palm]), got {list(names)}"
            )
        if not (math.isfinite(hold_s) and hold_s >= 0):
            raise ValueError(f"hold must be >= 0 s, got {hold_s}")
        self.names = tuple(names)
        self.hold_s = float(hold_s)
        self._last = np.full((len(names), 3), np.nan)  # last valid hand-frame positions
        self._seen_t = np.full(len(names), -math.inf)  # their sample times
        self.samples = 0
        self.held = 0
        self.paused = 0
        self.pauses = 0  # pause episodes
        self._was_paused = False

    def unseen(self) -> tuple[str, ...]:
        """The markers never seen yet."""
        return tuple(n for n, t in zip(self.names, self._seen_t) if t == -math.inf)

    def overdue(self, t_s: float) -> tuple[str, ...]:
        """The markers last seen more than hold_s before ``t_s`` (or never)."""
        return tuple(n for n, t in zip(self.names, self._seen_t) if not t_s - t <= self.hold_s)

    def update(
        self,
        t_s: float,
        quat_wxyz: Sequence[float],
        position: Sequence[float],
        markers,
        occluded: Sequence[bool] | None = None,
    ) -> ContactsUpdate:
        """The contacts of one sample: the hand pose (world) and each marker's world
        position (k x 3, metres; NaN when lost), ``occluded`` the tracker's own flags."""
        p = np.asarray(markers, dtype=float).reshape(len(self.names), 3)
        valid = np.all(np.isfinite(p), axis=1)
        if occluded is not None:
            valid &= ~np.asarray(occluded, dtype=bool)
        if valid.any():
            c = hand_frame(quat_wxyz, position, p[valid])
            self._last[valid] = c
            self._seen_t[valid] = t_s
        self.samples += 1
        lost = tuple(n for n, v in zip(self.names, valid) if not v)
        lost_for = float(max(t_s - self._seen_t[~valid])) if lost else 0.0
        if lost and not lost_for <= self.hold_s:  # never seen yet: inf, paused
            self.paused += 1
            if not self._was_paused:
                self.pauses += 1
            self._was_paused = True
            return ContactsUpdate(PAUSED, None, lost, lost_for)
        self._was_paused = False
        if lost:
            self.held += 1
        contacts = [[float(x) for x in row] for row in self._last]
        return ContactsUpdate(HELD if lost else TRACKED, contacts, lost, lost_for)


class RerunRule:
    """The per-posture re-run rule: :meth:`choose` gives the contacts to send with a POSE
    (the first ones, then only when some contact moved more than ``tol_m`` from those
    last sent) or None (the device keeps the last ones)."""

    def __init__(self, tol_m: float = DEFAULT_TOL_MM / 1000.0):
        if not (math.isfinite(tol_m) and tol_m >= 0):
            raise ValueError(f"the re-run tolerance must be >= 0, got {tol_m}")
        self.tol_m = float(tol_m)
        self.sent: np.ndarray | None = None
        self.poses = 0  # POSEs this rule decided for
        self.reruns = 0  # of which carried contacts
        self.first_t: float | None = None
        self.last_t: float | None = None

    def moved_m(self, contacts) -> float:
        """How far the contact that moved most is from the contacts last sent (inf before
        any was sent)."""
        if self.sent is None:
            return math.inf
        c = np.asarray(contacts, dtype=float)
        return float(np.max(np.linalg.norm(c - self.sent, axis=1)))

    def choose(self, t_s: float, contacts) -> list[list[float]] | None:
        self.poses += 1
        self.first_t = t_s if self.first_t is None else self.first_t
        self.last_t = t_s
        if contacts is None or not self.moved_m(contacts) > self.tol_m:
            return None
        self.sent = np.array(contacts, dtype=float)
        self.reruns += 1
        return [list(map(float, row)) for row in contacts]

    def stats(self) -> dict[str, float | int]:
        """POSEs, re-runs (POSEs with contacts), re-runs per second of sample time and
        per 100 POSEs."""
        span = 0.0
        if self.first_t is not None and self.last_t is not None:
            span = self.last_t - self.first_t
        return {
            "poses": self.poses,
            "reruns": self.reruns,
            "reruns_per_s": self.reruns / span if span > 0 else float("nan"),
            "reruns_per_100": 100.0 * self.reruns / self.poses if self.poses else float("nan"),
            "tol_mm": self.tol_m * 1000.0,
        }


#: A hand pose: (quat_wxyz, position), hand -> world, in this project's world.
Pose = tuple[Sequence[float], Sequence[float]]


class HandTracking:
    """The per-sample rule of a live tracker source (module docstring): the rigid body's
    pose and the markers in, the sample to send out, or None while nothing may be sent.

    ``markers``: the marker names in the device's contact order (empty: poses only);
    ``body``: the rigid body's name in the notices; ``say``: where the one-line notices
    go. Each pause, whatever its cause, is said once when it begins and once when it ends;
    waiting for a first sight is said once. :meth:`update` takes every sample (its time
    in seconds on the tracker's clock), :meth:`send` the ones the source sends, which it
    passes through the re-run rule.
    """

    def __init__(
        self,
        markers: Sequence[str],
        body: str,
        say: Callable[[str], None],
        hold_s: float = DEFAULT_HOLD_S,
        tol_m: float = DEFAULT_TOL_MM / 1000.0,
    ):
        self.contacts = MarkerContacts(markers, hold_s) if markers else None
        self.rule = RerunRule(tol_m)
        self.body = body
        self.say = say
        self.hold_s = float(hold_s)
        self._pose: tuple[tuple[float, float, float, float], tuple[float, ...]] | None = None
        self._pose_t = -math.inf
        self._paused = False
        self._waiting_said = False
        self.counts = {
            "samples": 0,
            "waiting": 0,  # before the body and every marker were seen once
            "body_lost": 0,  # the pose was not valid (held or paused)
            "held": 0,  # the last pose or a marker's last contact stood in
            "paused": 0,
            "pauses": 0,  # pause episodes
        }

    def unseen(self) -> tuple[str, ...]:
        """What was never seen yet: ``rigid body NAME``, ``marker NAME``."""
        body = () if self._pose is not None else (f"rigid body {self.body}",)
        names = self.contacts.unseen() if self.contacts is not None else ()
        return body + tuple(f"marker {n}" for n in names)

    def update(
        self,
        t_s: float,
        pose: Pose | None,
        markers=None,
        occluded: Sequence[bool] | None = None,
    ) -> Sample | None:
        """One sample: ``pose`` (None when the tracker lost the rigid body), the markers'
        world positions (k x 3, metres; NaN or None when lost) and the tracker's occlusion
        flags. The sample to send, with every contact (its time still ``t_s``), or None
        (waiting, paused)."""
        c = self.counts
        c["samples"] += 1
        if pose is not None:
            w, x, y, z = map(float, pose[0])
            self._pose = ((w, x, y, z), tuple(map(float, pose[1])))
            self._pose_t = t_s
        else:
            c["body_lost"] += 1
        if self._pose is None:
            return self._wait()
        body_for = t_s - self._pose_t
        if not body_for <= self.hold_s:
            return self._pause(f"rigid body {self.body} lost for more than {self.hold_s:g} s")
        quat, position = self._pose
        held = pose is None
        contacts = None
        if self.contacts is not None:
            k = len(self.contacts.names)
            if pose is None or markers is None:
                # a stale pose would put a seen marker at a wrong hand-frame position
                markers, occluded = np.full((k, 3), np.nan), None
            upd = self.contacts.update(t_s, quat, position, markers, occluded)
            if self.contacts.unseen():
                return self._wait()
            if upd.state == PAUSED:
                lost = ", ".join(self.contacts.overdue(t_s))
                return self._pause(f"marker {lost} lost for more than {self.hold_s:g} s")
            held = held or upd.state == HELD
            contacts = upd.contacts
        if self._paused:
            self._paused = False
            seen = "and every marker " if self.contacts is not None else ""
            self.say(f"rigid body {self.body} {seen}seen again: POSEs resume")
        c["held"] += held
        return (t_s, quat, contacts)

    def new_run(self) -> None:
        """A new run of POSEs begins (a source iterated again, as for each trial): its first
        POSE carries the contacts whatever was sent before, as the device may not hold
        them any more."""
        self.rule.sent = None

    def send(self, t_s: float, sample: Sample) -> Sample:
        """What the source yields for a sample of :meth:`update` it sends, at ``t_s`` (its
        time from the first one sent): the contacts only when the re-run rule says so
        (always None without markers)."""
        return (t_s, sample[1], self.rule.choose(t_s, sample[2]))

    def stats(self) -> dict[str, float | int]:
        """The counts (samples, waiting, body_lost, held, paused, pauses) and the POSEs
        sent; with markers the re-runs too (:meth:`RerunRule.stats`)."""
        out: dict[str, float | int] = dict(self.counts)
        out["poses"] = self.rule.poses
        if self.contacts is not None:
            out.update(self.rule.stats())
        return out

    def _wait(self) -> None:
        self.counts["waiting"] += 1
        if not self._waiting_said:
            self._waiting_said = True
            self.say(
                f"waiting for the first sight of {', '.join(self.unseen())}: no POSE sent "
                "until then"
            )
        return None

    def _pause(self, why: str) -> None:
        self.counts["paused"] += 1
        if not self._paused:
            self._paused = True
            self.counts["pauses"] += 1
            self.say(
                f"{why}: paused, no POSE sent (the device's watchdog turns the motors off "
                f"{POSE_WATCHDOG_MS} ms after the last POSE) until it is seen again"
            )
        return None


__all__ = [
    "TRACKED",
    "HELD",
    "PAUSED",
    "DEFAULT_HOLD_S",
    "DEFAULT_TOL_MM",
    "ContactsUpdate",
    "HandTracking",
    "MarkerContacts",
    "Pose",
    "RerunRule",
    "hand_frame",
]
