"""The virtual participant's reading of a vibration pattern: a posterior over weight
directions (hand frame) given what it perceived. SIMULATED: a model, never human data.

The participant knows the map from a weight direction to the pattern in full: Algorithm 1
through the real core (:func:`graspguide.participant.ideal_observer.cue_levels`), with
its own contacts, ``y_O`` and policy, for a weight with no moment (it is told it feels an
object's weight; a moment is not part of its picture of the task), over a near-uniform
grid of directions. Its prior over the directions is uniform on the sphere (nothing in
its instructions favours one). docs/participant.md states both assumptions.

Reproducibility (the module comment of :mod:`graspguide.participant.model` says why): the
grid is built with ``math`` on plain floats; the posterior is computed with elementwise
numpy operations (+, -, *, /, comparisons: IEEE-exact per element) and ``math.exp`` /
``math.log``, never with numpy's reductions over the grid, linear algebra or SIMD
transcendental functions, so a posterior has the same bits on every CPU (up to libm's
last bit).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from graspguide.participant.ideal_observer import cue_levels

#: Directions of the reading grid (a Fibonacci sphere: near-equal areas, one point per
#: 6.9 deg^2; its covering radius is 1.98 deg, checked in the tests). Each point stands for
#: an equal share of the sphere, so a posterior over the points is a posterior over areas.
GRID_N = 6000


@functools.lru_cache(maxsize=2)
def direction_grid(n: int = GRID_N) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` unit directions on a Fibonacci sphere, sorted by z (x, y, z arrays, read-only)."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    xs, ys, zs = [], [], []
    for i in range(n):
        z = 1.0 - (2.0 * i + 1.0) / n
        r = math.sqrt(max(0.0, 1.0 - z * z))
        phi = i * golden
        xs.append(r * math.cos(phi))
        ys.append(r * math.sin(phi))
        zs.append(z)
    out = (np.array(xs), np.array(ys), np.array(zs))
    for v in out:
        v.flags.writeable = False
    return out


@functools.lru_cache(maxsize=4)
def cap_neighbours(radius_deg: float, n: int = GRID_N) -> tuple[np.ndarray, ...]:
    """For every grid point, the indices of the grid points within ``radius_deg`` of it
    (itself included): the points a hold at that point covers. The grid is sorted by z,
    so only a band of indices needs checking (elementwise products only)."""
    gx, gy, gz = direction_grid(n)
    c = math.cos(math.radians(radius_deg))
    # |z_i - z_j| <= chord <= 2 sin(r/2); z steps by 2/n.
    band = int(math.ceil(2.0 * math.sin(math.radians(radius_deg) / 2.0) * n / 2.0)) + 2
    out = []
    for i in range(n):
        lo, hi = max(0, i - band), min(n, i + band + 1)
        dots = gx[lo:hi] * gx[i] + gy[lo:hi] * gy[i] + gz[lo:hi] * gz[i]
        idx = np.nonzero(dots >= c)[0] + lo
        idx.flags.writeable = False
        out.append(idx)
    return tuple(out)


@functools.lru_cache(maxsize=4)
def cap_matrix(radius_deg: float, n: int = GRID_N):
    """:func:`cap_neighbours` as a sparse 0/1 matrix (row i: the points within
    ``radius_deg`` of point i, in ascending order), so the mass every cap holds is one
    product. Its rows sum in the order a loop over the neighbours would, so the result is
    the loop's to the last bit."""
    from scipy.sparse import csr_matrix

    nbrs = cap_neighbours(radius_deg, n)
    indptr = np.zeros(n + 1, dtype=np.int64)
    indptr[1:] = np.cumsum([len(x) for x in nbrs])
    indices = np.concatenate(nbrs)
    return csr_matrix((np.ones(len(indices)), indices, indptr), shape=(n, n))


