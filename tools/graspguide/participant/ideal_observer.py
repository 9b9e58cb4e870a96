"""An ideal observer of the vibrotactile cue: how much of the target can anyone find?

SIMULATED. These are bounds computed from a model of the task, never human data.
``graspguide observer`` prints them for every condition of a protocol (:func:`run`).

The observer knows Algorithm 1, the hand's contacts and the task's prior over wrenches,
but not the wrench of the trial. docs/ideal-observer.md states the definitions and every
assumption; in short:

* **Target.** The trial succeeds when the gravity direction in the hand frame, ``u``,
  lies within ``threshold_deg`` of ``f_hat`` (the wrench force direction) for
  ``hold_s``. The observer must find ``f_hat`` on the sphere.
* **Search budget.** Any window of ``hold_s`` inside ``[0, T]`` contains one of the
  instants ``j * hold_s`` (``j = 0 .. floor(T / hold_s)``), and at that instant the hand
  is within the threshold of the target. So whatever the path, the targets a search can
  hit by ``T`` lie in the union of ``floor(T / hold_s) + 1`` caps of radius
  ``threshold_deg``: its area is at most that many cap areas (the search area).
* **Mode C.** The cue does not depend on the orientation (docs/algorithm.md, step 6), so
  all the observer learns is one reading of the pattern, then only "not yet" while it
  searches. Its success is at most the posterior mass of the best region of the search
  area: the highest-posterior cells of an equal-area grid (cell area = one cap) up to the
  search area. Two readings: which motors are on (exact), and the levels with
  multiplicative noise ``exp(weber * N(0, 1))`` per motor (a Weber fraction taken as the
  SD of the log-intensity).
* **Mode V.** The overall intensity gives the error angle at every pose, so an observer
  with unlimited readings localises the target: the upper bound is 1. What an explicit
  observer achieves (trilateration from three noisy readings, Weber noise, stated
  movement and reading times) is reported beside it as a lower bound on the ideal one.

Posterior masses come from ``n_prior`` seeded draws of the protocol's prior (the same
candidate and acceptance rules as :func:`graspguide.protocol.study_protocol.draw_wrenches`:
``candidate_wrench`` and ``classify_wrench``);
the expected bound averages over ``n_trials`` further draws. Sampling noise of a finite
prior sample makes a posterior spikier, which raises its best-region mass: the estimate
errs upward, the safe side for an upper bound.
"""

from __future__ import annotations

import math
import os
import random
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from graspguide.core import solver
from graspguide.protocol.study_protocol import (
    Protocol,
    candidate_wrench,
    classify_wrench,
    derive_seed,
    draw_wrenches,
    load_protocol,
    modality_parts,
)
from graspguide.repo_root import find_repo_root

#: Mode V reading: 3 ERM time constants (0.18 s) plus a simple reaction time (0.21 s),
#: the values of graspguide.participant.model.ParticipantParams (docs/participant.md).
V_READ_S = 0.39
#: Mode V movement: mean angular speed of a minimum-jerk rotation whose peak is 90 deg/s
#: (peak / 1.875), the participant model's peak speed.
V_MEAN_SPEED_DEG_S = 90.0 / 1.875


@dataclass(frozen=True)
class Bounds:
    """Upper bounds on the success rate of any observer (SIMULATED)."""

    k: int
    mode: str
    policy: str
    seed: int
    n_prior: int
    n_trials: int
    n_cells: int
    caps: int
    search_area_deg2: float
    search_fraction: float  # of the whole sphere
    weber_frac: float
    #: mode C, reading only which motors are on (expected over the prior)
    onoff_bound: float
    #: mode C, reading the levels too, at the Weber noise (expected over the prior)
    intensity_bound: float
    #: the bound for this mode: C -> intensity_bound (all the C cue carries), V -> 1
    bound: float
    #: mode V: the success of the explicit trilateration observer (a lower bound on the
    #: ideal observer); None in mode C
    v_achieved: float | None
    #: per wrench of the protocol: (id, on/off mass, intensity mass averaged over noise)
    protocol_wrenches: tuple[tuple[str, float, float], ...]
    simulated: bool = True


# --------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------
def cap_area_sr(threshold_deg: float) -> float:
    return 2.0 * math.pi * (1.0 - math.cos(math.radians(threshold_deg)))


