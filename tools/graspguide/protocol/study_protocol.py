"""A study protocol file (``protocols/paper.toml``): the hand geometry per contact
configuration, the conditions, how the target wrenches are drawn, the per-participant
order, and the trial parameters; and the deterministic plan of one participant's trials.

The format is documented in docs/study.md (every key, its default, what it means).
:func:`load_protocol` reads and checks a file (an unknown key or a bad value is a
:class:`ProtocolFileError` naming the file, the key and what to put there);
:func:`draw_wrenches` draws the wrench set (seeded, pure Python ``random.Random``, so it
does not depend on the numpy version); :func:`plan` lists one participant's trials.

Rules (docs/study.md explains why):

* **single motor**: a wrench "drives a single motor" in a condition (k, policy) when the
  core (:func:`graspguide.core.solver.solve`, mode C, the protocol's constraint model) at the
  trial's start orientation answers ``ok`` with exactly one motor PWM > 0. The paper's
  split (5 single, 7 several) is reproduced in the reference condition
  ``[wrenches] split_k`` / ``split_policy``; every trial also carries the flag for its own
  condition.
* **order**: sessions are (contact count, modality) blocks. Contact counts in the order
  ``[conditions] contact_counts`` or reversed (``contact_order = "alternate"``); within
  each, the modalities in the participant's row of a balanced (Williams) Latin square
  (``modality_order = "balanced_latin_square"``); the wrenches of each session shuffled
  (seeded by the protocol seed, the participant and the session).
* **participant number**: the counterbalancing row comes from the number at the end of
  the participant id (U1 -> 1, P07 -> 7).
"""

from __future__ import annotations

import hashlib
import math
import random
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from graspguide.core.units import UNITS, hand_span_problem, moment_unit_problem
from graspguide.core.vocabulary import CONSTRAINT_MODELS, FINGERS, MODALITIES
from graspguide.protocol.scene_file import (
    TRIAL_DEFAULTS,
    canonical_json,
    check_trial_fields,
    config_hash,
    file_unit_fix,
)
from graspguide.protocol.toml_file import load_toml

MODALITY_ORDERS = ("balanced_latin_square", "random", "fixed")
CONTACT_ORDERS = ("alternate", "fixed")
WRENCH_ORDERS = ("shuffle", "fixed")
PARTICIPANT_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,30}?([0-9]+)$")

# Below 5 Hz the poses come further apart than the device's 200 ms POSE watchdog, which
# would turn the motors off between them; 2000 Hz is the fastest motion capture (a
# 115200-baud link carries about 150 POSEs per second: on a board the link is the limit).
POSE_RATE_HZ = (5.0, 2000.0)

# table -> {key: (required, default)}; None default with required False: optional.
_SCHEMA: dict[str, dict[str, tuple[bool, Any]]] = {
    "study": {
        "name": (True, None),
        "seed": (True, None),
        "participants": (False, 8),
        "pose_rate_hz": (False, 100.0),
    },
    "trial": {
        "threshold_deg": (False, 3.0),
        "hold_s": (False, 0.5),
        "timeout_s": (False, 90.0),
        "constraints": (False, "paper"),
        "start_quat": (False, [1.0, 0.0, 0.0, 0.0]),
    },
    "hand": {
        "units": (True, None),
        "y_axis": (False, [0.0, 1.0, 0.0]),
        "k3": (False, None),
        "k4": (False, None),
    },
    "conditions": {
        "modalities": (False, list(MODALITIES)),
        "contact_counts": (False, [3, 4]),
        "modality_order": (False, "balanced_latin_square"),
        "contact_order": (False, "alternate"),
        "wrench_order": (False, "shuffle"),
    },
    "wrenches": {
        "count": (False, 12),
        "single_motor": (False, 5),
        "split_k": (False, 3),
        "split_policy": (False, "Fperp"),
        "force_N": (False, 1.0),
        "moment_max_Nm": (False, 0.0),
        "start_error_deg": (False, [20.0, 120.0]),
        "max_draws": (False, 100000),
    },
    "familiarization": {"duration_s": (False, 120.0), "trials": (False, 0)},
}


class ProtocolFileError(ValueError):
    """A protocol file that cannot be used; the message names the file, the key and the
    fix."""


