"""Ideal-observer bounds on scenes whose answer is known by hand (SIMULATED)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from graspguide.participant import ideal_observer as io
from graspguide.protocol.study_protocol import draw_wrenches, load_protocol

PAPER = Path(__file__).resolve().parents[3] / "protocols" / "paper.toml"


@pytest.fixture(scope="module")
def paper():
    return load_protocol(str(PAPER))


def test_search_caps_counts_one_instant_per_hold_window():
    assert io.search_caps(90.0, 0.5) == 181
    assert io.search_caps(0.4, 0.5) == 1
    with pytest.raises(ValueError):
        io.search_caps(90.0, 0.0)


def test_equal_area_grid_cells_are_equally_likely_under_a_uniform_direction():
    grid = io.EqualAreaGrid(200)
    rng = np.random.default_rng(3)
    u = rng.standard_normal((200_000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    counts = np.bincount(grid.index(u), minlength=grid.n_cells)
    expected = len(u) / grid.n_cells
    assert abs(counts.min() - expected) < 6 * math.sqrt(expected)
    assert abs(counts.max() - expected) < 6 * math.sqrt(expected)


def test_two_wrenches_with_the_same_cue_everywhere_give_at_most_one_half_in_one_shot():
    # two targets on opposite sides of the sphere, the same levels: one cap finds one
    grid = io.EqualAreaGrid(1000)
    dirs = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]] * 50)
    levels = np.tile([0.6, 0.8, 0.0], (100, 1))
    trial = np.array([[0.6, 0.8, 0.0]])
    assert io.onoff_masses(levels, dirs, trial, grid, 1.0)[0] == pytest.approx(0.5)
    rng = np.random.default_rng(0)
    m = io.intensity_masses(levels, dirs, trial, grid, 1.0, 0.3, rng, n_noise=5)[0]
    assert m == pytest.approx(0.5)
    # two caps' worth of search find both
    assert io.onoff_masses(levels, dirs, trial, grid, 2.0)[0] == pytest.approx(1.0)


def test_a_cue_that_tells_nothing_leaves_the_share_of_the_sphere_searched():
    grid = io.EqualAreaGrid(400)
    rng = np.random.default_rng(5)
    dirs = rng.standard_normal((400_000, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    levels = np.ones((len(dirs), 3))
    n_top = 40.0  # a tenth of the sphere
    m = io.onoff_masses(levels, dirs, levels[:1], grid, n_top)[0]
    # finite samples can only raise the best region's mass (the safe side)
    assert 0.1 <= m < 0.1 + 0.01


def test_the_pattern_separates_targets_when_the_motors_differ():
    grid = io.EqualAreaGrid(1000)
    dirs = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]] * 50)
    levels = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] * 50)
    out = io.onoff_masses(levels, dirs, levels[:2], grid, 1.0)
    assert list(out) == [pytest.approx(1.0), pytest.approx(1.0)]


def test_a_single_wrench_prior_is_found_with_certainty_by_the_real_core(paper):
    w = draw_wrenches(paper)[0].wrench
    for mode in ("C", "V"):
        b = io.ideal_observer_bounds(
            "", 4, mode, "Fperp", seed=2, protocol=paper, prior=[w] * 20, trials=[w] * 3
        )
        assert b.onoff_bound == pytest.approx(1.0)
        assert b.intensity_bound == pytest.approx(1.0)
        assert b.bound == pytest.approx(1.0)


def test_the_v_observer_finds_targets_without_noise():
    rng = np.random.default_rng(1)
    t = rng.standard_normal((30, 3))
    t /= np.linalg.norm(t, axis=1)[:, None]
    ok = io.v_trilateration_success(t, np.array([0.0, 0.0, -1.0]), 3.0, 0.5, 90.0, 1e-6, rng)
    assert ok == pytest.approx(1.0)
    # no time for a single hold: nothing is found
    assert (
        io.v_trilateration_success(t, np.array([0.0, 0.0, -1.0]), 3.0, 0.5, 0.3, 1e-6, rng) == 0.0
    )


def test_bounds_lie_in_unit_interval_and_repeat_for_a_seed(paper):
    kw = dict(protocol=paper, n_prior=400, n_trials=30)
    a = io.ideal_observer_bounds("", 3, "V", "F", seed=11, **kw)
    b = io.ideal_observer_bounds("", 3, "V", "F", seed=11, **kw)
    assert a == b
    for x in (a.onoff_bound, a.intensity_bound, a.bound, a.v_achieved):
        assert x is not None and 0.0 <= x <= 1.0
    assert a.caps == 181
    assert 0.0 < a.search_fraction < 1.0
    assert a.simulated is True


# A hand whose contacts all lie in the plane z = 0, with y_axis in that plane: the mirror
# z -> -z maps the hand onto itself, so a force and its mirror image give the same contact
# forces up to the mirror, the same norms |lambda_i| (policy F) and so the same cue. An
# observer cannot tell them apart: from a prior made of such pairs, one cap of search
# finds one of the two (half the mass), two caps find both.
PLANAR_K3 = ((0.045, 0.045, 0.0), (0.015, 0.095, 0.0), (-0.010, 0.100, 0.0))
PAIR_DIRS = [(1, 2, 1), (2, -1, 1), (-1, 1, 2), (1, 1, 1), (-2, -1, 1), (1, -2, 2)]


def _mirror_pairs() -> list[tuple[float, ...]]:
    out: list[tuple[float, ...]] = []
    for d in PAIR_DIRS:
        n = math.sqrt(sum(x * x for x in d))
        fx, fy, fz = (x / n for x in d)
        out += [(fx, fy, fz, 0.0, 0.0, 0.0), (fx, fy, -fz, 0.0, 0.0, 0.0)]
    return out


def test_the_ideal_observer_bounds_on_a_scene_whose_answer_is_known_by_hand(paper):
    pairs = _mirror_pairs()
    planar = dataclasses.replace(
        paper, hands={3: PLANAR_K3, 4: paper.hands[4]}, moments="zero", moment_max_Nm=0.0
    )
    # the premises, on the real core: the mirror gives the same levels, every motor is on
    for w, m in zip(pairs[::2], pairs[1::2], strict=True):
        a = io.cue_levels(PLANAR_K3, w, "F", planar.y_axis, planar.constraints)
        b = io.cue_levels(PLANAR_K3, m, "F", planar.y_axis, planar.constraints)
        assert a is not None and b is not None
        assert np.all(a > 0)
        assert np.array_equal(a, b)
    # by hand: 3 deg caps of area 2 pi (1 - cos 3 deg); the grid has 27 bands x 54 sectors
    # = 1458 cells; one cap of search is this many cells
    per_cap = 2 * math.pi * (1 - math.cos(math.radians(3.0))) / (4 * math.pi / 1458)
    kw = dict(prior=pairs * 10, trials=pairs, weber_frac=1e-3)
    for caps, search_s in ((1, 0.0), (2, 0.5)):
        b = io.ideal_observer_bounds("", 3, "C", "F", protocol=planar, search_s=search_s, **kw)
        assert (b.caps, b.n_cells) == (caps, 1458)
        # all motors on for all 12 targets: which are on says nothing, 1 in 12 per cap
        assert b.onoff_bound == pytest.approx(caps * per_cap / 12, rel=1e-9)
        # the levels tell the pair, never which of the two: 1 in 2 per cap
        assert b.intensity_bound == pytest.approx(min(1.0, caps * per_cap / 2), rel=1e-9)
    # the paper's hand is not planar (z = 35-40 mm): the same targets are told apart
    b = io.ideal_observer_bounds("", 3, "C", "F", protocol=paper, search_s=0.0, **kw)
    assert b.intensity_bound == pytest.approx(per_cap, rel=1e-9)
