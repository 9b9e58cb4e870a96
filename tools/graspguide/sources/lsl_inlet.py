"""``--source lsl:...``: hand poses, and fingertip contacts from markers, read live from a
Lab Streaming Layer motion-capture stream (docs/lab-streams.md, "LSL MoCap source").

The stream is what a lab's LSL MoCap app publishes (stream type ``MoCap``, numeric
channels, their labels and units in ``<desc><channels><channel><label>``/``<unit>``/
``<type>``): the hand's rigid body as a position and a quaternion, and optionally the
fingertip markers as positions. Channels are matched by label (:func:`match_channels`):

* body ``Hand``: ``Hand_X, Hand_Y, Hand_Z`` and ``Hand_QW, Hand_QX, Hand_QY, Hand_QZ``;
* marker ``Thumb``: ``Thumb_X, Thumb_Y, Thumb_Z``; optionally ``Thumb_Occluded`` (nonzero:
  occluded) or ``Thumb_Valid`` (zero: occluded).

Labels are compared without case and separators (``_ . : - /`` and spaces), so
``hand.x``, ``Hand X`` and ``HAND_X`` are the same; positions may also be written
``Hand_PosX`` / ``Hand_PositionX``, quaternion components ``Hand_QuatW``, ``Hand_RotW``,
``Hand_OrientationW`` or ``Hand_QuaternionW``; a ``Subject:`` prefix (text up to the last
colon) is read past when the whole label does not match.

Spec keys (:data:`LSL_KEYS`): ``name``, ``type`` (default MoCap; ``any``), ``source_id``,
``hostname`` select the stream; ``body`` (Hand), ``markers`` (Thumb;Index;Middle, in the
device's contact order thumb, index, middle[, palm]; ``none`` for no contacts),
``hold`` (0.2 s), ``tol_mm`` (2.0), ``wait`` (5 s to find the stream), ``stall`` (0.5 s),
``end`` (10 s) and ``newest`` (1).

Timestamps: the inlet is opened with liblsl's ``proc_clocksync | proc_monotonize``: liblsl
adds the :meth:`time_correction` offset to each sample's timestamp itself (the samples are
on this machine's ``local_clock()``), and keeps them increasing. ``t_s`` is the time from
the first sample sent (the hold rule works on the LSL timestamps themselves).

What the runner sees: samples ``(t_s, quat_wxyz, contacts_or_None)`` as of any source.
Each sample goes through :class:`graspguide.sources.marker_contacts.HandTracking`, the rule
NatNet's source follows too: a marker or the rigid body lost for at most ``hold`` keeps its
last value; longer is a *pause*. ``contacts`` is None when the per-posture re-run rule
keeps the last ones. A pause, the wait for the body's and every marker's first sight, and
a *stall* (no sample for ``stall`` seconds) are gaps: no sample is yielded, so no POSE is
sent and the device's watchdog turns the motors off 200 ms after the last POSE; the source
says so once per episode on stderr and counts it (:meth:`LslSource.stats`). After ``end``
seconds without a sample the source ends (the trial ends as "the source ended first").
"""

from __future__ import annotations

import math
import re
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from typing import Any, TextIO

import numpy as np

from graspguide.core.suggest import did_you_mean
from graspguide.link.messages import POSE_WATCHDOG_MS
from graspguide.sources.marker_contacts import (
    DEFAULT_HOLD_S,
    DEFAULT_TOL_MM,
    HandTracking,
    Pose,
)
from graspguide.sources.poses import WORLD, Sample, Source, SourceError, TrackerConvention

