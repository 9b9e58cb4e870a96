"""`scene.toml`: one experiment's scene (contacts, object axis, constraint model, policy,
mode) and trial parameters, as `graspguide stream` sends them to a device.

Format (every key is checked; an unknown key is an error, so a typo is never ignored)::

    [scene]
    units = "mm"                 # "m" or "mm"; contacts are converted to metres

    [contacts]
    thumb  = [45.0, 45.0, 35.0]  # hand frame, in `units`
    index  = [15.0, 95.0, 40.0]
    middle = [-10.0, 100.0, 40.0]
    palm   = [20.0, 40.0, 0.0]   # optional: k = 4 when present, else k = 3
    y_axis = [0.0, 1.0, 0.0]     # object axis y_O in the hand frame (default [0, 1, 0])
    constraints = "paper"        # "paper" | "normal" | "none" (default "paper")
    policy = "F"                 # "F" | "Fperp" (default "F")
    mode = "C"                   # "C" | "V" (default "C")

    [trial]                      # the paper's defaults
    threshold_deg = 3.0          # [0, 180] degrees
    hold_s = 0.5                 # [0, 600] seconds, at most timeout_s
    timeout_s = 90.0             # (0, 1800] seconds

The [trial] ranges are the core's (``graspguide.core._core.TRIAL_LIMITS``, from
graspguide_cue/trial_config.h), so the file, the core and the device accept the same
values. The contacts must span like a hand in the stated unit (:func:`hand_span_problem`:
the two farthest 5 mm to 0.5 m apart), so a file in millimetres that says ``units = "m"``
is refused, not guided.

:func:`load_scene` returns a :class:`Scene`; :meth:`Scene.to_dict` is its normalised form
(metres, every default filled in) and :meth:`Scene.config_hash` the sha256 of that form as
canonical JSON (sorted keys, no spaces), stable across runs and machines.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from graspguide.core.units import UNITS, hand_span_problem
from graspguide.core.vocabulary import CONSTRAINT_MODELS, FINGERS, MODES, POLICIES
from graspguide.protocol.toml_file import load_toml

TRIAL_DEFAULTS = {"threshold_deg": 3.0, "hold_s": 0.5, "timeout_s": 90.0}

_TABLES = {
    "scene": {"units"},
    "contacts": set(FINGERS) | {"y_axis", "constraints", "policy", "mode"},
    "trial": set(TRIAL_DEFAULTS),
}


class SceneError(ValueError):
    """A scene file that cannot be used; the message names the file, the key and the fix."""


# --------------------------------------------------------------------------------------
# Checks every reader of trial fields and contacts shares (scene and protocol files,
# `graspguide solve`, `graspguide stream`, pose sources)
# --------------------------------------------------------------------------------------
_TRIAL_UNITS = {"threshold_deg": "degrees", "hold_s": "seconds", "timeout_s": "seconds"}


def trial_limits() -> dict[str, dict[str, Any]]:
    """The core's range of each trial field: key -> {"min", "max", "min_exclusive"}.
    Read from the compiled core, never copied, so the readers cannot drift from it."""
    from graspguide.core._core import TRIAL_LIMITS

    return TRIAL_LIMITS


def trial_range_text(key: str) -> str:
    """The accepted range of a trial field as it reads in an error: "[0, 600] seconds"."""
    r = trial_limits()[key]
    low = "(" if r["min_exclusive"] else "["
    text = f"{low}{r['min']:g}, {r['max']:g}] {_TRIAL_UNITS[key]}"
    return text + ", at most timeout_s" if key == "hold_s" else text


def check_trial_fields(
    values: Mapping[str, Any], fail: Callable[[str, str], Exception]
) -> dict[str, float]:
    """threshold_deg, hold_s and timeout_s as floats, each checked against the core's
    range (and hold_s <= timeout_s, or the trial could never succeed); ``fail(key,
    message)`` makes the exception raised for the first bad one."""
    out: dict[str, float] = {}
    for key in TRIAL_DEFAULTS:
        value = values[key]
        if not _is_number(value):
            raise fail(key, f"must be a number in {trial_range_text(key)}, got {value!r}")
        v = float(value)
        r = trial_limits()[key]
        # written so that NaN fails: it compares false with everything
        if not ((v > r["min"] if r["min_exclusive"] else v >= r["min"]) and v <= r["max"]):
            raise fail(key, f"must be in {trial_range_text(key)}, got {value!r}")
        out[key] = v
    if out["hold_s"] > out["timeout_s"]:
        raise fail(
            "hold_s",
            f"must not exceed timeout_s ({out['timeout_s']:g} s), got "
            f"{out['hold_s']:g}: the trial could never succeed",
        )
    return out


def file_unit_fix(key: str, sym: str | None) -> str:
    """How to fix a file's contacts whose likely unit is ``sym`` (hand_span_problem)."""
    if sym in UNITS:
        return f'set {key} = "{sym}"'
    if sym == "cm":
        return f'give the contacts in millimetres (x 10) and set {key} = "mm"'
    return f'{key} ("m" or "mm") is the unit of the contact positions'