def modality_parts(modality: str) -> tuple[str, str]:
    """("F"|"Fperp", "C"|"V") of a modality name such as "Fperp+C"."""
    policy, _, mode = modality.partition("+")
    return policy, mode


def derive_seed(*parts: Any) -> int:
    """A 64-bit seed from the parts (sha256 of their text): stable across runs,
    machines and Python versions."""
    text = ":".join(str(p) for p in parts)
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "big")


def participant_number(participant: str) -> int:
    """The number at the end of a participant id (U1 -> 1); ProtocolFileError if the id
    is not a short name ending in a number."""
    m = PARTICIPANT_RE.match(participant or "")
    if not m or int(m.group(1)) < 1:
        raise ProtocolFileError(
            f"participant id {participant!r}: use a letter, then letters, digits, '-' or "
            "'_', ending with a number >= 1 (U1, U2, P07): the number picks the "
            "participant's counterbalanced order"
        )
    return int(m.group(1))


# --------------------------------------------------------------------------------------
# The protocol
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Wrench:
    id: str
    wrench: tuple[float, ...]
    wrench_class: str  # "single" | "multi" | "" (familiarization)
    single_motor: dict[str, bool] = field(default_factory=dict)  # "k3/Fperp" -> bool
    start_error_deg: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "wrench": list(self.wrench),
            "class": self.wrench_class,
            "single_motor": dict(self.single_motor),
            "start_error_deg": self.start_error_deg,
        }


@dataclass(frozen=True)
class Protocol:
    name: str
    seed: int
    participants: int
    pose_rate_hz: float
    threshold_deg: float
    hold_s: float
    timeout_s: float
    constraints: str
    start_quat: tuple[float, float, float, float]
    y_axis: tuple[float, float, float]
    hands: dict[int, tuple[tuple[float, float, float], ...]]  # k -> contacts (metres)
    modalities: tuple[str, ...]
    contact_counts: tuple[int, ...]
    modality_order: str
    contact_order: str
    wrench_order: str
    wrench_count: int
    single_motor: int
    split_k: int
    split_policy: str
    force_N: float
    moment_max_Nm: float
    start_error_deg: tuple[float, float]
    max_draws: int
    familiarization_s: float
    familiarization_trials: int
    source: str = field(default="<protocol>", compare=False)

    def to_dict(self) -> dict[str, Any]:
        """The normalised protocol (metres, defaults filled in): what is hashed."""
        return {
            "study": {
                "name": self.name,
                "seed": self.seed,
                "participants": self.participants,
                "pose_rate_hz": self.pose_rate_hz,
            },
            "trial": {
                "threshold_deg": self.threshold_deg,
                "hold_s": self.hold_s,
                "timeout_s": self.timeout_s,
                "constraints": self.constraints,
                "start_quat": list(self.start_quat),
            },
            "hand": {
                "y_axis": list(self.y_axis),
                **{f"k{k}": [list(c) for c in cs] for k, cs in sorted(self.hands.items())},
            },
            "conditions": {
                "modalities": list(self.modalities),
                "contact_counts": list(self.contact_counts),
                "modality_order": self.modality_order,
                "contact_order": self.contact_order,
                "wrench_order": self.wrench_order,
            },
            "wrenches": {
                "count": self.wrench_count,
                "single_motor": self.single_motor,
                "split_k": self.split_k,
                "split_policy": self.split_policy,
                "force_N": self.force_N,
                "moment_max_Nm": self.moment_max_Nm,
                "start_error_deg": list(self.start_error_deg),
                "max_draws": self.max_draws,
            },
            "familiarization": {
                "duration_s": self.familiarization_s,
                "trials": self.familiarization_trials,
            },
        }

    def canonical_json(self) -> str:
        return canonical_json(self.to_dict())

    @property
    def config_hash(self) -> str:
        """sha256 of the normalised protocol as canonical JSON."""
        return config_hash(self.to_dict())

    @property
    def policies(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(modality_parts(m)[0] for m in self.modalities))

    @property
    def sessions_per_participant(self) -> int:
        return len(self.modalities) * len(self.contact_counts)