#: Every key of ``lsl:KEY=VALUE,...`` and its default.
LSL_KEYS: dict[str, str] = {
    "name": "",
    "type": "MoCap",
    "source_id": "",
    "hostname": "",
    "body": "Hand",
    "markers": "Thumb;Index;Middle",
    "hold": f"{DEFAULT_HOLD_S:g}",
    "tol_mm": f"{DEFAULT_TOL_MM:.1f}",
    "wait": "5",
    "stall": "0.5",
    "end": "10",
    "newest": "1",
}
MOCAP_TYPE = "MoCap"
# liblsl's inlet buffer: a stall longer than this loses its oldest samples, which is
# what a live source wants anyway (the newest hand).
BUFFER_S = 30
_SEPARATORS = re.compile(r"[\s_.:/\\-]+")
_POSITION_FORMS = ("{a}", "pos{a}", "position{a}")
_QUAT_FORMS = ("q{a}", "quat{a}", "quaternion{a}", "rot{a}", "orientation{a}")
_UNITS = {
    "m": "m",
    "meter": "m",
    "meters": "m",
    "metre": "m",
    "metres": "m",
    "mm": "mm",
    "millimeter": "mm",
    "millimeters": "mm",
    "millimetre": "mm",
    "millimetres": "mm",
}


# --------------------------------------------------------------------------------------
# The spec
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LslSpec:
    name: str = ""
    type: str = MOCAP_TYPE
    source_id: str = ""
    hostname: str = ""
    body: str = "Hand"
    markers: tuple[str, ...] = ("Thumb", "Index", "Middle")
    hold_s: float = DEFAULT_HOLD_S
    tol_mm: float = DEFAULT_TOL_MM
    wait_s: float = 5.0
    stall_s: float = 0.5
    end_s: float = 10.0
    newest: bool = True

    def predicate(self) -> str:
        """The XPath liblsl resolves the stream with."""
        parts = [
            f"{key}='{value}'"
            for key, value in (
                ("name", self.name),
                ("type", self.type if self.type.lower() != "any" else ""),
                ("source_id", self.source_id),
                ("hostname", self.hostname),
            )
            if value
        ]
        return " and ".join(parts) or "channel_count>0"

    def wanted(self) -> str:
        text = self.predicate().replace(" and ", ", ")
        return "any stream" if text == "channel_count>0" else text


def _number(key: str, text: str, low: float, high: float) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SourceError(
            f"lsl: {key} must be a number, got {text!r} (e.g. {key}={LSL_KEYS[key]})"
        ) from None
    if not (math.isfinite(value) and low <= value <= high):
        raise SourceError(f"lsl: {key} must be in {low:g}..{high:g}, got {text!r}")
    return value


def parse_spec(rest: str) -> LslSpec:
    """The :class:`LslSpec` of ``KEY=VALUE,...`` (the part after ``lsl:``); SourceError
    naming the key and how to write it."""
    given: dict[str, str] = {}
    for item in filter(None, (x.strip() for x in rest.split(","))):
        key, eq, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or key not in LSL_KEYS:
            raise SourceError(
                f"lsl: bad key {item!r}{did_you_mean(key, LSL_KEYS)}; keys are "
                + ", ".join(f"{k}={v or 'TEXT'}" for k, v in LSL_KEYS.items())
                + " (lsl:name=Hand,type=MoCap,markers=Thumb;Index;Middle)"
            )
        if key in given:
            raise SourceError(f"lsl: {key} is given twice")
        if "'" in value or '"' in value:
            raise SourceError(f"lsl: {key} must not contain quotes, got {value!r}")
        given[key] = value
    v = {**LSL_KEYS, **given}
    for key in ("type", "body"):
        if not v[key]:
            raise SourceError(f"lsl: {key} must not be empty (default {LSL_KEYS[key]})")
    if v["markers"].lower() == "none":
        markers: tuple[str, ...] = ()
    else:
        markers = tuple(m.strip() for m in v["markers"].split(";"))
        if not 3 <= len(markers) <= 4 or not all(markers):
            raise SourceError(
                f"lsl: markers must name 3 or 4 markers in the contact order thumb, index, "
                f"middle[, palm] separated by ';' (markers=Thumb;Index;Middle), or none, got "
                f"{v['markers']!r}"
            )
        if len({m.lower() for m in markers} | {v["body"].lower()}) != len(markers) + 1:
            raise SourceError(
                f"lsl: the body and the markers must have distinct names, got "
                f"body={v['body']} markers={v['markers']}"
            )
    if v["newest"].lower() not in ("0", "1", "yes", "no", "true", "false"):
        raise SourceError(f"lsl: newest must be 1 or 0, got {v['newest']!r}")
    stall = _number("stall", v["stall"], 0.01, 3600)
    end = _number("end", v["end"], 0.01, 86400)
    if end < stall:
        raise SourceError(f"lsl: end ({end:g} s) must not be shorter than stall ({stall:g} s)")
    return LslSpec(
        name=v["name"],
        type=v["type"],
        source_id=v["source_id"],
        hostname=v["hostname"],
        body=v["body"],
        markers=markers,
        hold_s=_number("hold", v["hold"], 0, 60),
        tol_mm=_number("tol_mm", v["tol_mm"], 0, 1000),
        wait_s=_number("wait", v["wait"], 0.01, 3600),
        stall_s=stall,
        end_s=end,
        newest=v["newest"].lower() in ("1", "yes", "true"),
    )


