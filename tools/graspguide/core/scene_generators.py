"""Seeded scene generators for tests and benchmarks of GraspGuide.

Hand frame (meters): x toward the thumb side, y from the wrist to the fingertips, z out
of the palm. A scene is a plain dict (JSON-friendly):

    {"name": str, "k": 3 | 4,
     "contacts": [[x, y, z], ...],          # k rows, hand frame
     "wrench": [fx, fy, fz, mx, my, mz],   # object frame; moment about the centroid
     "y_axis": [x, y, z],
     "orientation": [w, x, y, z]}          # hand -> world

Extreme cases add "expect_status" (None where not known a priori), "note", optionally
"expect" (a dict of further expected outputs, e.g. {"fallback_mask": 1}), "same_as"
(name of a case whose pwm/levels/error must be equal) and "runs" (the
(policy, mode, constraints) combinations worth running).

Every random draw comes from a ``numpy.random.Generator`` (``numpy.random.default_rng``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from graspguide.core.rotations import quat_from_axis_angle
from graspguide.core.vocabulary import FINGERS

NOMINAL_CONTACTS = {
    "thumb": (0.045, 0.045, 0.035),
    "index": (0.015, 0.095, 0.040),
    "middle": (-0.010, 0.100, 0.040),
    "palm": (0.0, 0.045, 0.0),
}
PERTURBATION_M = 0.015  # each coordinate perturbed uniformly in +-this
FORCE_RANGE_N = (0.5, 5.0)  # force magnitude, uniform
PURE_FORCE_SHARE = 0.7  # share of scenes with zero moment
MAX_MOMENT_NM = 0.1  # moment norm uniform in [0, this] otherwise
DEFAULT_Y_AXIS = (0.0, 1.0, 0.0)
IDENTITY_QUATERNION = (1.0, 0.0, 0.0, 0.0)

RUN_DEFAULT = [("F", "C", "paper")]
RUN_OK = [("F", "C", "paper"), ("Fperp", "V", "normal"), ("F", "V", "none")]


def nominal_contacts(k: int) -> np.ndarray:
    if k not in (3, 4):
        raise ValueError("k must be 3 or 4")
    return np.array([NOMINAL_CONTACTS[n] for n in FINGERS[:k]], dtype=np.float64)


def random_unit_vector(rng: np.random.Generator, dim: int = 3) -> np.ndarray:
    """Uniform direction on the sphere (normalised Gaussian)."""
    while True:
        v = rng.standard_normal(dim)
        n = float(np.linalg.norm(v))
        if n > 1e-12:
            return v / n


def random_quaternion(rng: np.random.Generator) -> np.ndarray:
    """Uniform random unit quaternion [w, x, y, z], with w >= 0."""
    q = random_unit_vector(rng, 4)
    return -q if q[0] < 0 else q


def _scene(
    name: str, contacts, wrench, y_axis=DEFAULT_Y_AXIS, orientation=IDENTITY_QUATERNION
) -> dict[str, Any]:
    contacts = [[float(c) for c in row] for row in contacts]
    return {
        "name": name,
        "k": len(contacts),
        "contacts": contacts,
        "wrench": [float(v) for v in wrench],
        "y_axis": [float(v) for v in y_axis],
        "orientation": [float(v) for v in orientation],
    }


def random_scene(rng: np.random.Generator, k: int, name: str = "random") -> dict[str, Any]:
    """A hand-like scene: nominal contacts perturbed by +-15 mm, random wrench and pose.

    Draw order (fixed, so seeds are stable): contact perturbations (k x 3), force
    direction, force magnitude, pure-force coin, moment direction, moment magnitude
    (both drawn even for a pure force), orientation.
    """
    contacts = nominal_contacts(k) + rng.uniform(-PERTURBATION_M, PERTURBATION_M, (k, 3))
    f_dir = random_unit_vector(rng)
    f_mag = rng.uniform(*FORCE_RANGE_N)
    pure = rng.random() < PURE_FORCE_SHARE
    m_dir = random_unit_vector(rng)
    m_mag = rng.uniform(0.0, MAX_MOMENT_NM)
    moment = np.zeros(3) if pure else m_dir * m_mag
    q = random_quaternion(rng)
    return _scene(name, contacts, np.concatenate([f_dir * f_mag, moment]), DEFAULT_Y_AXIS, q)


def random_scenes(seed: int, k: int, count: int, prefix: str | None = None) -> list[dict[str, Any]]:
    """`count` scenes, scene i drawn from default_rng([seed, k, i]) (independent streams)."""
    prefix = prefix or f"random_k{k}"
    return [
        random_scene(np.random.default_rng([seed, k, i]), k, f"{prefix}_{i:04d}")
        for i in range(count)
    ]


def _case(
    scene: dict[str, Any],
    expect_status: str | None,
    note: str,
    runs=None,
    expect: dict | None = None,
    same_as: str | None = None,
) -> dict[str, Any]:
    scene = dict(scene)
    scene["expect_status"] = expect_status
    scene["note"] = note
    scene["runs"] = [
        list(r)
        for r in (runs if runs is not None else (RUN_OK if expect_status == "ok" else RUN_DEFAULT))
    ]
    if expect:
        scene["expect"] = dict(expect)
    if same_as:
        scene["same_as"] = same_as
    return scene


def extreme_scenes() -> list[dict[str, Any]]:
    """Named edge cases; each notes its expected status where it is known a priori."""
    cases: list[dict[str, Any]] = []
    add = cases.append

    def case(
        name,
        contacts,
        wrench,
        status,
        note,
        *,
        orientation=IDENTITY_QUATERNION,
        y_axis=DEFAULT_Y_AXIS,
        **expected,
    ):
        """One named case: the scene, its expected status, why, and runs/expect/same_as."""
        add(_case(_scene(name, contacts, wrench, y_axis, orientation), status, note, **expected))

    nan, inf = float("nan"), float("inf")

    hand3 = nominal_contacts(3)
    hand4 = nominal_contacts(4)
    pure_f = [0.3, -1.2, -0.8, 0.0, 0.0, 0.0]
    q_tilt = quat_from_axis_angle([1.0, 2.0, -0.5], 0.7).tolist()

    # Dyadic geometry: every sum below is exact in binary floating point, so the
    # centroid and the offsets are exact and boundary cases sit exactly on the boundary.
    d = 0.0078125  # 2^-7 m
    P = np.array([0.0, 8 * d, 2 * d])
    d1 = np.array([6 * d, -2 * d, 2 * d])
    d2 = np.array([2 * d, 4 * d, 3 * d])
    tetra = [P + d1, P + d2, P - d1 - d2]  # centroid exactly P

    # ---- coincident contacts --------------------------------------------------------------------
    for hand, why in (
        (hand3, "two equal contacts (pairwise check)"),
        (hand4, "two equal contacts among four; the other three span a plane"),
    ):
        c = hand.copy()
        c[1] = c[0]
        case(f"coincident_thumb_equals_index_k{len(c)}", c, pure_f, "coincident_contacts", why)
    c = hand4.copy()
    c[2] = c[1] + np.array([1e-6, 0.0, 0.0])
    case(
        "coincident_index_middle_1um_k4",
        c,
        pure_f,
        "coincident_contacts",
        "index and middle 1 um apart (<= 1e-4 L)",
    )
    case(
        "coincident_all_equal_k3",
        [hand3[0]] * 3,
        pure_f,
        "coincident_contacts",
        "all contacts equal: L = 0",
    )
    case(
        "coincident_palm_at_centroid_k4",
        tetra + [P],
        pure_f,
        "coincident_contacts",
        "palm exactly at the centroid of all four (r_4 = 0)",
    )
    case(
        "coincident_contact_at_centroid_k3",
        [P + d1, P - d1, P],
        pure_f,
        "coincident_contacts",
        "third contact exactly at the midpoint = centroid (also collinear: "
        "coincident is checked first)",
    )

    # ---- rank -----------------------------------------------------------------------------------
    u = np.array([2 * d, d, 3 * d])
    case(
        "collinear_k3",
        [P, P + u, P + 3 * u],
        pure_f,
        "rank_deficient",
        "three collinear contacts: rank 5",
    )
    case(
        "collinear_k4",
        [P, P + u, P + 3 * u, P + 4 * u],
        pure_f,
        "rank_deficient",
        "four collinear contacts: rank 5",
    )
    c = np.array([P, P + u, P + 3 * u])
    c[1] += np.array([1e-9, -2e-9, 0.0])
    case(
        "nearly_collinear_k3",
        c,
        pure_f,
        "rank_deficient",
        "middle contact 2 nm off the line: sigma_6/sigma_1 ~ 1e-7",
    )

    # ---- contacts on / near the y_O axis (fallback axis) ----------------------------------------
    on_axis = [[0.0, 8 * d, 0.0], [4 * d, -4 * d, d], [-4 * d, -4 * d, -d]]  # O = 0
    case(
        "contact_on_y_axis_k3",
        on_axis,
        pure_f,
        "ok",
        "r_1 = (0, a, 0) exactly parallel to y_O: fallback axis for contact 0",
        orientation=q_tilt,
        expect={"fallback_mask": 1},
    )
    neg = [[0.0, -8 * d, 0.0], [4 * d, 4 * d, d], [-4 * d, 4 * d, -d]]
    case(
        "contact_on_neg_y_axis_k3",
        neg,
        pure_f,
        "ok",
        "r_1 anti-parallel to y_O: fallback axis",
        orientation=q_tilt,
        expect={"fallback_mask": 1},
    )
    on4 = [[0.0, 8 * d, 0.0], [4 * d, -2 * d, d], [-4 * d, -2 * d, -d], [0.0, -4 * d, 0.0]]
    case(
        "contacts_on_y_axis_k4",
        on4,
        [0.4, 0.2, -1.1, 0.0, 0.0, 0.0],
        "ok",
        "thumb and palm both on the y_O axis (opposite sides)",
        orientation=q_tilt,
        expect={"fallback_mask": 9},
    )
    for label, sin_t, mask in (("inside", 5e-4, 1), ("outside", 2e-3, 0)):
        # Centroid exactly 0, r_1 = (a sin_t, a, 0): ||y_1 x y_O|| = sin_t / sqrt(1 + sin_t^2).
        a = 8 * d
        h = a * sin_t / 2
        cc = [[2 * h, a, 0.0], [4 * d - h, -a / 2, d], [-4 * d - h, -a / 2, -d]]
        case(
            f"contact_near_y_axis_{label}_tol_k3",
            cc,
            pure_f,
            "ok",
            f"||y_1 x y_O|| ~ {sin_t:g} ({label} kAxisParallelTol = 1e-3)",
            orientation=q_tilt,
            expect={"fallback_mask": mask},
        )
    onz = [[0.0, 0.0, 8 * d], [4 * d, d, -4 * d], [-4 * d, -d, -4 * d]]
    diag = [[4 * d, 4 * d, 4 * d], [-4 * d, 2 * d, -2 * d], [0.0, -6 * d, -2 * d]]  # O = 0
    for name, contacts, y_axis, why in (
        (
            "z_contact_on_axis",
            onz,
            (0.0, 0.0, 1.0),
            "y_O = +z, contact 0 on it: fallback e = +x (tie with +y, first index)",
        ),
        (
            "diagonal",
            diag,
            (1.0, 1.0, 1.0),
            "y_O = (1,1,1) unnormalised, contact 0 on it: three-way tie, e = +x",
        ),
    ):
        case(
            f"custom_y_axis_{name}",
            contacts,
            pure_f,
            "ok",
            why,
            y_axis=y_axis,
            orientation=q_tilt,
            expect={"fallback_mask": 1},
        )
    case(
        "y_axis_default_reference_k3",
        hand3,
        pure_f,
        "ok",
        "reference for y_axis_scaled",
        orientation=q_tilt,
    )
    case(
        "y_axis_scaled",
        hand3,
        pure_f,
        "ok",
        "y_O = (0, 2.5, 0) is normalised",
        y_axis=(0.0, 2.5, 0.0),
        orientation=q_tilt,
        same_as="y_axis_default_reference_k3",
    )
    case("y_axis_zero", hand3, pure_f, "bad_axis", "y_O = 0", y_axis=(0.0, 0.0, 0.0))

    # ---- units and scale ------------------------------------------------------------------------
    for k in (3, 4):
        base = random_scene(np.random.default_rng([7, k]), k, f"scale_base_k{k}")
        base["wrench"][3:] = [0.02, -0.035, 0.01]
        add(_case(base, "ok", "reference for the scaled/offset variants (non-zero moment)"))
        C = np.array(base["contacts"])
        w = np.array(base["wrench"])
        variants = (
            ("tiny_hand_0p1mm", 2e-3, 0.0, "hand scaled by 2e-3: contacts ~0.1 mm apart"),
            ("huge_hand_10m", 200.0, 0.0, "hand scaled by 200: contacts ~10 m apart"),
            ("mm_units", 1000.0, 0.0, "hand in mm, moment in N mm"),
            ("offset_1e6", 1.0, 1e6, "all contacts offset by 1e6 m (x, y and z)"),
        )
        for label, s, off, note in variants:
            ws = w.copy()
            ws[3:] *= s
            add(
                _case(
                    _scene(f"{label}_k{k}", C * s + off, ws, base["y_axis"], base["orientation"]),
                    "ok",
                    note,
                    same_as=base["name"],
                )
            )

    # ---- wrench ---------------------------------------------------------------------------------
    case("zero_wrench", hand3, [0.0] * 6, "zero_wrench", "w = 0")
    case(
        "zero_force_with_moment", hand3, [0, 0, 0, 0.01, -0.02, 0.0], "zero_force", "f = 0, m != 0"
    )
    case(
        "tiny_force_with_moment",
        hand4,
        [1e-9, 0, 0, 0.02, 0.0, 0.01],
        "zero_force",
        "||f|| / ||w_L|| ~ 2e-9 < 1e-6",
    )

    # ---- relevance boundary ---------------------------------------------------------------------
    # r_1 = (4d, 0, 0) exactly (O = 0); f = (0, 0, 1) is exactly perpendicular to r_1.
    rb = [[4 * d, 0.0, 0.0], [-2 * d, 4 * d, d], [-2 * d, -4 * d, -d]]
    for name, fx, why, relevant in (
        ("exact", 0.0, "f . r_1 = 0 exactly: contact 0 is relevant (<= 0 counts)", True),
        ("inside_band", 1e-7, "cos(f, r_1) = 1e-7 <= kRelevanceCosTol: relevant", True),
        ("outside_band", 1e-4, "cos(f, r_1) = 1e-4 > kRelevanceCosTol: not relevant", False),
    ):
        wrench = [fx, 0.0, 1.0, 0.0, 0.0, 0.0]
        scene = _scene(f"relevance_boundary_{name}", rb, wrench, orientation=q_tilt)
        add(_case(scene, "ok", why, expect={"relevant0": relevant}))

    # ---- constraint models ----------------------------------------------------------------------
    for name, hand, wrench, used, why in (
        (
            "paper_infeasible_k3",
            hand3,
            [0, 0, -1.0, 0, 0, 0],
            "normal",
            "nominal 3-contact hand pushed along -z: paper infeasible, falls back to normal",
        ),
        (
            "paper_infeasible_k4",
            hand4,
            [0, 1.0, 0, 0, -0.05, 0],
            "normal",
            "4-contact hand, moment about y_O of the wrong sign for lambda_ix >= 0: "
            "paper infeasible, falls back to normal",
        ),
        (
            "paper_feasible_interior_k4",
            hand4,
            [0, 1.0, 0, 0, 0.05, 0],
            "paper",
            "the same with the opposite moment: paper strictly feasible (margin > 0)",
        ),
        (
            "paper_feasible_degenerate_k3",
            hand3,
            [0, -2.0, 0.5, 0, 0, 0],
            "paper",
            "pure force: every lambda_ix = 0 at the (degenerate) paper optimum",
        ),
        (
            "paper_feasible_degenerate_k4",
            hand4,
            [0, 0, -1.0, 0, 0, 0],
            "paper",
            "pure force, 4 contacts: paper feasible on a degenerate vertex",
        ),
    ):
        case(name, hand, wrench, "ok", why, expect={"constraints_used": used})

    # ---- non-finite inputs ----------------------------------------------------------------------
    def with_value(name, field, index, value, k=3):
        sc = _scene(name, hand3 if k == 3 else hand4, pure_f, orientation=q_tilt)
        if field == "contacts":
            sc["contacts"][index[0]][index[1]] = value
        else:
            sc[field][index] = value
        return sc

    for name, field, index, value in (
        ("nan_contact", "contacts", (1, 2), nan),
        ("inf_contact", "contacts", (0, 0), inf),
        ("neg_inf_contact", "contacts", (2, 1), -inf),
        ("nan_force", "wrench", 1, nan),
        ("inf_moment", "wrench", 4, inf),
        ("neg_inf_force", "wrench", 0, -inf),
        ("nan_y_axis", "y_axis", 1, nan),
        ("inf_y_axis", "y_axis", 0, inf),
        ("nan_orientation", "orientation", 0, nan),
        ("inf_orientation", "orientation", 3, inf),
    ):
        add(_case(with_value(name, field, index, value), "non_finite_input", f"{value} in {field}"))

    # ---- quaternions ----------------------------------------------------------------------------
    q_ref = _scene("quaternion_unit", hand4, [0.7, -0.4, -1.5, 0.0, 0.0, 0.0], orientation=q_tilt)
    add(_case(q_ref, "ok", "reference for the scaled quaternions"))
    for label, s in (("scaled_3p7", 3.7), ("scaled_2e-6", 2e-6 / 1.0), ("negated", -1.0)):
        case(
            f"quaternion_{label}",
            hand4,
            q_ref["wrench"],
            "ok",
            f"orientation scaled by {s:g}: same result as the unit quaternion",
            orientation=[s * v for v in q_tilt],
            same_as="quaternion_unit",
        )
    case(
        "quaternion_zero",
        hand4,
        pure_f,
        "bad_quaternion",
        "q = 0",
        orientation=(0.0, 0.0, 0.0, 0.0),
    )
    case(
        "quaternion_tiny",
        hand4,
        pure_f,
        "bad_quaternion",
        "||q|| = 1e-7 < kMinQuaternionNorm",
        orientation=(1e-7, 0.0, 0.0, 0.0),
    )

    # ---- guidance error / alpha -----------------------------------------------------------------
    for name, force, why, error_deg in (
        (
            "aligned_with_gravity",
            [0, 0, -2.0],
            "R f_hat = g: error 0, alpha 0 (mode V: every active motor at 70)",
            0.0,
        ),
        ("opposite_to_gravity", [0, 0, 2.0], "R f_hat = -g: error 180, alpha 185", 180.0),
        ("perpendicular_to_gravity", [1.5, 0, 0], "R f_hat = +x: error 90", 90.0),
    ):
        scene = _scene(name, hand3, [*force, 0, 0, 0])
        add(_case(scene, "ok", why, expect={"error_deg": error_deg}))
    case(
        "rotated_into_gravity",
        hand3,
        [1.0, 0, 0, 0, 0, 0],
        "ok",
        "hand rotated +90 deg about y takes +x to -z: error ~0",
        orientation=quat_from_axis_angle([0, 1, 0], math.pi / 2).tolist(),
    )

    # ---- contact count and check order ----------------------------------------------------------
    case("bad_contact_count_k2", hand3[:2], pure_f, "bad_contact_count", "two contacts")
    case("bad_contact_count_k1", hand3[:1], pure_f, "bad_contact_count", "one contact")
    sc = _scene("order_nan_before_count", hand3[:2], pure_f)
    sc["wrench"][2] = nan
    add(_case(sc, "non_finite_input", "NaN and k = 2: non_finite_input first"))
    case(
        "order_count_before_axis",
        hand3[:2],
        pure_f,
        "bad_contact_count",
        "k = 2 and y_O = 0: bad_contact_count first",
        y_axis=(0, 0, 0),
    )
    case(
        "order_axis_before_quaternion",
        hand3,
        pure_f,
        "bad_axis",
        "y_O = 0 and q = 0: bad_axis first",
        y_axis=(0, 0, 0),
        orientation=(0, 0, 0, 0),
    )
    case(
        "order_quaternion_before_coincident",
        [hand3[0]] * 3,
        pure_f,
        "bad_quaternion",
        "q = 0 and coincident contacts: bad_quaternion first",
        orientation=(0, 0, 0, 0),
    )
    case(
        "order_coincident_before_zero_wrench",
        [hand3[0]] * 3,
        [0.0] * 6,
        "coincident_contacts",
        "coincident and w = 0: coincident first",
    )
    case(
        "order_zero_wrench_before_rank",
        [P, P + u, P + 3 * u],
        [0.0] * 6,
        "zero_wrench",
        "collinear and w = 0: zero_wrench first",
    )
    case(
        "order_zero_force_before_rank",
        [P, P + u, P + 3 * u],
        [0, 0, 0, 0.01, 0, 0],
        "zero_force",
        "collinear and f = 0: zero_force first",
    )
    return cases


__all__ = [
    "FINGERS",
    "NOMINAL_CONTACTS",
    "nominal_contacts",
    "random_unit_vector",
    "random_quaternion",
    "random_scene",
    "random_scenes",
    "extreme_scenes",
]