@dataclass(frozen=True)
class PatternMap:
    """The pattern Algorithm 1 gives for each grid direction (zero moment): per point and
    motor, whether it is on, its level |m_i| and ln |m_i| (0 where off); the weakest
    motor on and how many are on. Read-only arrays, shared by every participant."""

    on: np.ndarray  # (G, k) bool
    ln_level: np.ndarray  # (G, k) float
    weakest: np.ndarray  # (G,) int
    n_on: np.ndarray  # (G,) int
    valid: np.ndarray  # (G,) bool: the core solved for this direction


def _build_map(
    levels: Sequence[np.ndarray | None], k: int, xs: Sequence[int] | None = None
) -> PatternMap:
    g = len(levels)
    on = np.zeros((g, k), dtype=bool)
    ln = np.zeros((g, k))
    weakest = np.zeros(g, dtype=int)
    n_on = np.zeros(g, dtype=int)
    valid = np.zeros(g, dtype=bool)
    for i, lev in enumerate(levels):
        if lev is None or not np.any(lev > 0):
            continue
        valid[i] = True
        vals = [float(v) for v in lev]
        best = None
        for j, v in enumerate(vals):
            if v > 0:
                on[i, j] = True
                ln[i, j] = math.log(v)
                if best is None or v < vals[best]:
                    best = j
        weakest[i] = best if best is not None else 0
        n_on[i] = int(on[i].sum())
    for a in (on, ln, weakest, n_on, valid):
        a.flags.writeable = False
    return PatternMap(on, ln, weakest, n_on, valid)


@functools.lru_cache(maxsize=16)
def pattern_map(
    contacts: tuple[tuple[float, ...], ...], y_axis: tuple[float, ...], policy: str
) -> PatternMap:
    """The map of every grid direction to its pattern, for these contacts (hand frame),
    ``y_O`` and policy, with the paper's constraints. Cached: one per hand and policy for
    a whole study (about 0.1 s each)."""
    gx, gy, gz = direction_grid()
    levels = [
        cue_levels(contacts, (float(x), float(y), float(z), 0.0, 0.0, 0.0), policy, y_axis)
        for x, y, z in zip(gx.tolist(), gy.tolist(), gz.tolist(), strict=True)
    ]
    return _build_map(levels, len(contacts))


@dataclass(frozen=True)
class Percept:
    """What the participant perceived of the pattern: which motors it felt (after
    counting errors) and, for those, the estimated level ln |m_i| with its SD."""

    on: tuple[bool, ...]
    ln_level: tuple[float, ...]  # 0 where not felt
    sd: tuple[float, ...]  # SD of ln_level per felt motor (inf where not felt)


def pattern_likelihood(pm: PatternMap, percept: Percept, miss_prob: Sequence[float]) -> np.ndarray:
    """The likelihood of the percept at every entry of the map (elementwise numpy and
    ``math.exp`` only). ``miss_prob[n]``: the probability that the weakest of ``n``
    simultaneous vibrations is not felt (the participant's model of its own counting
    errors). The levels enter as ratios (ln levels with their common offset removed,
    weighted by 1/SD^2): the participant reads relative intensities, not absolute ones.
    """
    k = len(percept.on)
    s = np.array(percept.on, dtype=bool)
    # On/off: the felt set equals the map's, or the map's without its weakest motor.
    full = np.ones(len(pm.n_on), dtype=bool)
    for j in range(k):
        full &= pm.on[:, j] == s[j]
    minus = np.ones(len(pm.n_on), dtype=bool)
    for j in range(k):
        expect = pm.on[:, j] & (pm.weakest != j)
        minus &= expect == s[j]
    minus &= pm.n_on >= 3
    p_miss = np.zeros(len(pm.n_on))
    for n in range(3, k + 1):
        p_miss = np.where(pm.n_on == n, float(miss_prob[n]), p_miss)
    prior_on = np.where(full, 1.0 - p_miss, 0.0) + np.where(minus & ~full, p_miss, 0.0)
    prior_on = np.where(pm.valid, prior_on, 0.0)
    # Levels: weighted residuals about their weighted mean, over the felt motors.
    felt = [j for j in range(k) if percept.on[j]]
    quad = np.zeros(len(pm.n_on))
    if len(felt) >= 2:
        w = [1.0 / (percept.sd[j] * percept.sd[j]) for j in felt]
        wsum = 0.0
        for x in w:
            wsum += x
        r = [percept.ln_level[j] - pm.ln_level[:, j] for j in felt]
        mean = np.zeros(len(pm.n_on))
        for wi, ri in zip(w, r):
            mean = mean + (wi / wsum) * ri
        for wi, ri in zip(w, r):
            d = ri - mean
            quad = quad + wi * (d * d)
    like = np.zeros(len(pm.n_on))
    idx = np.nonzero(prior_on > 0)[0].tolist()
    if idx:
        qs = quad[idx].tolist()
        q0 = min(qs)
        vals = [math.exp(-0.5 * (q - q0)) for q in qs]
        like[idx] = np.array(vals) * prior_on[idx]
    return like


