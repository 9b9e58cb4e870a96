"""Pose sources for `graspguide stream`: each yields samples ``(t_s, quat_wxyz,
contacts_or_None)`` -- time in seconds from the source's start, the hand -> world
orientation as a unit quaternion [w, x, y, z] in this project's world (z up,
right-handed), and optionally the contacts (metres, hand frame) -- at the source's rate.

Spec strings (:func:`graspguide.sources.source_spec.open_source`):

* ``replay:FILE.csv`` -- a recorded stream. A header line is required and names the
  columns: ``t_s,qw,qx,qy,qz`` and optionally ``thumb_x,thumb_y,thumb_z,index_x,index_y,
  index_z,middle_x,middle_y,middle_z[,palm_x,palm_y,palm_z]`` (metres, hand frame). The
  ``poses.csv`` that ``graspguide stream --log DIR`` writes is such a file (its own
  columns send_time_s, host_time_us and has_contacts are read past), and ``replay:DIR``
  reads DIR/poses.csv: a logged session replays the poses it sent, at their times.
  Values are in this project's world convention (convert tracker data first, see
  :class:`TrackerConvention`). ``t_s`` must increase. Errors name the file and line.
* ``synthetic[:rate=240,duration=10,seed=0]`` -- a scripted hand: from a start orientation
  (seeded: tilted 40..80 degrees about a horizontal axis, so
  the force starts that far off gravity) it turns smoothly (minimum-jerk profile over 60 % of the
  duration) to the orientation that aligns the scene's force with gravity, then holds it,
  with a small physiological tremor (~0.3 degrees at 8-12 Hz plus noise) all along.
  Deterministic for a seed. Needs the scene and wrench (:meth:`SyntheticSource.aim`) to
  know the target; without them it turns towards the identity.

Tracker conventions (:class:`TrackerConvention`, :data:`TRACKER_PRESETS`) convert a
tracker's positions and quaternions to the world here: metres, z up, right-handed,
quaternion order w, x, y, z. The presets are typical defaults; verify against your
tracker's settings (units, up axis and quaternion order are configurable in most of them).

A tracker adapter (:class:`TrackerAdapter`) declares its :class:`TrackerConvention` and
yields raw samples in the tracker's own units, axes and quaternion order; the base class
converts every sample, so no adapter ever does its own axis arithmetic.
"""

from __future__ import annotations

import csv
import importlib
import math
import os
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from graspguide.core.rotations import (
    matrix_to_quat,
    quat_angle_deg,
    quat_from_axis_angle,
    quat_mul,
    quat_to_matrix,
    slerp,
)
from graspguide.core.vocabulary import FINGERS
from graspguide.records.files import SESSION_POSES_FILE

Sample = tuple[float, tuple[float, float, float, float], list[list[float]] | None]
QUAT_COLUMNS = ["t_s", "qw", "qx", "qy", "qz"]


class SourceError(ValueError):
    """A pose source that cannot be used (bad spec, bad file); says what to fix."""


#: Every ``--source`` kind and how it is written: the one list `stream` and `trial` show.
SOURCE_KINDS: dict[str, str] = {
    "replay": "replay:FILE.csv|FILE.xdf",
    "lsl": "lsl:name=NAME,type=MoCap,source_id=ID",
    "natnet": "natnet:server=IP,body=NAME",
    "synthetic": "synthetic[:rate=240,duration=10,seed=0]",
    "plugin": "plugin:MODULE:CLASS[:ARG]",
    "participant": "participant[:KEY=VALUE,...]",
}
#: The options of ``synthetic:...`` and how each is read.
SYNTHETIC_OPTIONS = {"rate": float, "duration": float, "seed": int, "tremor_deg": float}


def unknown_source(spec: str) -> SourceError:
    """The error for a ``--source`` whose kind is none of SOURCE_KINDS: every kind, the
    closest one, and where a tracker's name goes instead."""
    from graspguide.core.suggest import unknown_name

    kind = spec.partition(":")[0]
    text = unknown_name("source", kind, list(SOURCE_KINDS))
    text += "; written " + ", ".join(SOURCE_KINDS.values())
    if kind.lower() in TRACKER_PRESETS:
        text += (
            f"; {kind} is a tracker convention: replay its export with --source "
            f"replay:FILE.csv --tracker {kind.lower()}, or stream it live with "
            "--source plugin:MODULE:CLASS (a TrackerAdapter)"
        )
    return SourceError(text)