# --------------------------------------------------------------------------------------
# Loading and checking
# --------------------------------------------------------------------------------------
def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class _Checker:
    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, message: str) -> ProtocolFileError:
        return ProtocolFileError(f"{self.source}: {where}: {message}")

    def number(
        self, where: str, v: Any, lo: float, hi: float, unit: str = "", lo_open: bool = False
    ) -> float:
        accepted = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]{' ' + unit if unit else ''}"
        if not _is_number(v):
            raise self.fail(where, f"must be a number in {accepted}, got {v!r}")
        # written so that NaN fails: it compares false with everything
        if not ((v > lo if lo_open else v >= lo) and v <= hi):
            raise self.fail(where, f"must be in {accepted}, got {v!r}")
        return float(v)

    def integer(self, where: str, v: Any, lo: int, hi: int, what: str = "") -> int:
        if not isinstance(v, int) or isinstance(v, bool):
            raise self.fail(where, f"must be an integer in {lo}..{hi}{what}, got {v!r}")
        if not lo <= v <= hi:
            raise self.fail(where, f"must be in {lo}..{hi}{what}, got {v!r}")
        return int(v)

    def choice(self, where: str, v: Any, allowed: Sequence[Any]) -> Any:
        if v not in allowed or isinstance(v, bool):
            raise self.fail(
                where, f"must be one of {', '.join(repr(a) for a in allowed)}, got {v!r}"
            )
        return v

    def vector(self, where: str, v: Any, n: int, divisor: float = 1.0) -> tuple[float, ...]:
        if not isinstance(v, list) or len(v) != n or not all(_is_number(x) for x in v):
            raise self.fail(where, f"must be a list of {n} numbers, got {v!r}")
        out = tuple(float(x) / divisor for x in v)
        if not all(math.isfinite(x) for x in out):
            raise self.fail(where, f"must be finite numbers, got {v!r}")
        return out