def search_caps(search_s: float, hold_s: float) -> int:
    """How many threshold caps can hold every target a search of ``search_s`` can hit."""
    if hold_s <= 0:
        raise ValueError("hold_s must be > 0 for a finite search bound")
    return int(math.floor(search_s / hold_s + 1e-12)) + 1


class EqualAreaGrid:
    """Cells of equal area on the unit sphere: ``n_z`` bands equal in z (Archimedes:
    equal z steps are equal areas) times ``2 n_z`` equal longitude sectors."""

    def __init__(self, n_cells: int) -> None:
        self.n_z = max(1, round(math.sqrt(n_cells / 2.0)))
        self.n_phi = 2 * self.n_z
        self.n_cells = self.n_z * self.n_phi

    def index(self, u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(np.asarray(u, dtype=float))
        z = np.clip(u[:, 2], -1.0, 1.0)
        iz = np.minimum(((z + 1.0) / 2.0 * self.n_z).astype(int), self.n_z - 1)
        phi = np.arctan2(u[:, 1], u[:, 0]) % (2.0 * math.pi)
        ip = np.minimum((phi / (2.0 * math.pi) * self.n_phi).astype(int), self.n_phi - 1)
        return iz * self.n_phi + ip


def top_mass(weights: np.ndarray, n_top: float) -> float:
    """Largest total weight of ``n_top`` cells (a fractional last cell counts in part)."""
    w = np.sort(np.asarray(weights, dtype=float))[::-1]
    total = float(w.sum())
    if total <= 0:
        return 0.0
    whole = int(math.floor(n_top))
    mass = float(w[:whole].sum())
    if whole < len(w):
        mass += (n_top - whole) * float(w[whole])
    return min(1.0, mass / total)


# --------------------------------------------------------------------------------------
# The cue
# --------------------------------------------------------------------------------------
def cue_levels(
    contacts: Sequence[Sequence[float]],
    wrench: Sequence[float],
    policy: str,
    y_axis: Sequence[float] = (0.0, 1.0, 0.0),
    constraints: str = "paper",
) -> np.ndarray | None:
    """Motor levels |m_i| of the real core (mode C, which does not depend on the
    orientation); a motor with PWM 0 is off (level 0). None if the core cannot solve."""
    r = solver.solve(
        [list(c) for c in contacts],
        list(wrench),
        policy=policy,
        mode="C",
        constraints=constraints,
        orientation=[1.0, 0.0, 0.0, 0.0],
        y_axis=list(y_axis),
    )
    if r["status"] != "ok":
        return None
    lev = np.abs(np.asarray(r["levels"], dtype=float))
    lev[np.asarray(r["pwm"]) == 0] = 0.0
    return lev


def target_direction(wrench: Sequence[float]) -> np.ndarray:
    f = np.asarray(wrench[:3], dtype=float)
    return f / np.linalg.norm(f)


def draw_prior(protocol: Protocol, n: int, seed: int) -> list[tuple[float, ...]]:
    """``n`` wrenches from the protocol's prior: its candidate rule and its acceptance
    (solvable everywhere, start error in range, a motor on), seeded."""
    rng = random.Random(derive_seed(seed, "ideal-observer-prior", n))
    out: list[tuple[float, ...]] = []
    for _ in range(max(1, protocol.max_draws) * max(1, n)):
        w = candidate_wrench(rng, protocol)
        if classify_wrench(protocol, w) is not None:
            out.append(w)
            if len(out) == n:
                break
    return out


# --------------------------------------------------------------------------------------
# Mode C bounds from samples (the core of the definition; tests call these directly)
# --------------------------------------------------------------------------------------
def onoff_masses(
    prior_levels: np.ndarray,
    prior_dirs: np.ndarray,
    trial_levels: np.ndarray,
    grid: EqualAreaGrid,
    n_top: float,
) -> np.ndarray:
    """Per trial: the posterior mass of the best search region given which motors are on."""
    cells = grid.index(prior_dirs)
    keys = [bytes(row) for row in (prior_levels > 0).astype(np.uint8)]
    groups: dict[bytes, list[int]] = {}
    for i, key in enumerate(keys):
        groups.setdefault(key, []).append(i)
    cache: dict[bytes, float] = {}
    out = np.ones(len(trial_levels))
    for t, row in enumerate((np.asarray(trial_levels) > 0).astype(np.uint8)):
        key = bytes(row)
        if key not in groups:
            continue  # a pattern the sample never shows: no bound below 1
        if key not in cache:
            hist = np.bincount(cells[groups[key]], minlength=grid.n_cells)
            cache[key] = top_mass(hist, n_top)
        out[t] = cache[key]
    return out


def intensity_masses(
    prior_levels: np.ndarray,
    prior_dirs: np.ndarray,
    trial_levels: np.ndarray,
    grid: EqualAreaGrid,
    n_top: float,
    weber_frac: float,
    rng: np.random.Generator,
    n_noise: int = 1,
) -> np.ndarray:
    """Per trial: the posterior mass of the best search region given the on/off pattern
    and the levels read with log-normal noise of SD ``weber_frac`` (averaged over
    ``n_noise`` readings, each a separate trial)."""
    if weber_frac <= 0:
        raise ValueError("weber_frac must be > 0")
    cells = grid.index(prior_dirs)
    on_prior = prior_levels > 0
    log_prior = np.log(np.where(on_prior, prior_levels, 1.0))
    out = np.ones(len(trial_levels))
    for t, lev in enumerate(np.asarray(trial_levels, dtype=float)):
        on = lev > 0
        same = np.all(on_prior == on, axis=1)
        if not same.any():
            continue
        masses = []
        for _ in range(n_noise):
            obs = np.log(lev[on]) + weber_frac * rng.standard_normal(int(on.sum()))
            d = log_prior[same][:, on] - obs
            logw = -0.5 * np.sum(d * d, axis=1) / weber_frac**2
            w = np.exp(logw - logw.max())
            hist = np.bincount(cells[same], weights=w, minlength=grid.n_cells)
            masses.append(top_mass(hist, n_top))
        out[t] = float(np.mean(masses))
    return out


# --------------------------------------------------------------------------------------
# Mode V: an explicit observer (a lower bound on the ideal one)
# --------------------------------------------------------------------------------------
def _rotate_toward(u: np.ndarray, e: np.ndarray, ang: float) -> np.ndarray:
    return math.cos(ang) * u + math.sin(ang) * e


def v_trilateration_success(
    targets: np.ndarray,
    start: np.ndarray,
    threshold_deg: float,
    hold_s: float,
    timeout_s: float,
    weber_frac: float,
    rng: np.random.Generator,
    read_s: float = V_READ_S,
    speed_deg_s: float = V_MEAN_SPEED_DEG_S,
) -> float:
    """Fraction of targets found in ``timeout_s`` by: read the error angle at the current
    pose and at two poses tilted along orthogonal axes, intersect the three cones
    (``t . u_j = cos d_j``), move to the estimate, repeat; hold when the reading is below
    the threshold. The error is read as ``2 asin(sin(e/2) exp(weber N(0,1)))``: the
    overall intensity alpha = 185 sin(e/2) with the Weber noise."""
    thr = math.radians(threshold_deg)
    speed = math.radians(speed_deg_s)

    def read(u: np.ndarray, t: np.ndarray) -> float:
        e = math.acos(max(-1.0, min(1.0, float(u @ t))))
        s = math.sin(e / 2.0) * math.exp(weber_frac * rng.standard_normal())
        return 2.0 * math.asin(min(1.0, s))

    found = 0
    for t in np.asarray(targets, dtype=float):
        u = np.asarray(start, dtype=float) / np.linalg.norm(start)
        clock = 0.0
        while clock < timeout_s:
            d0 = read(u, t)
            clock += read_s
            if d0 < thr:
                clock += hold_s
                if clock <= timeout_s and math.acos(min(1.0, float(u @ t))) <= thr:
                    found += 1
                    break
                continue
            a = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 = a / np.linalg.norm(a)
            e2 = np.cross(u, e1)
            step = min(max(0.5 * d0, 3.0 * thr), math.radians(20.0))
            u1 = _rotate_toward(u, e1, step)
            u2 = _rotate_toward(u, e2, step)
            d1 = read(u1, t)
            d2 = read(u2, t)
            clock += 2 * read_s + (step + step * math.sqrt(2.0) + step) / speed
            try:
                est = np.linalg.solve(np.stack([u, u1, u2]), np.cos([d0, d1, d2]))
            except np.linalg.LinAlgError:
                continue
            n = float(np.linalg.norm(est))
            if not math.isfinite(n) or n < 1e-9:
                continue
            est /= n
            clock += math.acos(max(-1.0, min(1.0, float(u @ est)))) / speed
            u = est
    return found / max(1, len(targets))


# --------------------------------------------------------------------------------------
# The bounds of a protocol condition
# --------------------------------------------------------------------------------------
def _levels_of(protocol: Protocol, k: int, policy: str, wrenches) -> tuple[np.ndarray, np.ndarray]:
    lev, dirs = [], []
    for w in wrenches:
        m = cue_levels(protocol.hands[k], w, policy, protocol.y_axis, protocol.constraints)
        if m is None:
            continue
        lev.append(m)
        dirs.append(target_direction(w))
    return np.asarray(lev), np.asarray(dirs)


def ideal_observer_bounds(
    protocol_path: str,
    k: int,
    mode: str,
    policy: str,
    seed: int = 1,
    n_prior: int = 20000,
    n_trials: int = 500,
    weber_frac: float = 0.3,
    search_s: float | None = None,
    protocol: Protocol | None = None,
    prior: Sequence[tuple[float, ...]] | None = None,
    trials: Sequence[tuple[float, ...]] | None = None,
) -> Bounds:
    """Upper bounds on success in condition (k, mode, policy) of the protocol.

    ``search_s`` defaults to the protocol's timeout; ``prior``/``trials`` (wrench lists)
    default to seeded draws of the protocol's prior (``n_prior``, ``n_trials``)."""
    if mode not in ("C", "V"):
        raise ValueError(f"mode must be C or V, got {mode!r}")
    p = protocol if protocol is not None else load_protocol(protocol_path)
    T = p.timeout_s if search_s is None else search_s
    caps = search_caps(T, p.hold_s)
    cap = cap_area_sr(p.threshold_deg)
    area = min(4.0 * math.pi, caps * cap)
    grid = EqualAreaGrid(round(4.0 * math.pi / cap))
    n_top = area / (4.0 * math.pi / grid.n_cells)
    prior_w = list(prior) if prior is not None else draw_prior(p, n_prior, seed)
    trial_w = list(trials) if trials is not None else draw_prior(p, n_trials, seed + 7919)
    pl, pd = _levels_of(p, k, policy, prior_w)
    tl, td = _levels_of(p, k, policy, trial_w)
    rng = np.random.default_rng(derive_seed(seed, "ideal-observer", k, mode, policy))
    onoff = onoff_masses(pl, pd, tl, grid, n_top)
    inten = intensity_masses(pl, pd, tl, grid, n_top, weber_frac, rng)
    proto = draw_wrenches(p)
    wl, _ = _levels_of(p, k, policy, [w.wrench for w in proto])
    po = onoff_masses(pl, pd, wl, grid, n_top)
    pi = intensity_masses(pl, pd, wl, grid, n_top, weber_frac, rng, n_noise=20)
    per = tuple((w.id, float(a), float(b)) for w, a, b in zip(proto, po, pi, strict=True))
    v_achieved = None
    if mode == "V":
        start_u = np.array([0.0, 0.0, -1.0])  # gravity in the hand frame at the start pose
        q = p.start_quat
        if any(abs(a - b) > 0 for a, b in zip(q, (1.0, 0.0, 0.0, 0.0), strict=True)):
            from graspguide.core.rotations import qconj, rotate

            start_u = np.asarray(rotate(qconj(q), (0.0, 0.0, -1.0)))
        v_achieved = v_trilateration_success(
            td, start_u, p.threshold_deg, p.hold_s, T, weber_frac, rng
        )
    ib = float(np.mean(inten)) if len(inten) else 1.0
    return Bounds(
        k=k,
        mode=mode,
        policy=policy,
        seed=seed,
        n_prior=len(pl),
        n_trials=len(tl),
        n_cells=grid.n_cells,
        caps=caps,
        search_area_deg2=area * (180.0 / math.pi) ** 2,
        search_fraction=area / (4.0 * math.pi),
        weber_frac=weber_frac,
        onoff_bound=float(np.mean(onoff)) if len(onoff) else 1.0,
        intensity_bound=ib,
        bound=ib if mode == "C" else 1.0,
        v_achieved=v_achieved,
        protocol_wrenches=per,
    )


def format_table(rows: Sequence[Bounds]) -> str:
    lines = [
        "| k | modality | on/off bound | intensity bound | bound | V observer achieves |",
        "|---|---|---|---|---|---|",
    ]
    for b in rows:
        v = "" if b.v_achieved is None else f"{100 * b.v_achieved:.1f} %"
        lines.append(
            f"| {b.k} | {b.policy}+{b.mode} | {100 * b.onoff_bound:.1f} % | "
            f"{100 * b.intensity_bound:.1f} % | {100 * b.bound:.1f} % | {v} |"
        )
    return "\n".join(lines)


def format_per_wrench(rows: Sequence[Bounds]) -> str:
    """The mode-C posterior masses of each protocol wrench, one table per condition."""
    out = []
    for b in rows:
        if b.mode != "C":
            continue
        out += [
            f"k = {b.k}, {b.policy}+C, per wrench of the protocol:",
            "",
            "| wrench | on/off | intensity |",
            "|---|---|---|",
        ]
        out += [
            f"| {wid} | {100 * x:.1f} % | {100 * y:.1f} % |" for wid, x, y in b.protocol_wrenches
        ]
        out.append("")
    return "\n".join(out).rstrip("\n")


def observer_bounds_all(
    protocol_path: str,
    seed: int = 1,
    n_prior: int = 20000,
    n_trials: int = 500,
    weber_frac: float = 0.3,
) -> tuple[Protocol, list[Bounds]]:
    """The bounds of every condition of the protocol (k x modality, in the protocol's
    order), from one shared prior sample and one shared trial sample."""
    p = load_protocol(protocol_path)
    prior = draw_prior(p, n_prior, seed)
    trials = draw_prior(p, n_trials, seed + 7919)
    rows = []
    for k in p.contact_counts:
        for modality in p.modalities:
            policy, mode = modality_parts(modality)
            rows.append(
                ideal_observer_bounds(
                    protocol_path,
                    k,
                    mode,
                    policy,
                    seed,
                    weber_frac=weber_frac,
                    protocol=p,
                    prior=prior,
                    trials=trials,
                )
            )
    return p, rows


def report_text(
    protocol_path: str, rows: Sequence[Bounds], seed: int, weber_frac: float, per_wrench: bool
) -> str:
    """The Markdown report of :func:`observer_bounds_all`: settings, table, per wrench."""
    b0 = rows[0]
    lines = [
        "# Ideal-observer bounds (SIMULATED: model bounds, not human data)",
        "",
        f"SIMULATED ideal-observer bounds: {protocol_path}, seed {seed}, prior sample "
        f"{b0.n_prior}, trials {b0.n_trials}, {b0.n_cells} equal-area cells, search "
        f"{b0.caps} caps = {b0.search_area_deg2:.0f} deg^2 ({100 * b0.search_fraction:.1f} % "
        f"of the sphere), Weber {weber_frac:g}",
        "",
        format_table(rows),
        "",
        "Upper bounds on the success rate of any observer of the cue under the assumptions "
        "of docs/ideal-observer.md; the V column is what one explicit observer achieves "
        "(a lower bound on the ideal one).",
    ]
    if per_wrench:
        lines += ["", format_per_wrench(rows)]
    return "\n".join(lines) + "\n"


def run(
    protocol: str | None = None,
    seed: int = 1,
    n_prior: int = 20000,
    n_trials: int = 500,
    weber: float = 0.3,
    per_wrench: bool = False,
    out: str | None = None,
) -> int:
    """``graspguide observer``: print the bounds of every condition of the protocol
    (default protocols/paper.toml of the repository); with ``out``, also write them as a
    Markdown file. Exit status 0, or 2 for a protocol file that cannot be used and 1 for
    an output file that cannot be written (the message says which)."""
    from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, fail, report
    from graspguide.protocol.study_protocol import ProtocolFileError

    if protocol is None:
        root = find_repo_root()
        protocol = os.path.join(root or "", "protocols", "paper.toml")
    t0 = time.monotonic()
    try:
        _, rows = observer_bounds_all(protocol, seed, n_prior, n_trials, weber)
    except ProtocolFileError as e:
        return fail("observer", e, EXIT_USAGE)
    text = report_text(protocol, rows, seed, weber, per_wrench)
    if out is not None:
        try:
            with open(out, "w", encoding="utf-8") as f:
                f.write(text)
        except OSError as e:
            report("observer", f"cannot write {out}: {e.strerror}")
            return EXIT_FAILURE
    print(text.split("\n", 2)[2].rstrip("\n"))
    if out is not None:
        print(f"Wrote {out}")
    print(f"wall time {time.monotonic() - t0:.1f} s")
    return EXIT_OK
