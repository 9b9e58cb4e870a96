"""``--source replay:FILE.xdf[#KEY=VALUE,...]``: the hand poses of an XDF recording -- a
``--record`` file of `graspguide stream`, or a LabRecorder file of a lab's motion-capture
stream -- read with pyxdf and yielded as samples ``(t_s, quat_wxyz, contacts_or_None)``.

The spec string: :func:`graspguide.sources.poses.open_source` splits ``--source`` at its
first ``:`` and sends ``replay:`` values whose part before the first ``#`` ends in
``.xdf`` here; that part is the file, what follows ``#`` chooses the stream:

* nothing: the first stream of type ``MoCap`` (case-insensitive) in the file;
* ``name=NAME``, ``type=TYPE``, ``source_id=ID``: the first stream with all of these
  (``replay:run.xdf#name=GraspGuide-Hand``);
* ``body=PREFIX``: in a stream whose channels are labelled per rigid body
  (``Hand_QW``, ``Hand_QX``, ...), the body's prefix (needed when there are several).

Channels are found by label, case-insensitive: ``qw, qx, qy, qz`` (or ``PREFIX_qw`` ...,
the separator ``_``, ``.`` or ``:``), and the contacts ``thumb_x, thumb_y, thumb_z,
index_x .. middle_z[, palm_x, palm_y, palm_z]`` when all of the first three fingers are
there (a sample whose contacts are NaN has none). Values are in this project's world
unless ``--tracker`` names the recording's convention (units, up axis, handedness; the
quaternion's order is the labels'). Times: ``t_s`` is each timestamp less the first, as
pyxdf gives them with clock synchronisation and without dejittering (the times the
samples were stamped with).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from typing import Any

import numpy as np

from graspguide.core.vocabulary import FINGERS
from graspguide.sources.poses import (
    WORLD,
    Sample,
    Source,
    SourceError,
    TrackerConvention,
    _contact_units_problem,
)

MOCAP_TYPE = "MoCap"
SELECTOR_KEYS = ("name", "type", "source_id", "body")
_SEPARATORS = "_.:"


def split_spec(spec: str) -> tuple[str, dict[str, str]]:
    """``FILE.xdf#name=X,type=Y`` -> (``FILE.xdf``, {"name": "X", "type": "Y"}); raises
    SourceError for an unknown key."""
    path, hash_, rest = spec.partition("#")
    chosen: dict[str, str] = {}
    for item in filter(None, (x.strip() for x in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq or key not in SELECTOR_KEYS or not value.strip():
            raise SourceError(
                f"replay:{spec}: bad stream choice {item!r}; after '#' give "
                + ", ".join(f"{k}=..." for k in SELECTOR_KEYS)
                + " (e.g. replay:run.xdf#name=GraspGuide-Hand)"
            )
        chosen[key] = value.strip()
    if hash_ and not chosen:
        raise SourceError(f"replay:{spec}: nothing after '#'; give e.g. #name=GraspGuide-Hand")
    return path, chosen


def _first(info: dict[str, Any], key: str) -> str:
    value = info.get(key)
    if isinstance(value, list):
        value = value[0] if value else None
    return "" if value is None else str(value)


def _labels(stream: dict[str, Any]) -> list[str]:
    """The channel labels of a pyxdf stream ('' where a channel has none)."""
    info = stream["info"]
    n = int(_first(info, "channel_count") or 0)
    labels = [""] * n
    try:
        channels = info["desc"][0]["channels"][0]["channel"]
    except (KeyError, IndexError, TypeError):
        return labels
    for i, ch in enumerate(channels[:n]):
        if isinstance(ch, dict):
            labels[i] = _first(ch, "label")
    return labels


def _describe(streams: list[dict[str, Any]]) -> str:
    if not streams:
        return "none"
    return ", ".join(f"{_first(s['info'], 'name')} ({_first(s['info'], 'type')})" for s in streams)


def _choose(path: str, streams: list[dict[str, Any]], chosen: dict[str, str]) -> dict[str, Any]:
    wanted = {k: v for k, v in chosen.items() if k != "body"}
    if not wanted:
        wanted = {"type": MOCAP_TYPE}
    for s in streams:
        info = s["info"]
        if all(
            _first(info, key).lower() == value.lower()
            if key == "type"
            else _first(info, key) == value
            for key, value in wanted.items()
        ):
            return s
    what = ", ".join(f"{k}={v}" for k, v in wanted.items())
    if wanted == {"type": MOCAP_TYPE}:
        head = f"no {MOCAP_TYPE} stream in {path}"
        fix = "; choose one with replay:FILE.xdf#name=NAME"
    else:
        head = f"no stream with {what} in {path}"
        fix = ""
    raise SourceError(f"{head}; streams: {_describe(streams)}{fix}")


def _quat_columns(path: str, name: str, labels: list[str], body: str | None) -> list[int]:
    """Where qw, qx, qy, qz are: plain labels, or PREFIX_qw... of one rigid body."""
    lower = [x.lower() for x in labels]
    if body is None and all(f"q{c}" in lower for c in "wxyz"):
        return [lower.index(f"q{c}") for c in "wxyz"]
    prefixes: dict[str, dict[str, int]] = {}
    for i, label in enumerate(lower):
        m = re.fullmatch(rf"(.+)[{re.escape(_SEPARATORS)}]q([wxyz])", label)
        if m:
            prefixes.setdefault(m.group(1), {})[m.group(2)] = i
    bodies = {p: idx for p, idx in prefixes.items() if len(idx) == 4}
    if body is not None:
        idx = bodies.get(body.lower())
        if idx is None:
            raise SourceError(
                f"{path}: stream {name!r} has no rigid body {body!r} (channels "
                f"{body}_qw..{body}_qz); bodies: {', '.join(sorted(bodies)) or 'none'}"
            )
        return [idx[c] for c in "wxyz"]
    if len(bodies) == 1:
        idx = next(iter(bodies.values()))
        return [idx[c] for c in "wxyz"]
    if len(bodies) > 1:
        raise SourceError(
            f"{path}: stream {name!r} has several rigid bodies ({', '.join(sorted(bodies))}); "
            "choose one with replay:FILE.xdf#body=NAME"
        )
    missing = [f"q{c}" for c in "wxyz" if f"q{c}" not in lower]
    raise SourceError(
        f"{path}: stream {name!r} has no orientation channels: need the labels qw, qx, qy, "
        f"qz (or BODY_qw..BODY_qz), missing {', '.join(missing)}; its channels: "
        f"{', '.join(labels) or 'unlabelled'}"
    )


def _contact_columns(labels: list[str], prefix: str) -> list[int]:
    """The contact channels of 3 or 4 fingers, in order, or [] when they are not all there."""
    lower = {x.lower(): i for i, x in enumerate(labels)}
    columns: list[int] = []
    for finger in FINGERS:
        idx = [lower.get(f"{prefix}{finger}_{a}") for a in "xyz"]
        if any(i is None for i in idx):
            break
        columns += [i for i in idx if i is not None]
    return columns if len(columns) >= 9 else []


def _load_pyxdf() -> Any:
    try:
        import pyxdf  # type: ignore[import-untyped]
    except ImportError as e:
        raise SourceError(
            f"replay of an XDF file needs pyxdf ({e}); install the pinned pyxdf "
            "(tools/requirements-dev.txt)"
        ) from None
    return pyxdf


class XdfReplaySource(Source):
    """The poses of one stream of an XDF file (see the module's docstring)."""

    name = "replay"

    def __init__(self, spec: str, convention: TrackerConvention | None = None):
        self.spec = spec
        self.path, chosen = split_spec(spec)
        self.convention = convention
        if not os.path.isfile(self.path):
            raise SourceError(f"replay: cannot read {self.path}: no such file")
        pyxdf = _load_pyxdf()
        try:
            streams, _ = pyxdf.load_xdf(self.path, dejitter_timestamps=False)
        except Exception as e:  # pyxdf raises IOError, struct.error, ParseError...
            raise SourceError(
                f"replay: {self.path} is not a readable XDF file ({type(e).__name__}: {e})"
            ) from None
        stream = _choose(self.path, streams, chosen)
        self.stream_name = _first(stream["info"], "name")
        self.samples = self._samples(stream, chosen.get("body"), convention or WORLD)
        dts = np.diff([s[0] for s in self.samples])
        self.rate_hz = float(1.0 / np.median(dts)) if len(dts) and np.median(dts) > 0 else None

    def _samples(
        self, stream: dict[str, Any], body: str | None, convention: TrackerConvention
    ) -> list[Sample]:
        where = f"{self.path}: stream {self.stream_name!r}"
        if _first(stream["info"], "channel_format") == "string":
            raise SourceError(f"{where} holds strings, not poses; choose a MoCap stream")
        labels = _labels(stream)
        quat = _quat_columns(self.path, self.stream_name, labels, body)
        label = labels[quat[0]]
        prefix = label[: len(label) - 2]  # "" or "Hand_"
        contacts = _contact_columns(labels, prefix.lower())
        k = len(contacts) // 3
        values = stream["time_series"]
        stamps = stream["time_stamps"]
        if len(stamps) == 0:
            raise SourceError(f"{where} has no samples")
        t0 = float(stamps[0])
        samples: list[Sample] = []
        last = -math.inf
        for n, (t, row) in enumerate(zip(stamps, values)):
            t = float(t)
            raw_q = [float(row[i]) for i in quat]
            if not all(math.isfinite(v) for v in raw_q + [t]):
                raise SourceError(f"{where}, sample {n}: the time and quaternion must be finite")
            if t <= last:
                raise SourceError(
                    f"{where}, sample {n}: timestamps must increase ({t} after {last})"
                )
            last = t
            norm = math.sqrt(sum(v * v for v in raw_q))
            if abs(norm - 1) > 1e-3:
                raise SourceError(
                    f"{where}, sample {n}: the quaternion {','.join(labels[i] for i in quat)} "
                    f"is not unit length (|q| = {norm:.6g})"
                )
            points = None
            if k:
                c = [float(row[i]) for i in contacts]
                if all(math.isfinite(v) for v in c):
                    points = [c[3 * i : 3 * i + 3] for i in range(k)]
                    problem = _contact_units_problem(points, convention)
                    if problem:
                        raise SourceError(f"{where}, sample {n}: {problem}")
            # the labels say which component is which: hand them over in the order the
            # convention expects, so that only its axes and units are applied
            ordered = raw_q if convention.quat_order == "wxyz" else raw_q[1:] + raw_q[:1]
            if convention is WORLD:
                q, points_w = tuple(raw_q), points
            else:
                q, points_w = convention.convert(ordered, points)
            samples.append((t - t0, q, points_w))  # type: ignore[arg-type]
        return samples

    def __iter__(self) -> Iterator[Sample]:
        return iter(self.samples)

    def describe(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "source": self.name,
            "path": self.path,
            "stream": self.stream_name,
            "rate_hz": self.rate_hz,
            "samples": len(self.samples),
        }
        if self.spec != self.path:
            d["spec"] = self.spec
        if self.convention is not None:
            d["tracker_convention"] = self.convention.describe()
        return d


__all__ = ["XdfReplaySource", "split_spec", "SELECTOR_KEYS"]