def parse_protocol(data: dict[str, Any], source: str = "<protocol>") -> Protocol:
    """A :class:`Protocol` from parsed TOML; ``source`` names it in errors."""
    c = _Checker(source)
    if not isinstance(data, dict):
        raise ProtocolFileError(f"{source}: expected a TOML document with tables")
    for table, value in data.items():
        if table not in _SCHEMA:
            raise c.fail(
                f"[{table}]",
                "unknown table; the tables are " + ", ".join(f"[{t}]" for t in _SCHEMA),
            )
        if not isinstance(value, dict):
            raise c.fail(table, f"must be a table ([{table}]), got {type(value).__name__}")
        for key in value:
            if key not in _SCHEMA[table]:
                raise c.fail(
                    f"[{table}] {key}", "unknown key; allowed: " + ", ".join(sorted(_SCHEMA[table]))
                )
    for table in ("study", "hand"):
        if table not in data:
            raise c.fail(f"[{table}]", "table missing; see docs/study.md for its keys")

    def get(table: str, key: str) -> Any:
        required, default = _SCHEMA[table][key]
        t = data.get(table, {})
        if key not in t:
            if required:
                raise c.fail(f"[{table}] {key}", "missing; see docs/study.md")
            return default
        return t[key]

    name = get("study", "name")
    if not isinstance(name, str) or not name.strip():
        raise c.fail("[study] name", f"must be a non-empty string, got {name!r}")
    seed = c.integer("[study] seed", get("study", "seed"), 0, 2**63 - 1)
    participants = c.integer("[study] participants", get("study", "participants"), 1, 10000)
    rate = c.number(
        "[study] pose_rate_hz", get("study", "pose_rate_hz"), *POSE_RATE_HZ, "poses per second"
    )

    trial = check_trial_fields(
        {k: get("trial", k) for k in TRIAL_DEFAULTS},
        lambda key, message: c.fail(f"[trial] {key}", message),
    )
    threshold, hold, timeout = (trial[k] for k in ("threshold_deg", "hold_s", "timeout_s"))
    constraints = c.choice("[trial] constraints", get("trial", "constraints"), CONSTRAINT_MODELS)
    start_quat = c.vector("[trial] start_quat", get("trial", "start_quat"), 4)
    qn = math.sqrt(sum(x * x for x in start_quat))
    if abs(qn - 1.0) > 1e-6:
        raise c.fail(
            "[trial] start_quat", f"must be a unit quaternion [w, x, y, z], its norm is {qn:.6g}"
        )

    units = c.choice("[hand] units", get("hand", "units"), tuple(UNITS))
    y_axis = c.vector("[hand] y_axis", get("hand", "y_axis"), 3)
    if math.sqrt(sum(x * x for x in y_axis)) < 1e-9:
        raise c.fail("[hand] y_axis", "must not be zero")

    cond_modalities = get("conditions", "modalities")
    if (
        not isinstance(cond_modalities, list)
        or not cond_modalities
        or any(m not in MODALITIES for m in cond_modalities)
    ):
        raise c.fail(
            "[conditions] modalities",
            f"must be a non-empty list of {', '.join(repr(m) for m in MODALITIES)}, "
            f"got {cond_modalities!r}",
        )
    if len(set(cond_modalities)) != len(cond_modalities):
        raise c.fail("[conditions] modalities", f"lists a modality twice: {cond_modalities!r}")
    counts = get("conditions", "contact_counts")
    if (
        not isinstance(counts, list)
        or not counts
        or any(isinstance(k, bool) or k not in (3, 4) for k in counts)
        or len(set(counts)) != len(counts)
    ):
        raise c.fail(
            "[conditions] contact_counts", f"must be [3], [4], [3, 4] or [4, 3], got {counts!r}"
        )
    modality_order = c.choice(
        "[conditions] modality_order", get("conditions", "modality_order"), MODALITY_ORDERS
    )
    contact_order = c.choice(
        "[conditions] contact_order", get("conditions", "contact_order"), CONTACT_ORDERS
    )
    wrench_order = c.choice(
        "[conditions] wrench_order", get("conditions", "wrench_order"), WRENCH_ORDERS
    )

    hands: dict[int, tuple[tuple[float, float, float], ...]] = {}
    for k in (3, 4):
        table = get("hand", f"k{k}")
        where = f"[hand.k{k}]"
        if table is None:
            if k in counts:
                raise c.fail(
                    where,
                    f"missing: contact_counts uses k = {k}; add [hand.k{k}] "
                    f"with {', '.join(FINGERS[:k])} = [x, y, z]",
                )
            continue
        if not isinstance(table, dict):
            raise c.fail(where, "must be a table of finger = [x, y, z]")
        unknown = [f for f in table if f not in FINGERS[:k]]
        if unknown:
            raise c.fail(
                f"{where} {unknown[0]}", f"unknown contact; k = {k} has {', '.join(FINGERS[:k])}"
            )
        missing = [f for f in FINGERS[:k] if f not in table]
        if missing:
            raise c.fail(
                where,
                f"missing {', '.join(missing)} (k = {k} needs "
                f"{', '.join(FINGERS[:k])}, each [x, y, z] in {units})",
            )
        raw = [c.vector(f"{where} {f}", table[f], 3) for f in FINGERS[:k]]
        problem = hand_span_problem(raw, units, lambda sym: file_unit_fix("[hand] units", sym))
        if problem:
            raise c.fail(where, problem)
        hands[k] = tuple(tuple(x / UNITS[units] for x in p) for p in raw)  # type: ignore

    count = c.integer("[wrenches] count", get("wrenches", "count"), 1, 1000)
    single = c.integer(
        "[wrenches] single_motor",
        get("wrenches", "single_motor"),
        0,
        count,
        f" (at most count = {count})",
    )
    split_k = c.choice("[wrenches] split_k", get("wrenches", "split_k"), (3, 4))
    if split_k not in hands:
        raise c.fail("[wrenches] split_k", f"k = {split_k} has no [hand.k{split_k}]")
    split_policy = c.choice(
        "[wrenches] split_policy", get("wrenches", "split_policy"), ("F", "Fperp")
    )
    force = c.number(
        "[wrenches] force_N", get("wrenches", "force_N"), 0.0, 1000.0, "N", lo_open=True
    )
    moment = c.number(
        "[wrenches] moment_max_Nm", get("wrenches", "moment_max_Nm"), 0.0, 100.0, "N m"
    )
    for k, contacts in sorted(hands.items()):
        problem = moment_unit_problem(contacts, [force, 0.0, 0.0, moment, 0.0, 0.0])
        if problem:
            raise c.fail("[wrenches] moment_max_Nm", f"with force_N and [hand.k{k}]: {problem}")
    span = get("wrenches", "start_error_deg")
    if (
        not isinstance(span, list)
        or len(span) != 2
        or not all(_is_number(x) for x in span)
        or not 0.0 <= span[0] < span[1] <= 180.0
    ):  # NaN fails the comparison
        raise c.fail(
            "[wrenches] start_error_deg",
            f"must be [min, max] with 0 <= min < max <= 180 degrees, got {span!r}",
        )
    lo, hi = float(span[0]), float(span[1])
    if lo <= threshold:
        raise c.fail(
            "[wrenches] start_error_deg",
            f"the minimum ({lo:g}) must exceed "
            f"[trial] threshold_deg ({threshold:g}), or a trial could start aligned",
        )
    max_draws = c.integer("[wrenches] max_draws", get("wrenches", "max_draws"), 1, 10**7)

    fam_s = c.number(
        "[familiarization] duration_s", get("familiarization", "duration_s"), 0.0, 3600.0, "seconds"
    )
    fam_n = c.integer("[familiarization] trials", get("familiarization", "trials"), 0, 100)

    return Protocol(
        name=name,
        seed=seed,
        participants=participants,
        pose_rate_hz=rate,
        threshold_deg=threshold,
        hold_s=hold,
        timeout_s=timeout,
        constraints=constraints,
        start_quat=start_quat,
        y_axis=y_axis,
        hands=hands,
        modalities=tuple(cond_modalities),
        contact_counts=tuple(counts),
        modality_order=modality_order,
        contact_order=contact_order,
        wrench_order=wrench_order,
        wrench_count=count,
        single_motor=single,
        split_k=split_k,
        split_policy=split_policy,
        force_N=force,
        moment_max_Nm=moment,
        start_error_deg=(lo, hi),
        max_draws=max_draws,
        familiarization_s=fam_s,
        familiarization_trials=fam_n,
        source=source,
    )