# --------------------------------------------------------------------------------------
# Tracker conventions
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrackerConvention:
    """How a tracker reports poses: ``units`` "m"/"mm", ``up_axis`` "y"/"z", ``handedness``
    "right"/"left", ``quat_order`` "wxyz"/"xyzw".

    Conversion to this project's world (m, z up, right-handed, w, x, y, z): positions
    ``p_w = M p_t / scale``; orientations ``R_w = M R_t M^T`` -- the world *and* the
    tracked body's axes get the same axis change, so a rotation about the tracker's up
    axis becomes a rotation about world z. ``M``: identity for z-up, a +90 degree turn
    about x for y-up (tracker y -> world z, tracker z -> world -y); for left-handed
    trackers the axis that is neither x nor up is mirrored first.
    """

    units: str = "m"
    up_axis: str = "z"
    handedness: str = "right"
    quat_order: str = "wxyz"

    def __post_init__(self):
        for name, value, allowed in (
            ("units", self.units, ("m", "mm")),
            ("up_axis", self.up_axis, ("y", "z")),
            ("handedness", self.handedness, ("right", "left")),
            ("quat_order", self.quat_order, ("wxyz", "xyzw")),
        ):
            if value not in allowed:
                raise SourceError(
                    f"TrackerConvention {name} must be one of {allowed}, got {value!r}"
                )

    @property
    def matrix(self) -> np.ndarray:
        mirror = np.eye(3)
        if self.handedness == "left":
            mirror[2 if self.up_axis == "y" else 1, 2 if self.up_axis == "y" else 1] = -1
        if self.up_axis == "z":
            up = np.eye(3)
        else:
            up = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
        return up @ mirror

    def position(self, p: Sequence[float]) -> list[float]:
        scale = 1000.0 if self.units == "mm" else 1.0
        return list(self.matrix @ (np.asarray(p, dtype=float) / scale))

    def quaternion(self, q: Sequence[float]) -> tuple[float, float, float, float]:
        a = np.asarray(q, dtype=float)
        if a.shape != (4,):
            raise SourceError(f"a quaternion has 4 components, got {list(a)}")
        wxyz = a if self.quat_order == "wxyz" else np.array([a[3], a[0], a[1], a[2]])
        m = self.matrix
        w, x, y, z = (float(v) for v in matrix_to_quat(m @ quat_to_matrix(wxyz) @ m.T))
        return w, x, y, z

    def describe(self) -> dict[str, str]:
        return asdict(self)

    def convert(self, q, positions=None):
        """(quat_wxyz, positions in metres, world axes) from the tracker's values."""
        return (
            self.quaternion(q),
            None if positions is None else [self.position(p) for p in positions],
        )


WORLD = TrackerConvention("m", "z", "right", "wxyz")
# Typical defaults; verify against your tracker's settings. Sources and what each fact rests
# on, confirmed or not: docs/trackers.md.
TRACKER_PRESETS: dict[str, TrackerConvention] = {
    # Vicon (Nexus/Tracker, DataStream SDK): mm, z up, right-handed, x,y,z,w -- the SDK's
    # Output_GetSegmentGlobalRotationQuaternion has Rotation[4]; the order and units are
    # not confirmed in a vendor page found here.
    "vicon": TrackerConvention("mm", "z", "right", "xyzw"),
    # OptiTrack Motive, NatNet: right-handed y up (Motive docs, Data Export: "Y-up
    # right-hand"), Streaming pane's Up Axis default; x,y,z,w (NatNet SDK NatNetClient.py
    # unpacks qx,qy,qz,qw); metres (the SDK's layout; not confirmed in a vendor page).
    "optitrack": TrackerConvention("m", "y", "right", "xyzw"),
    # Motive streaming with Up Axis = Z Up (Data Streaming pane).
    "motive-zup": TrackerConvention("m", "z", "right", "xyzw"),
    # Leap Motion / Ultraleap: mm, y up, right-handed (LeapC 4.1 "Leap Concepts",
    # Coordinate System); x,y,z,w is LEAP_QUATERNION's field order, not confirmed here.
    "leap": TrackerConvention("mm", "y", "right", "xyzw"),
    # Qualisys QTM: mm, z up by default (its calibration sets the axes), right-handed; QTM
    # gives a rotation matrix, not a quaternion (QTM manual, Rotation angle calculations):
    # write it as w,x,y,z.
    "qualisys": TrackerConvention("mm", "z", "right", "wxyz"),
    # Xsens MTi: ENU, z up, right-handed (MTi Family Reference Manual 4.2.3); quaternion
    # q0 (real) first (MTi and MTx User Manual 4.3.1); no positions (metres if added).
    "xsens": TrackerConvention("m", "z", "right", "wxyz"),
    "world": WORLD,
}


