"""What a run records with ``--record FILE.xdf`` (docs/lab-streams.md, "Recording and
replaying as XDF"): three streams in one XDF file (:mod:`graspguide.records.xdf_writer`),
on one clock, the poses' trial time:

* ``NAME-Hand`` (type MoCap, double64): each POSE as the host sent it -- the hand's
  orientation ``qw, qx, qy, qz`` (hand -> world, this project's world: z up, right-handed)
  and, when the source gives contacts, ``thumb_x .. palm_z`` (metres, hand frame). Doubles,
  so that ``--source replay:FILE.xdf`` sends the very same POSEs again.
* ``NAME-Telemetry`` (type GraspGuide, float32): each TELEMETRY, the channels of the LSL
  outlet (:data:`graspguide.sources.lab_streams.TELEMETRY_CHANNELS`).
* ``NAME-Markers`` (type Markers, string): the run's events as the LSL outlet writes them
  (:func:`graspguide.sources.lab_streams.marker_text`).

Timestamps: a POSE's is its ``t_s`` (the source's time from its start, the time the
POSE's device timestamp is made of); a TELEMETRY's is the ``t_s`` of the POSE it answers;
a marker's is the ``t_s`` of the last POSE sent before it (0 before the first). Every
stream has one ClockOffset of 0: they share this clock, and pyxdf's clock
synchronisation leaves the timestamps exactly as written. A run of several trials
(`graspguide trial`) records on :data:`SESSION_CLOCK` instead: each trial's times from
its start offset on (:meth:`XdfRecorder.on_trial_clock`).

:class:`XdfRecorder` is a :class:`graspguide.records.events.TrialObserver` with one more
hook, :meth:`XdfRecorder.on_pose`, which the pose loop's ``on_send`` calls.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from graspguide.core.vocabulary import FINGERS
from graspguide.records.xdf_writer import Channel, XdfWriter
from graspguide.sources.lab_streams import (
    MARKER_TYPE,
    TELEMETRY_CHANNELS,
    TELEMETRY_TYPE,
    marker_text,
    source_id,
)

MOCAP_TYPE = "MoCap"
#: The pose stream's orientation channels: (label, unit, type).
QUAT_CHANNELS: tuple[tuple[str, str, str], ...] = tuple(
    (f"q{c}", "normalized", f"Orientation{c.upper()}") for c in "wxyz"
)
#: The contact channels, finger by finger (the first 3 or 4 fingers are recorded).
CONTACT_CHANNELS: tuple[tuple[str, str, str], ...] = tuple(
    (f"{finger}_{axis}", "meters", f"Position{axis.upper()}")
    for finger in FINGERS
    for axis in "xyz"
)
#: What the pose stream's values mean (its ``<desc><frames>``).
HAND_FRAMES = {
    "orientation": "unit quaternion w, x, y, z of the hand -> world rotation; world: "
    "z up, right-handed (gravity along -z)",
    "positions": "contact points in meters in the hand frame (thumb, index, middle, palm)",
}
CLOCK_NAME = "trial_time"
CLOCK_TEXT = (
    "seconds from the start of the pose source (the POSE's t_s; the device timestamp of "
    "a POSE is this time in microseconds on --virtual-clock); a TELEMETRY is stamped with "
    "the t_s of the POSE it answers, a marker with the t_s of the last POSE sent before it"
)
#: `graspguide trial`'s clock (name, description): its t_s restarts every trial, so the
#: streams share a session clock instead.
SESSION_CLOCK = (
    "session_time",
    "seconds on the run's session clock: a trial's start offset plus the POSE's t_s (the "
    "trial's time, which restarts every trial: the frames files' t_s and the TELEMETRY's "
    "trial_time_s channel). The offset: on the virtual clock (--port sim, a simulated "
    "source) the device's time base of the trial (a POSE's device timestamp is the "
    "session time in microseconds, modulo 2^32; each trial starts at least 1 s after the last "
    "pose of the one before); in real time the host's monotonic time of the trial's "
    "start since the run began. A TELEMETRY is stamped with the time of the POSE it "
    "answers, a trial_start marker with its trial's start offset, any other marker with "
    "the time of the last POSE sent before it (0 before the first)",
)


class XdfRecorder:
    """The XDF recording of one run; a context manager and a TrialObserver.

    ``name`` prefixes the streams' names as ``--lsl`` does; ``nominal_rate_hz`` is the
    pose rate (0: irregular, as on the virtual clock); ``simulated``, ``participant``,
    ``session`` and ``extra`` go to each stream's ``<desc><acquisition>``. The pose
    stream's header is written with the first pose, when it is known whether the source
    gives contacts and of how many fingers."""

    def __init__(
        self,
        path: str,
        name: str = "GraspGuide",
        *,
        participant: str = "",
        session: str = "",
        nominal_rate_hz: float = 0.0,
        simulated: bool = False,
        extra: dict[str, Any] | None = None,
        clock: tuple[str, str] = (CLOCK_NAME, CLOCK_TEXT),
    ):
        self.path = path
        self.clock_name, self.clock_text = clock
        self.name = name
        self.participant = participant
        self.session = session
        self.nominal_rate_hz = float(nominal_rate_hz) if math.isfinite(nominal_rate_hz) else 0.0
        self.simulated = simulated
        self.extra = {str(k): str(v) for k, v in (extra or {}).items()}
        self.writer = XdfWriter(path, header={"recorder": "graspguide", "clock": self.clock_name})
        self.now_s = 0.0
        # added to every t_s given (on_trial_clock): 0 for one trial, as `stream` records
        self.offset_s = 0.0
        self.poses = self.samples = self.markers = 0
        self._contact_fingers = 0
        self._hand_id: int | None = None
        self.telemetry_id = self._add(
            "Telemetry", TELEMETRY_TYPE, TELEMETRY_CHANNELS, "float32", self.nominal_rate_hz
        )
        self.marker_id = self._add(
            "Markers", MARKER_TYPE, (("event_json", "json", "Marker"),), "string", 0.0
        )

    def _add(self, kind: str, type_: str, channels, fmt: str, rate: float, **desc: Any) -> int:
        acquisition: dict[str, Any] = {
            "manufacturer": "GraspGuide",
            "participant": self.participant,
            "session": self.session,
            "simulated": "true" if self.simulated else "false",
            **self.extra,
        }
        stream_id = self.writer.add_stream(
            f"{self.name}-{kind}",
            type_,
            [Channel(*c) for c in channels],
            fmt,
            rate,
            source_id=source_id(self.name, self.participant, self.session, kind.lower()),
            created_at=self.now_s,
            desc={
                "clock": {
                    "name": self.clock_name,
                    "unit": "seconds",
                    "description": self.clock_text,
                },
                "acquisition": acquisition,
                **desc,
            },
        )
        # one offset of 0: the streams share this clock (pyxdf then adds exactly 0)
        self.writer.write_clock_offset(stream_id, self.now_s, 0.0)
        return stream_id

    # ---- the poses
    def on_pose(self, t_s: float, quat: Sequence[float], contacts: Any) -> None:
        """A POSE as sent: ``t_s``, the orientation w, x, y, z, the contacts or None."""
        if self._hand_id is None:
            self._contact_fingers = 0 if contacts is None else min(len(contacts), len(FINGERS))
            channels = QUAT_CHANNELS + CONTACT_CHANNELS[: 3 * self._contact_fingers]
            self._hand_id = self._add(
                "Hand", MOCAP_TYPE, channels, "double64", self.nominal_rate_hz, frames=HAND_FRAMES
            )
        values = [float(x) for x in quat]
        if self._contact_fingers:
            if contacts is None:
                values += [math.nan] * (3 * self._contact_fingers)
            else:
                # a pose with fewer contacts than the first: the missing ones are NaN
                for i in range(self._contact_fingers):
                    p = contacts[i] if i < len(contacts) else (math.nan,) * 3
                    values += [float(x) for x in p]
        self.now_s = self.offset_s + float(t_s)
        self.writer.push(self._hand_id, self.now_s, values)
        self.poses += 1

    def on_trial_clock(self, offset_s: float) -> None:
        """A trial starts ``offset_s`` into the session: its t_s are recorded from there,
        and a marker from now on is stamped no earlier (never back in time)."""
        self.offset_s = float(offset_s)
        self.now_s = max(self.now_s, self.offset_s)

    # ---- TrialObserver
    def on_event(self, name: str, **fields: Any) -> None:
        self.writer.push(self.marker_id, self.now_s, [marker_text(name, fields)])
        self.markers += 1

    def on_telemetry(
        self, t_s: float, error_deg: float, alpha: float, pwm: Sequence[int], status: int
    ) -> None:
        duty = [float(x) for x in pwm[: len(FINGERS)]]
        duty += [0.0] * (len(FINGERS) - len(duty))
        self.writer.push(
            self.telemetry_id,
            self.offset_s + float(t_s),
            [float(error_deg), float(alpha), *duty, float(int(status)), float(t_s)],
        )
        self.samples += 1

    # ---- lifetime
    def close(self) -> None:
        """The buffered samples and every stream's footer; the file is complete."""
        self.writer.close()

    def __enter__(self) -> XdfRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = [
    "XdfRecorder",
    "MOCAP_TYPE",
    "QUAT_CHANNELS",
    "CONTACT_CHANNELS",
    "CLOCK_NAME",
    "SESSION_CLOCK",
]