def load_protocol(path: str) -> Protocol:
    """Read and check a protocol file; ProtocolFileError (naming the file) on any
    problem."""
    return parse_protocol(load_toml(path, ProtocolFileError, "protocol file"), path)


# --------------------------------------------------------------------------------------
# Wrenches
# --------------------------------------------------------------------------------------
def motors_driven(protocol: Protocol, k: int, policy: str, wrench: Sequence[float]) -> int | None:
    """How many motors the core drives (PWM > 0) for this wrench in condition (k, policy)
    at the protocol's start orientation, mode C; None if the core cannot solve it."""
    from graspguide.core import solver

    r = solver.solve(
        [list(c) for c in protocol.hands[k]],
        list(wrench),
        policy=policy,
        mode="C",
        constraints=protocol.constraints,
        orientation=list(protocol.start_quat),
        y_axis=list(protocol.y_axis),
    )
    if r["status"] != "ok":
        return None
    return sum(1 for p in r["pwm"] if p > 0)


def _start_error_deg(protocol: Protocol, k: int, wrench: Sequence[float]) -> float | None:
    from graspguide.core import solver

    r = solver.solve(
        [list(c) for c in protocol.hands[k]],
        list(wrench),
        policy="F",
        mode="V",
        constraints=protocol.constraints,
        orientation=list(protocol.start_quat),
        y_axis=list(protocol.y_axis),
    )
    return None if r["status"] != "ok" else float(r["error_deg"])


def _candidate(rng: random.Random, protocol: Protocol) -> tuple[float, ...]:
    # force direction uniform on the sphere, moment uniform in a ball of moment_max_Nm
    while True:
        f = [rng.gauss(0.0, 1.0) for _ in range(3)]
        n = math.sqrt(sum(x * x for x in f))
        if n > 1e-9:
            break
    f = [protocol.force_N * x / n for x in f]
    m = [0.0, 0.0, 0.0]
    if protocol.moment_max_Nm > 0:
        while True:
            m = [rng.uniform(-1.0, 1.0) for _ in range(3)]
            if sum(x * x for x in m) <= 1.0:
                break
        m = [protocol.moment_max_Nm * x for x in m]
    return tuple(round(x, 4) + 0.0 for x in f + m)