# --------------------------------------------------------------------------------------
# Sources
# --------------------------------------------------------------------------------------
class Source:
    """Iterable of samples; ``rate_hz`` is the nominal rate (None if unknown);
    ``simulated``: the poses do not come from a live person (a scripted hand, a replayed
    file), see :func:`graspguide.sources.trial_sources.simulation`."""

    name = "source"
    rate_hz: float | None = None
    simulated = True
    # A live source yields each sample when it happens (a tracker); the others have
    # their samples at hand, so a link slower than them can be sent the newest one due.
    live = False

    def __iter__(self) -> Iterator[Sample]:  # pragma: no cover - interface
        raise NotImplementedError

    def describe(self) -> dict[str, object]:
        return {"source": self.name, "rate_hz": self.rate_hz}


class ReplaySource(Source):
    name = "replay"

    def __init__(self, path: str, convention: TrackerConvention | None = None):
        self.path = path
        self.convention = convention
        self.samples = self._load(path, convention or WORLD)
        dts = np.diff([s[0] for s in self.samples])
        self.rate_hz = float(1.0 / np.median(dts)) if len(dts) and np.median(dts) > 0 else None

    @staticmethod
    def _load(path: str, convention: TrackerConvention) -> list[Sample]:
        if os.path.isdir(path):  # a `graspguide stream --log` session folder
            path = os.path.join(path, SESSION_POSES_FILE)
        try:
            f = open(path, newline="", encoding="utf-8")
        except OSError as e:
            raise SourceError(f"replay: cannot read {path}: {e.strerror}") from None
        with f:
            reader = csv.reader(f)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise SourceError(
                    f"{path}: empty file; the first line must be the header "
                    f"{','.join(QUAT_COLUMNS)}[,thumb_x,...]"
                ) from None
            cols = _replay_columns(path, header)
            k = len(cols.contacts) // 3
            samples: list[Sample] = []
            last_t = -math.inf
            for row in reader:
                line = reader.line_num
                if not row or all(not c.strip() for c in row):
                    continue
                if len(row) != len(header):
                    raise SourceError(
                        f"{path}:{line}: {len(row)} values, the header has {len(header)}"
                    )
                try:
                    all_vals = [float(c) for c in row]
                except ValueError:
                    bad = next(c for c in row if not _is_float(c))
                    raise SourceError(f"{path}:{line}: not a number: {bad!r}") from None
                vals = [all_vals[i] for i in cols.quat + cols.contacts]
                if not all(math.isfinite(v) for v in vals):
                    raise SourceError(f"{path}:{line}: values must be finite")
                if cols.has_contacts is not None and all_vals[cols.has_contacts]:
                    raise SourceError(
                        f"{path}:{line}: this POSE carried contacts (has_contacts=1), which "
                        "a session log does not keep: it cannot be replayed as it ran; "
                        "replay a file with the contact columns (thumb_x,...) instead"
                    )
                t, q = vals[0], vals[1:5]
                if t <= last_t:
                    raise SourceError(f"{path}:{line}: t_s must increase ({t} after {last_t})")
                n = math.sqrt(sum(x * x for x in q))
                if abs(n - 1) > 1e-3:
                    raise SourceError(
                        f"{path}:{line}: the quaternion qw,qx,qy,qz is not "
                        f"unit length (|q| = {n:.6g})"
                    )
                last_t = t
                contacts = [vals[5 + 3 * i : 8 + 3 * i] for i in range(k)] if k else None
                if contacts is not None:
                    problem = _contact_units_problem(contacts, convention)
                    if problem:
                        raise SourceError(f"{path}:{line}: {problem}")
                if convention is not WORLD:
                    q, contacts = convention.convert(q, contacts)
                samples.append((t, tuple(q), contacts))  # type: ignore[arg-type]
        if not samples:
            raise SourceError(f"{path}: no samples after the header")
        return samples

    def __iter__(self) -> Iterator[Sample]:
        t0 = self.samples[0][0]
        for t, q, c in self.samples:
            yield (t - t0, q, c)

    def describe(self):
        d = {
            "source": self.name,
            "path": self.path,
            "rate_hz": self.rate_hz,
            "samples": len(self.samples),
        }
        if self.convention is not None:
            d["tracker_convention"] = self.convention.describe()
        return d