def posterior_full(pm: PatternMap, percept: Percept, miss_prob: Sequence[float]) -> np.ndarray:
    """Posterior weights over the grid (uniform prior; the maximum scaled to 1). If the
    percept fits no direction of the map (it cannot happen with the counting-error model,
    but a broken percept must not stop the participant), the prior: every valid
    direction alike."""
    like = pattern_likelihood(pm, percept, miss_prob)
    top = max(like.tolist()) if len(like) else 0.0
    if not top > 0:
        return np.where(pm.valid, 1.0, 0.0)
    return like / top


@functools.lru_cache(maxsize=64)
def _examples(
    contacts: tuple[tuple[float, ...], ...],
    y_axis: tuple[float, ...],
    policy: str,
    n: int,
    seed: int,
) -> tuple[PatternMap, tuple[tuple[float, float, float], ...]]:
    rng = np.random.default_rng([seed & (2**64 - 1), 0x6C6561726E])  # "learn"
    dirs: list[tuple[float, float, float]] = []
    levels: list[np.ndarray] = []
    while len(dirs) < n:
        v = rng.standard_normal(3).tolist()
        m = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if m < 1e-9:
            continue
        d = (v[0] / m, v[1] / m, v[2] / m)
        lev = cue_levels(contacts, (*d, 0.0, 0.0, 0.0), policy, y_axis)
        if lev is None or not np.any(lev > 0):
            continue
        dirs.append(d)
        levels.append(lev)
    return _build_map(levels, len(contacts)), tuple(dirs)


def posterior_learned(
    contacts: tuple[tuple[float, ...], ...],
    y_axis: tuple[float, ...],
    policy: str,
    percept: Percept,
    miss_prob: Sequence[float],
    n_examples: int,
    kernel_deg: float,
    seed: int,
) -> np.ndarray:
    """Posterior weights over the grid from only ``n_examples`` familiarisation trials
    (the participant's own, drawn from its seed: a weight direction felt with its pattern,
    the direction learned when the trial ended): a kernel estimate. Each example weighs
    in with the likelihood of the percept under its pattern and spreads its direction
    with a kernel exp(kappa (cos theta - 1)), kappa = 1 / kernel^2; a uniform floor of
    1e-3 of the largest weight keeps every direction possible."""
    ex_map, dirs = _examples(contacts, y_axis, policy, n_examples, seed)
    like = pattern_likelihood(ex_map, percept, miss_prob).tolist()
    gx, gy, gz = direction_grid()
    kappa = 1.0 / math.radians(kernel_deg) ** 2
    w = np.zeros(len(gx))
    for le, d in zip(like, dirs):
        if le <= 0:
            continue
        cosines = (gx * d[0] + gy * d[1] + gz * d[2]).tolist()
        w = w + le * np.array([math.exp(kappa * (c - 1.0)) for c in cosines])
    top = max(w.tolist())
    if not top > 0:
        return np.ones(len(gx))
    w = w / top
    return np.where(w > 1e-3, w, 1e-3)


__all__ = [
    "GRID_N",
    "PatternMap",
    "Percept",
    "cap_matrix",
    "cap_neighbours",
    "direction_grid",
    "pattern_likelihood",
    "pattern_map",
    "posterior_full",
    "posterior_learned",
]