def _classify(protocol: Protocol, w: tuple[float, ...]) -> tuple[dict[str, bool], float] | None:
    """Single-motor flags of every condition, and the start error; None when the wrench
    is unusable (the core fails in a condition, or the start error is out of range)."""
    errs = []
    for k in protocol.hands:
        e = _start_error_deg(protocol, k, w)
        if e is None:
            return None
        errs.append(e)
    err = errs[0]
    lo, hi = protocol.start_error_deg
    if not lo <= err <= hi:
        return None
    flags: dict[str, bool] = {}
    for k in sorted(protocol.hands):
        for policy in ("F", "Fperp"):
            n = motors_driven(protocol, k, policy, w)
            if n is None or n == 0:
                return None
            flags[f"k{k}/{policy}"] = n == 1
    return flags, round(err, 3)


def draw_wrenches(protocol: Protocol) -> list[Wrench]:
    """The protocol's wrench set, W01..Wnn: ``single_motor`` of them drive a single motor
    in the reference condition (split_k, split_policy), the others several. Every wrench
    is solvable in every condition and starts ``start_error_deg`` off gravity.
    Deterministic for the protocol (seeded by [study] seed)."""
    rng = random.Random(derive_seed(protocol.seed, "wrenches"))
    want = {"single": protocol.single_motor, "multi": protocol.wrench_count - protocol.single_motor}
    got: list[tuple[tuple[float, ...], str, dict[str, bool], float]] = []
    have = {"single": 0, "multi": 0}
    ref = f"k{protocol.split_k}/{protocol.split_policy}"
    for _ in range(protocol.max_draws):
        w = _candidate(rng, protocol)
        c = _classify(protocol, w)
        if c is None:
            continue
        flags, err = c
        cls = "single" if flags[ref] else "multi"
        if have[cls] >= want[cls]:
            continue
        have[cls] += 1
        got.append((w, cls, flags, err))
        if have == want:
            break
    else:
        raise ProtocolFileError(
            f"{protocol.source}: [wrenches]: only {have['single']} of {want['single']} "
            f"single-motor and {have['multi']} of {want['multi']} multi-motor wrenches found "
            f"in max_draws = {protocol.max_draws} draws for k = {protocol.split_k}, policy "
            f"{protocol.split_policy} (with policy F a motor's level is |lambda_i|, which is "
            'hardly ever exactly zero: use split_policy = "Fperp"), or lower single_motor, '
            "or widen start_error_deg, or raise max_draws"
        )
    width = max(2, len(str(len(got))))
    return [
        Wrench(
            id=f"W{i + 1:0{width}d}",
            wrench=w,
            wrench_class=cls,
            single_motor=flags,
            start_error_deg=err,
        )
        for i, (w, cls, flags, err) in enumerate(got)
    ]


def draw_familiarization_wrenches(protocol: Protocol) -> list[Wrench]:
    """Wrenches of the familiarization trials (F01..): drawn like the others from their
    own seed, without the split."""
    n = protocol.familiarization_trials
    if n == 0:
        return []
    rng = random.Random(derive_seed(protocol.seed, "familiarization"))
    out: list[Wrench] = []
    for _ in range(protocol.max_draws):
        w = _candidate(rng, protocol)
        c = _classify(protocol, w)
        if c is None:
            continue
        out.append(
            Wrench(
                id=f"F{len(out) + 1:02d}",
                wrench=w,
                wrench_class="",
                single_motor=c[0],
                start_error_deg=c[1],
            )
        )
        if len(out) == n:
            return out
    raise ProtocolFileError(
        f"{protocol.source}: [familiarization]: only {len(out)} of {n} "
        f"usable wrenches in max_draws = {protocol.max_draws} draws"
    )


# --------------------------------------------------------------------------------------
# Order and plan
# --------------------------------------------------------------------------------------
def balanced_latin_square(n: int) -> list[list[int]]:
    """Rows of a Williams design over n conditions: every condition once in every position
    across the rows, and (for even n) every ordered pair of neighbours exactly once. n rows
    for even n, 2n (the square and its mirror) for odd n."""
    first = [0]
    lo, hi = 1, n - 1
    take_lo = True
    while len(first) < n:
        if take_lo:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
        take_lo = not take_lo
    rows = [[(x + r) % n for x in first] for r in range(n)]
    if n % 2:
        rows += [list(reversed(row)) for row in rows]
    return rows