class TrackerAdapter(Source):
    """Base of live tracker adapters (Vicon DataStream, OptiTrack NatNet, Leap Motion...).

    A subclass sets ``convention`` (a :class:`TrackerConvention`, e.g.
    ``TRACKER_PRESETS["vicon"]``), ``name`` and ``rate_hz``, and implements
    :meth:`raw_samples`, yielding ``(t_s, quat, positions_or_None)`` exactly as the SDK
    gives them: the tracker's quaternion order, units and axes. Iterating the adapter yields
    samples in this project's world. Example::

        class ViconHand(TrackerAdapter):
            name, rate_hz = "vicon", 100.0
            convention = TRACKER_PRESETS["vicon"]
            def __init__(self, host): self.client = connect(host)   # the lab's SDK
            def raw_samples(self):
                while True:
                    frame = self.client.get_frame()
                    yield frame.t_s, frame.hand_quat_xyzw, None

    ``--source plugin:my_lab.vicon:ViconHand:192.168.1.10`` then streams it.
    """

    name = "tracker"
    convention: TrackerConvention = WORLD
    #: A live tracker follows a person; a subclass that plays a simulated hand sets it True.
    SIMULATED = False
    live = True

    @property
    def simulated(self) -> bool:  # type: ignore[override]
        return bool(self.SIMULATED)

    def raw_samples(self) -> Iterator[Sample]:  # pragma: no cover - interface
        raise NotImplementedError

    def __iter__(self) -> Iterator[Sample]:
        t0 = None
        for t, q, positions in self.raw_samples():
            values = [float(t), *[float(x) for x in q]]
            if not all(math.isfinite(v) for v in values):
                raise SourceError(
                    f"{self.name}: the tracker gave a non-finite sample t={t} q={list(q)}"
                )
            t0 = float(t) if t0 is None else t0
            if positions is not None:
                problem = _contact_units_problem(positions, self.convention, adapter=True)
                if problem:
                    raise SourceError(f"{self.name}: the tracker's contacts at t={t}: {problem}")
            wxyz, contacts = self.convention.convert(q, positions)
            yield (float(t) - t0, wxyz, contacts)

    def describe(self):
        return {
            "source": self.name,
            "rate_hz": self.rate_hz,
            "tracker_convention": self.convention.describe(),
        }


@dataclass(frozen=True)
class _Columns:
    quat: list[int]  # where t_s, qw, qx, qy, qz are
    contacts: list[int]  # where the contact columns are, finger by finger, x y z
    has_contacts: int | None  # a session log's has_contacts column