@dataclass(frozen=True)
class Scene:
    contacts: tuple[tuple[float, float, float], ...]  # metres, thumb, index, middle(, palm)
    y_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    constraints: str = "paper"
    policy: str = "F"
    mode: str = "C"
    threshold_deg: float = 3.0
    hold_s: float = 0.5
    timeout_s: float = 90.0
    source: str | None = field(default=None, compare=False)
    units: str = field(default="m", compare=False)  # units of the file (informational)

    @property
    def k(self) -> int:
        return len(self.contacts)

    @property
    def fingers(self) -> tuple[str, ...]:
        return FINGERS[: self.k]

    def to_dict(self) -> dict[str, Any]:
        """The normalised configuration (metres, defaults filled in)."""
        return {
            "k": self.k,
            "contacts_m": [list(c) for c in self.contacts],
            "y_axis": list(self.y_axis),
            "constraints": self.constraints,
            "policy": self.policy,
            "mode": self.mode,
            "threshold_deg": self.threshold_deg,
            "hold_s": self.hold_s,
            "timeout_s": self.timeout_s,
        }

    def canonical_json(self) -> str:
        return canonical_json(self.to_dict())

    def config_hash(self) -> str:
        return config_hash(self.to_dict())

    def set_scene_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :meth:`graspguide.link.client.DeviceClient.set_scene`: the
        normalised configuration without k, the contacts (metres) named as SET_SCENE's."""
        kwargs = self.to_dict()
        del kwargs["k"]
        kwargs["contacts"] = kwargs.pop("contacts_m")
        return kwargs


def canonical_json(obj: Any) -> str:
    return json.dumps(
        obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    )


def config_hash(obj: Any) -> str:
    """sha256 (hex) of ``obj`` as canonical JSON."""
    return hashlib.sha256(canonical_json(obj).encode("ascii")).hexdigest()


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _vector(where: str, key: str, value: Any, divisor: float = 1.0) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3 or not all(_is_number(x) for x in value):
        raise SceneError(f"{where}: {key} must be a list of 3 numbers [x, y, z], got {value!r}")
    out = tuple(float(x) / divisor for x in value)
    if not all(math.isfinite(x) for x in out):
        raise SceneError(f"{where}: {key} must be finite numbers, got {value!r}")
    return out  # type: ignore[return-value]


def _choice(where: str, key: str, value: Any, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise SceneError(
            f"{where}: {key} must be one of {', '.join(repr(a) for a in allowed)}, got {value!r}"
        )
    return value


def parse_scene(data: dict[str, Any], source: str = "<scene>") -> Scene:
    """A :class:`Scene` from the parsed TOML ``data``; ``source`` names it in errors."""
    if not isinstance(data, dict):
        raise SceneError(f"{source}: expected a TOML document with tables")
    for table in data:
        if table not in _TABLES:
            raise SceneError(
                f"{source}: unknown table [{table}]; the tables are "
                f"{', '.join('[' + t + ']' for t in _TABLES)}"
            )
        if not isinstance(data[table], dict):
            raise SceneError(
                f"{source}: {table} must be a table ([{table}]), got {type(data[table]).__name__}"
            )
        for key in data[table]:
            if key not in _TABLES[table]:
                raise SceneError(
                    f"{source}: unknown key {key!r} in [{table}]; allowed: "
                    f"{', '.join(sorted(_TABLES[table]))}"
                )
    scene_t = data.get("scene", {})
    if "units" not in scene_t:
        raise SceneError(
            f'{source}: [scene] units is missing: add units = "m" or '
            'units = "mm" (the unit of the contact positions)'
        )
    units = _choice(f"{source}: [scene]", "units", scene_t["units"], tuple(UNITS))
    scale = UNITS[units]

    ct = data.get("contacts")
    if ct is None:
        raise SceneError(
            f"{source}: the [contacts] table is missing: add thumb, index, "
            "middle (and optionally palm) as [x, y, z]"
        )
    where = f"{source}: [contacts]"
    missing = [f for f in FINGERS[:3] if f not in ct]
    if missing:
        raise SceneError(
            f"{where}: missing {', '.join(missing)}: thumb, index and middle "
            "are required ([x, y, z] each), palm is optional"
        )
    names = list(FINGERS[:3]) + (["palm"] if "palm" in ct else [])
    raw = [_vector(where, n, ct[n]) for n in names]
    problem = hand_span_problem(raw, units, lambda sym: file_unit_fix("[scene] units", sym))
    if problem:
        raise SceneError(f"{where}: {problem}")
    contacts = tuple(tuple(x / scale for x in c) for c in raw)
    y_axis = _vector(where, "y_axis", ct.get("y_axis", [0.0, 1.0, 0.0]))
    if math.sqrt(sum(x * x for x in y_axis)) < 1e-9:
        raise SceneError(f"{where}: y_axis must not be zero")
    constraints = _choice(where, "constraints", ct.get("constraints", "paper"), CONSTRAINT_MODELS)
    policy = _choice(where, "policy", ct.get("policy", "F"), POLICIES)
    mode = _choice(where, "mode", ct.get("mode", "C"), MODES)

    trial = check_trial_fields(
        {**TRIAL_DEFAULTS, **data.get("trial", {})},
        lambda key, message: SceneError(f"{source}: [trial] {key} {message}"),
    )
    return Scene(
        contacts=contacts,
        y_axis=y_axis,
        constraints=constraints,
        policy=policy,
        mode=mode,
        source=source,
        units=units,
        **trial,
    )


def load_scene(path: str) -> Scene:
    """Read and check a scene.toml; SceneError (naming the file) on any problem."""
    return parse_scene(load_toml(path, SceneError, "scene file"), path)


__all__ = [
    "Scene",
    "SceneError",
    "load_scene",
    "parse_scene",
    "config_hash",
    "canonical_json",
    "FINGERS",
    "check_trial_fields",
    "trial_limits",
    "trial_range_text",
]