@dataclass(frozen=True)
class PlannedTrial:
    trial_index: int  # 1..N, the order of the run
    participant: str
    session: int  # 0: familiarization; 1..S: the (k, modality) blocks
    session_trial: int  # 1..n within the session
    k: int
    policy: str
    mode: str
    modality: str
    wrench_id: str
    wrench: tuple[float, ...]
    single_motor: bool  # in this trial's (k, policy), at the start orientation
    wrench_class: str  # "single"/"multi" in the reference condition; "" for F..
    familiarization: bool

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "wrench": list(self.wrench)}


@dataclass(frozen=True)
class Session:
    session: int
    k: int
    modality: str

    @property
    def policy(self) -> str:
        return modality_parts(self.modality)[0]

    @property
    def mode(self) -> str:
        return modality_parts(self.modality)[1]


def session_order(protocol: Protocol, participant: str) -> list[Session]:
    """The participant's sessions 1..S in run order."""
    n = participant_number(participant)
    mods = list(protocol.modalities)
    if protocol.modality_order == "balanced_latin_square":
        rows = balanced_latin_square(len(mods))
        row = rows[(n - 1) % len(rows)]
        order = [mods[i] for i in row]
        n_rows = len(rows)
    elif protocol.modality_order == "random":
        order = list(mods)
        random.Random(derive_seed(protocol.seed, "modality_order", participant)).shuffle(order)
        n_rows = 1
    else:
        order, n_rows = list(mods), 1
    counts = list(protocol.contact_counts)
    if protocol.contact_order == "alternate" and len(counts) == 2:
        # alternate across participants, and flip for each further pass through the rows,
        # so that every (row, contact order) pair occurs once in 2 * rows participants
        if ((n - 1) + (n - 1) // n_rows) % 2:
            counts.reverse()
    sessions: list[Session] = []
    for k in counts:
        for m in order:
            sessions.append(Session(len(sessions) + 1, k, m))
    return sessions


def plan(
    protocol: Protocol,
    participant: str,
    wrenches: list[Wrench] | None = None,
    familiarization: list[Wrench] | None = None,
) -> list[PlannedTrial]:
    """Every trial of one participant, in run order (deterministic): the familiarization
    trials (session 0) first, then each session's wrenches. ``wrenches`` /
    ``familiarization``: the drawn sets, when the caller has them already."""
    if wrenches is None:
        wrenches = draw_wrenches(protocol)
    if familiarization is None:
        familiarization = draw_familiarization_wrenches(protocol)
    sessions = session_order(protocol, participant)
    trials: list[PlannedTrial] = []

    def add(session: int, pos: int, k: int, modality: str, w: Wrench, fam: bool) -> None:
        policy, mode = modality_parts(modality)
        trials.append(
            PlannedTrial(
                trial_index=len(trials) + 1,
                participant=participant,
                session=session,
                session_trial=pos,
                k=k,
                policy=policy,
                mode=mode,
                modality=modality,
                wrench_id=w.id,
                wrench=tuple(w.wrench),
                single_motor=bool(w.single_motor[f"k{k}/{policy}"]),
                wrench_class=w.wrench_class,
                familiarization=fam,
            )
        )

    # familiarization: the first sessions' conditions in turn, first contact count
    for i, w in enumerate(familiarization):
        s = sessions[i % len(protocol.modalities)]
        add(0, i + 1, s.k, s.modality, w, True)
    for s in sessions:
        order = list(wrenches)
        if protocol.wrench_order == "shuffle":
            random.Random(
                derive_seed(protocol.seed, "wrench_order", participant, s.session)
            ).shuffle(order)
        for pos, w in enumerate(order, start=1):
            add(s.session, pos, s.k, s.modality, w, False)
    return trials


__all__ = [
    "Protocol",
    "ProtocolFileError",
    "Wrench",
    "PlannedTrial",
    "Session",
    "load_protocol",
    "parse_protocol",
    "draw_wrenches",
    "draw_familiarization_wrenches",
    "plan",
    "session_order",
    "balanced_latin_square",
    "participant_number",
    "derive_seed",
    "motors_driven",
    "modality_parts",
    "MODALITIES",
]