def _replay_columns(path: str, header: list[str]) -> _Columns:
    """Where a replay file's columns are, by name (see :class:`ReplaySource`): t_s, qw,
    qx, qy, qz, the contact columns of 3 or 4 fingers in order, and a session log's own
    columns (records.POSE_COLUMNS), which are read past; any other name is refused."""
    from graspguide.records.storage import POSE_COLUMNS

    log_only = [c for c in POSE_COLUMNS if c not in QUAT_COLUMNS]
    names = {}
    for i, h in enumerate(header):
        if h in names:
            raise SourceError(f"{path}:1: column {h!r} appears twice")
        names[h] = i
    missing = [c for c in QUAT_COLUMNS if c not in names]
    if missing:
        raise SourceError(
            f"{path}:1: the header must name the columns {','.join(QUAT_COLUMNS)} "
            f"(missing {','.join(missing)}), got {','.join(header)}"
        )
    every_contact = [f"{n}_{a}" for n in FINGERS for a in "xyz"]
    contacts = [h for h in header if h in every_contact]
    unknown = [h for h in header if h not in QUAT_COLUMNS + log_only + every_contact]
    if unknown:
        raise SourceError(
            f"{path}:1: unknown column {unknown[0]!r}; a replay file has "
            f"{','.join(QUAT_COLUMNS)}, optionally the contacts "
            f"{','.join(every_contact[:9])}[,palm_x,palm_y,palm_z], and may be a "
            f"session log's poses.csv ({','.join(POSE_COLUMNS)})"
        )
    k = len(contacts) // 3
    if contacts and (k not in (3, 4) or contacts != every_contact[: 3 * k]):
        raise SourceError(
            f"{path}:1: contact columns must be {','.join(every_contact[:9])}"
            f"[,palm_x,palm_y,palm_z], got {','.join(contacts)}"
        )
    return _Columns(
        [names[c] for c in QUAT_COLUMNS],
        [names[c] for c in contacts],
        names.get("has_contacts"),
    )


def _contact_units_problem(
    positions, convention: TrackerConvention, adapter: bool = False
) -> str | None:
    """What is wrong with a pose's contacts in the convention's unit (a hand spans 5 mm to
    0.5 m), or None. All contacts at one point are left to the device (coincident)."""
    from graspguide.core.units import hand_span, hand_span_problem

    if hand_span(positions) == 0.0:
        return None

    def fix(sym: str | None) -> str:
        if sym not in ("m", "mm"):
            return f"the positions are read as {convention.units}; check their unit"
        c = convention
        if adapter:
            return (
                f"the adapter's convention says units {c.units!r}: declare "
                f"TrackerConvention(units={sym!r}, ...)"
            )
        return (
            f"the positions are read as {c.units}: convert them, or replay with "
            f"--tracker {sym}/{c.up_axis}/{c.handedness}/{c.quat_order}"
        )

    return hand_span_problem(positions, convention.units, fix)


def _is_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def aligned_quaternion(
    contacts, wrench, policy="F", constraints="paper", y_axis=(0.0, 1.0, 0.0)
) -> np.ndarray:
    """An orientation with zero guidance error (the scene's force along gravity), from the
    core: the force direction f (hand frame) probed through mode V's gain
    alpha = |R f - g| / 2 * span for three orientations, then rotated onto g = -z."""
    from graspguide.core import solver

    s = math.sqrt(0.5)

    def fz(q):  # z of R f, from |R f - g|^2 = 2 + 2 (R f)_z
        r = solver.solve(
            contacts,
            wrench,
            policy=policy,
            mode="V",
            constraints=constraints,
            orientation=q,
            y_axis=y_axis,
        )
        if r["status"] != "ok":
            raise SourceError(f"synthetic: the core cannot solve the scene: {r['status']}")
        d = 2 * r["alpha"] / solver.PWM_SPAN
        return (d * d - 2) / 2

    f = np.array([fz([s, 0, -s, 0]), fz([s, s, 0, 0]), fz([1, 0, 0, 0])])
    f /= np.linalg.norm(f)
    axis = np.cross(f, [0, 0, -1.0])
    angle = math.atan2(np.linalg.norm(axis), -f[2])
    if np.linalg.norm(axis) < 1e-12:
        axis = np.array([1.0, 0, 0])
    return quat_from_axis_angle(axis, angle)


