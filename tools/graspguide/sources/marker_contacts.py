"""Fingertip contacts from motion-capture markers, sample by sample.

A tracker gives the hand's rigid body (position ``t`` and orientation ``R``, hand ->
world) and the world positions ``p`` of the fingertip markers. The contacts the device
needs are in the hand frame: ``c = R^T (p - t)`` (both already in this project's world,
:class:`graspguide.sources.poses.TrackerConvention`).

Two rules shape what is sent (docs/lab-streams.md, "LSL MoCap source"):

* **Hold, then pause.** A marker that is lost (a NaN coordinate, or flagged occluded by
  the tracker) keeps its last hand-frame position for at most ``hold_s`` seconds of
  sample time after its last valid sample: the contacts stay whole. Past that the
  sample is *paused*: it has no contacts, and the source sends no POSE for it (the
  device's watchdog turns the motors off). When the marker is seen again the contacts
  resume from its new position. A lost marker is never given a made-up position, so a
  contact never jumps to NaN, zero or a guess.
* **Per-posture re-run.** The device re-runs its per-posture work (the grasp matrix, the
  force distribution) each time a POSE carries contacts. :class:`RerunRule` sends the
  contacts only when one of them moved more than ``tol_m`` from the contacts last sent;
  otherwise the POSE carries none and the device keeps the last ones. Marker noise and
  tremor below the tolerance cost nothing; a real change of grasp is sent.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from graspguide.core.rotations import quat_to_matrix

#: The states of a sample (:attr:`ContactsUpdate.state`).
TRACKED, HELD, PAUSED = "tracked", "held", "paused"


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

    def __init__(self, names: Sequence[str], hold_s: float = 0.2):
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

    def __init__(self, tol_m: float = 0.001):
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


__all__ = [
    "TRACKED",
    "HELD",
    "PAUSED",
    "ContactsUpdate",
    "MarkerContacts",
    "RerunRule",
    "hand_frame",
]