# --------------------------------------------------------------------------------------
# Channels
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Channels:
    """Where the values are in a sample: the body's position (x, y, z) and quaternion
    (w, x, y, z), each marker's position, each marker's occlusion flag channel (or None,
    with ``flag_valid``: the flag says valid rather than occluded) and the unit read from
    the descriptions ("m", "mm" or "" when none is given)."""

    body_position: list[int]
    body_quat: list[int]
    markers: list[list[int]]
    flags: list[int | None]
    flag_valid: list[bool]
    units: str


def _norm(label: str) -> str:
    return _SEPARATORS.sub("", label).lower()


def match_channels(spec: LslSpec, labels: Sequence[str], units: Sequence[str]) -> Channels:
    """The channels of the body and markers of ``spec`` among ``labels`` (module
    docstring); SourceError naming what is missing, what was asked and what was found."""
    full = [_norm(x) for x in labels]
    tail = [_norm(x.rsplit(":", 1)[-1]) if ":" in x else None for x in labels]

    def find(name: str, forms: Sequence[str], axis: str, required: bool = True) -> int | None:
        wanted = {_norm(name) + f.format(a=axis) for f in forms}
        hits = [i for i, x in enumerate(full) if x in wanted]
        if not hits:
            hits = [i for i, x in enumerate(tail) if x is not None and x in wanted]
        if len(hits) > 1:
            raise SourceError(
                f"lsl: channels {', '.join(repr(labels[i]) for i in hits)} all read as "
                f"{name} {axis.upper()}; rename one in the MoCap app"
            )
        if not hits:
            if required:
                missing.append(f"{name}_{forms[0].format(a=axis).upper()}")
            return None
        return hits[0]

    missing: list[str] = []
    body_p = [find(spec.body, _POSITION_FORMS, a) for a in "xyz"]
    body_q = [find(spec.body, _QUAT_FORMS, a) for a in "wxyz"]
    markers = [[find(m, _POSITION_FORMS, a) for a in "xyz"] for m in spec.markers]
    if missing:
        asked = [f"{spec.body}_X,Y,Z", f"{spec.body}_QW,QX,QY,QZ"]
        asked += [f"{m}_X,Y,Z" for m in spec.markers]
        raise SourceError(
            f"lsl: the stream has no channel {', '.join(missing)}; the spec asks for body="
            f"{spec.body} ({', '.join(asked[:2])})"
            + (
                f" and markers={';'.join(spec.markers)} ({', '.join(asked[2:])})"
                if spec.markers
                else ""
            )
            + f"; the stream's channel labels are: {', '.join(labels) if labels else '(none)'}"
            + "; set body=/markers= to the names the MoCap app uses, or markers=none for a "
            "stream without markers"
        )
    flags: list[int | None] = []
    flag_valid: list[bool] = []
    for m in spec.markers:
        occl = find(m, ("occluded", "occlusion"), "", required=False)
        valid = find(m, ("valid", "visible"), "", required=False)
        flags.append(occl if occl is not None else valid)
        flag_valid.append(occl is None and valid is not None)
    positions = [i for i in body_p + [i for m in markers for i in m] if i is not None]
    seen = {u for u in (units[i].strip().lower() for i in positions if i < len(units)) if u}
    bad = sorted(u for u in seen if u not in _UNITS)
    if bad:
        raise SourceError(
            f"lsl: position unit {bad[0]!r} is not supported; the positions must be in "
            "metres or millimetres (<unit>m</unit> or mm)"
        )
    kinds = {_UNITS[u] for u in seen}
    if len(kinds) > 1:
        raise SourceError(
            f"lsl: the position channels mix units {sorted(seen)}; they must share one"
        )
    return Channels(
        [int(i) for i in body_p],  # type: ignore[arg-type]
        [int(i) for i in body_q],  # type: ignore[arg-type]
        [[int(i) for i in m] for m in markers],  # type: ignore[arg-type]
        flags,
        flag_valid,
        kinds.pop() if kinds else "",
    )