class SyntheticSource(Source):
    name = "synthetic"

    def __init__(
        self,
        rate: float = 240.0,
        duration: float = 10.0,
        seed: int = 0,
        tremor_deg: float = 0.3,
        start_deg: tuple[float, float] = (40.0, 80.0),
        converge_fraction: float = 0.6,
    ):
        if not 1 <= rate <= 10000:
            raise SourceError(f"synthetic: rate must be in 1..10000 Hz, got {rate}")
        if not 0 < duration <= 3600:
            raise SourceError(f"synthetic: duration must be in (0, 3600] s, got {duration}")
        self.rate_hz = float(rate)
        self.duration = float(duration)
        self.seed = int(seed)
        self.tremor_deg = float(tremor_deg)
        self.start_deg = start_deg
        self.converge_fraction = converge_fraction
        self.target = np.array([1.0, 0.0, 0.0, 0.0])

    def aim(
        self, contacts, wrench, policy="F", constraints="paper", y_axis=(0.0, 1.0, 0.0)
    ) -> SyntheticSource:
        """Turn towards the orientation aligning this scene's force with gravity."""
        self.target = aligned_quaternion(contacts, wrench, policy, constraints, y_axis)
        return self

    def __iter__(self) -> Iterator[Sample]:
        rng = np.random.default_rng(self.seed)
        # tilt about a horizontal world axis: the force starts offset degrees off gravity
        phi = rng.uniform(0, 2 * math.pi)
        axis = np.array([math.cos(phi), math.sin(phi), 0.0])
        offset = math.radians(rng.uniform(*self.start_deg))
        start = quat_mul(quat_from_axis_angle(axis, offset), self.target)
        t_conv = self.converge_fraction * self.duration
        freqs = rng.uniform(8.0, 12.0, size=3)
        phases = rng.uniform(0, 2 * math.pi, size=3)
        amp = math.radians(self.tremor_deg)
        n = int(round(self.duration * self.rate_hz))
        for i in range(n + 1):
            t = i / self.rate_hz
            u = min(1.0, t / t_conv) if t_conv > 0 else 1.0
            s = u * u * u * (10 - 15 * u + 6 * u * u)  # minimum jerk
            q = slerp(start, self.target, s)
            tremor = amp * (np.sin(2 * math.pi * freqs * t + phases) + 0.3 * rng.normal(size=3))
            q = quat_mul(q, quat_from_axis_angle(tremor, float(np.linalg.norm(tremor))))
            q /= np.linalg.norm(q)
            yield (t, (float(q[0]), float(q[1]), float(q[2]), float(q[3])), None)

    def describe(self):
        return {
            "source": self.name,
            "rate_hz": self.rate_hz,
            "duration_s": self.duration,
            "seed": self.seed,
            "target_wxyz": [float(x) for x in self.target],
        }


def tracker_convention(name: str) -> TrackerConvention:
    """A preset by name, or ``units/up_axis/handedness/quat_order`` such as
    ``mm/y/right/xyzw``."""
    if name in TRACKER_PRESETS:
        return TRACKER_PRESETS[name]
    parts = name.split("/")
    if len(parts) != 4:
        raise SourceError(
            f"unknown tracker {name!r}: use one of "
            f"{', '.join(sorted(TRACKER_PRESETS))} or "
            "UNITS/UP/HANDEDNESS/ORDER such as mm/y/right/xyzw"
        )
    return TrackerConvention(*parts)


def open_plugin(rest: str) -> Source:
    module_name, _, tail = rest.partition(":")
    class_name, _, arg = tail.partition(":")
    if not module_name or not class_name:
        raise SourceError("plugin needs a module and a class: --source plugin:MODULE:CLASS[:ARG]")
    try:
        module = importlib.import_module(module_name)
    except ImportError as e:
        raise SourceError(f"plugin: cannot import {module_name!r}: {e}") from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, TrackerAdapter)):
        raise SourceError(
            f"plugin: {module_name}.{class_name} must be a "
            "graspguide.sources.poses.TrackerAdapter subclass"
        )
    return cls(arg) if arg else cls()


__all__ = [
    "Source",
    "ReplaySource",
    "SyntheticSource",
    "SourceError",
    "SOURCE_KINDS",
    "SYNTHETIC_OPTIONS",
    "unknown_source",
    "TrackerConvention",
    "TrackerAdapter",
    "tracker_convention",
    "TRACKER_PRESETS",
    "WORLD",
    "aligned_quaternion",
    "quat_mul",
    "quat_from_axis_angle",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_angle_deg",
]