def _described_channels(info: Any) -> tuple[list[str], list[str], list[str]]:
    """(labels, units, types) from ``<desc><channels><channel>``."""
    labels, units, types = [], [], []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        labels.append(ch.child_value("label"))
        units.append(ch.child_value("unit"))
        types.append(ch.child_value("type"))
        ch = ch.next_sibling("channel")
    return labels, units, types


# --------------------------------------------------------------------------------------
# Finding streams
# --------------------------------------------------------------------------------------
def _pylsl() -> Any:
    from graspguide.sources.lab_streams import LabStreamsError, _load_pylsl, network_problem

    try:
        lsl = _load_pylsl(configure_log=True)
    except LabStreamsError as e:
        raise SourceError(f"lsl: {e}") from None
    problem = network_problem()
    if problem:
        raise SourceError(f"lsl: {problem}")
    return lsl


def _row(info: Any) -> dict[str, Any]:
    return {
        "name": info.name(),
        "type": info.type(),
        "source_id": info.source_id(),
        "channels": info.channel_count(),
        "rate_hz": info.nominal_srate(),
        "hostname": info.hostname(),
    }


def list_lsl_streams(timeout: float = 2.0) -> list[dict[str, Any]]:
    """The LSL streams seen within ``timeout`` seconds: name, type, source_id, channels,
    rate_hz (0: irregular) and hostname of each, by name."""
    lsl = _pylsl()
    rows = [_row(i) for i in lsl.resolve_streams(wait_time=timeout)]
    return sorted(rows, key=lambda r: (r["name"], r["type"], r["source_id"]))


def stream_table(rows: Sequence[dict[str, Any]]) -> str:
    """``rows`` of :func:`list_lsl_streams` as an aligned text table."""
    head = ["name", "type", "source_id", "channels", "rate_hz", "hostname"]
    cells = [head] + [[str(r[h]) if h != "rate_hz" else f"{r[h]:g}" for h in head] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(head))]
    return "\n".join(
        "  ".join(c[i].ljust(widths[i]) for i in range(len(head))).rstrip() for c in cells
    )


def _seen_text(rows: Sequence[dict[str, Any]]) -> str:
    if not rows:
        return (
            "no LSL stream at all is seen (is the MoCap app streaming? see lsl_api.cfg in "
            "docs/lab-streams.md)"
        )
    return "streams seen: " + "; ".join(
        f"name={r['name']} type={r['type']} source_id={r['source_id'] or '-'} "
        f"({r['channels']} channels, host {r['hostname']})"
        for r in rows
    )


def resolve_stream(spec: LslSpec) -> Any:
    """The StreamInfo of the one stream ``spec`` selects, waiting up to ``wait``
    seconds; SourceError listing the streams seen when none or several match."""
    lsl = _pylsl()
    found = lsl.resolve_bypred(spec.predicate(), 1, spec.wait_s)
    if not found:
        seen = [_row(i) for i in lsl.resolve_streams(wait_time=min(1.0, spec.wait_s))]
        raise SourceError(
            f"lsl: no stream with {spec.wanted()} found within {spec.wait_s:g} s; "
            f"{_seen_text(seen)}; `graspguide stream --source lsl --list` lists them"
        )
    if len(found) > 1:
        raise SourceError(
            f"lsl: {len(found)} streams have {spec.wanted()}: "
            f"{_seen_text([_row(i) for i in found])}; add source_id= (or hostname=) to pick one"
        )
    return found[0]


# --------------------------------------------------------------------------------------
# The source
# --------------------------------------------------------------------------------------
class LslSource(Source):
    """A live LSL MoCap stream as a pose source (module docstring). ``notice``: where
    the one-line notices go (stderr when None)."""

    name = "lsl"
    live = True
    simulated = False

    def __init__(
        self,
        spec: LslSpec,
        convention: TrackerConvention | None = None,
        notice: TextIO | None = None,
    ):
        lsl = _pylsl()
        self.spec = spec
        self.notice = notice
        info = resolve_stream(spec)
        flags = lsl.proc_clocksync | lsl.proc_monotonize
        try:
            self.inlet = lsl.StreamInlet(
                info, max_buflen=BUFFER_S, recover=True, processing_flags=flags
            )
            full = self.inlet.info(timeout=spec.wait_s)
            # connected now: what the app pushes from here on is buffered for the trial
            self.inlet.open_stream(timeout=spec.wait_s)
            # proc_clocksync's first sample waits for liblsl's first clock offset (about
            # half a second): got here, before the trial, not in its first POSE
            self.inlet.time_correction(timeout=spec.wait_s)
        except Exception as e:
            raise SourceError(
                f"lsl: cannot open the stream {info.name()} ({e}); is its app still running?"
            ) from None
        self.stream_name = full.name()
        if full.channel_format() in (lsl.cf_string, getattr(lsl, "cf_undefined", -1)):
            raise SourceError(
                f"lsl: the stream {self.stream_name} carries text, not numbers: a MoCap stream "
                "has numeric channels"
            )
        self.labels, units, _types = _described_channels(full)
        if len(self.labels) != full.channel_count():
            raise SourceError(
                f"lsl: the stream {self.stream_name} describes {len(self.labels)} channels "
                f"(<desc><channels><channel><label>) but has {full.channel_count()}; its "
                f"labels: {', '.join(self.labels) or '(none)'}"
            )
        self.channels = match_channels(spec, self.labels, units)
        self.convention = self._convention(convention, self.channels.units)
        self.info = _row(full)
        self.rate_hz = full.nominal_srate() or None
        self.tracking = HandTracking(
            spec.markers, spec.body, self._say, spec.hold_s, spec.tol_mm / 1000.0
        )
        self.counts = {"skipped": 0, "stalls": 0}

    def _convention(self, given: TrackerConvention | None, units: str) -> TrackerConvention:
        if given is not None and units and given.units != units:
            raise SourceError(
                f"lsl: the stream {self.stream_name}'s channels say {units} but --tracker says "
                f"{given.units}; drop --tracker's unit or fix the app's <unit>"
            )
        conv = given if given is not None else replace(WORLD, units=units or "m")
        # the quaternion's components are read by label, w first, whatever the order
        return replace(conv, quat_order="wxyz")

    # ---- notices
    def _say(self, text: str) -> None:
        print(f"LSL stream {self.stream_name}: {text}", file=self.notice or sys.stderr, flush=True)

    # ---- the samples
    def _convert(self, row: np.ndarray) -> tuple[Pose | None, np.ndarray | None, Any]:
        """(pose or None when the rigid body is lost (a NaN, a zero quaternion), the
        markers in the world (None without markers), their occlusion flags or None) of
        one raw sample."""
        ch = self.channels
        conv = self.convention
        q = row[ch.body_quat]
        p = row[ch.body_position]
        n = float(np.linalg.norm(q))
        pose = None
        if np.all(np.isfinite(q)) and np.all(np.isfinite(p)) and n > 0.5:
            pose = (conv.quaternion(q / n), conv.position(p))
        if not ch.markers:
            return pose, None, None
        scale = 1000.0 if conv.units == "mm" else 1.0
        world = (row[np.asarray(ch.markers)] @ conv.matrix.T) / scale
        occluded = [
            None if f is None else (row[f] == 0 if valid else row[f] != 0)
            for f, valid in zip(ch.flags, ch.flag_valid)
        ]
        flags = [bool(o) for o in occluded] if any(o is not None for o in occluded) else None
        return pose, world, flags

    def _process(self, stamp: float, row: np.ndarray) -> Sample | None:
        """The sample to send for one raw sample (its LSL time, quat, every contact), or
        None (waiting, paused): :meth:`HandTracking.update`."""
        return self.tracking.update(stamp, *self._convert(row))

    def __iter__(self) -> Iterator[Sample]:
        spec = self.spec
        inlet = self.inlet
        t0: float | None = None
        self.tracking.new_run()
        last = time.monotonic()
        stalled = False
        try:
            while True:
                first, ts = inlet.pull_sample(timeout=min(0.05, spec.stall_s / 4))
                now = time.monotonic()
                if first is None:
                    gap = now - last
                    if gap > spec.stall_s and not stalled:
                        stalled = True
                        self.counts["stalls"] += 1
                        self._say(self._stall_text(gap, t0 is None))
                    if gap > spec.end_s:
                        self._say(f"no sample for {spec.end_s:g} s: the source ends")
                        return
                    continue
                if stalled:
                    self._say(f"samples again after {now - last:.2f} s: POSEs resume")
                    stalled = False
                last = now
                rows, stamps = [first], [ts]
                more, more_ts = inlet.pull_chunk(timeout=0.0)
                rows.extend(more)
                stamps.extend(more_ts)
                ready = []
                for row, stamp in zip(rows, stamps):
                    # the hold rule works on LSL time; t_s counts from the first sample sent
                    sample = self._process(stamp, np.asarray(row, dtype=float))
                    if sample is not None:
                        ready.append(sample)
                if spec.newest and len(ready) > 1:
                    self.counts["skipped"] += len(ready) - 1
                    ready = ready[-1:]
                for sample in ready:
                    t0 = sample[0] if t0 is None else t0
                    yield self.tracking.send(float(sample[0] - t0), sample)
        finally:
            try:
                inlet.close_stream()
            except Exception:  # the inlet is going anyway
                pass

    def _stall_text(self, gap: float, before_first: bool) -> str:
        if before_first:
            return f"no sample for {gap:.1f} s since the trial started: no POSE sent yet"
        return (
            f"stalled for {gap:.1f} s: no POSE sent; the device's watchdog turns the motors "
            f"off {POSE_WATCHDOG_MS} ms after the last POSE"
        )

    def stats(self) -> dict[str, Any]:
        """What the source did: samples skipped for newer ones, stalls, and
        :meth:`HandTracking.stats` (samples read, POSEs yielded, waiting, rigid-body-lost,
        held and paused samples, pause episodes; with markers the per-posture re-runs)."""
        return {**self.counts, **self.tracking.stats()}

    def describe(self) -> dict[str, Any]:
        return {
            "source": self.name,
            "stream": self.info,
            "rate_hz": self.rate_hz,
            "labels": self.labels,
            "body": self.spec.body,
            "markers": list(self.spec.markers),
            "hold_s": self.spec.hold_s,
            "tol_mm": self.spec.tol_mm,
            "stall_s": self.spec.stall_s,
            "end_s": self.spec.end_s,
            "newest": self.spec.newest,
            "tracker_convention": self.convention.describe(),
            "timestamps": "liblsl proc_clocksync|proc_monotonize, t_s from the first sample",
        }


def open_lsl_source(rest: str, convention: TrackerConvention | None = None) -> LslSource:
    """The source of ``--source lsl:REST``; SourceError when the spec is bad or the stream
    is not found or lacks a channel."""
    return LslSource(parse_spec(rest), convention)


__all__ = [
    "LSL_KEYS",
    "LslSpec",
    "LslSource",
    "Channels",
    "parse_spec",
    "match_channels",
    "list_lsl_streams",
    "stream_table",
    "resolve_stream",
    "open_lsl_source",
]
