"""The statuses of graspguide_cue/status.h: the same order (the code is the index, as
the protocol's ErrorCode carries it), the same snake_case names and the same messages.
tools/tests/test_micropython_solve.py checks this table against the C++ list."""

# (name, message), in the enum's order: code = index.
STATUSES = (
    ("ok", "ok"),
    ("non_finite_input", "an input is NaN or infinite; check the tracker data and the wrench"),
    (
        "bad_contact_count",
        "the scene needs 3 contacts (thumb, index, middle) or 4 (plus palm)",
    ),
    (
        "bad_axis",
        "y_axis (default [0, 1, 0]) and a gravity direction must be finite, non-zero vectors",
    ),
    ("bad_quaternion", "orientation must be a finite, non-zero quaternion [w, x, y, z]"),
    (
        "coincident_contacts",
        "two contacts (or a contact and the centroid) coincide; check the tracked positions",
    ),
    (
        "imprecise_contacts",
        "the contacts are so far from the origin that this precision cannot resolve the hand;"
        " send positions relative to a point near the hand (e.g. the palm)",
    ),
    ("zero_wrench", "the wrench is zero; give the virtual object a non-zero force"),
    (
        "zero_force",
        "the wrench has no force part, or one below 1e-6 of its moment, so there is no"
        " direction to align with gravity",
    ),
    (
        "rank_deficient",
        "the contacts are (nearly) collinear, so the grasp cannot resist every wrench; spread"
        " the contacts out",
    ),
    ("qp_infeasible", "no contact forces satisfy the constraint model for this wrench"),
    (
        "qp_iteration_limit",
        "the QP solver hit its iteration cap; raise max_iterations or report the scene",
    ),
    ("nothing_to_display", "every motor level is zero for this policy; try policy F"),
    ("time_went_backwards", "timestamps must not decrease within a trial"),
    (
        "bad_config",
        "a trial parameter is out of range: 0 <= threshold_deg <= 180, 0 <= hold_s <= 600 and"
        " hold_s <= timeout_s, 0 < timeout_s <= 1800 (max_iterations >= 1)",
    ),
    (
        "imu_stale",
        "no IMU sample for GRASPGUIDE_IMU_STALE_MS (or none yet); check the IMU's wiring, power"
        " and I2C address",
    ),
    (
        "imu_stuck",
        "the IMU repeated the same reading GRASPGUIDE_IMU_STUCK_SAMPLES times in a row; a live"
        " sensor's noise never does: power-cycle it and check the bus",
    ),
    (
        "imu_out_of_range",
        "an IMU reading is NaN, infinite or beyond the part's configured full scale; check the"
        " range the board sets against the limits it reports",
    ),
    (
        "bad_imu_config",
        "an IMU health setting is out of range: 1 <= stale_ms <= 60000, stuck_samples >= 2,"
        " recovery_samples >= 1, full scales finite and > 0",
    ),
)

OK = 0
NON_FINITE_INPUT = 1
BAD_CONTACT_COUNT = 2
BAD_AXIS = 3
BAD_QUATERNION = 4
COINCIDENT_CONTACTS = 5
IMPRECISE_CONTACTS = 6
ZERO_WRENCH = 7
ZERO_FORCE = 8
RANK_DEFICIENT = 9
QP_INFEASIBLE = 10
QP_ITERATION_LIMIT = 11
NOTHING_TO_DISPLAY = 12
TIME_WENT_BACKWARDS = 13
BAD_CONFIG = 14
IMU_STALE = 15
IMU_STUCK = 16
IMU_OUT_OF_RANGE = 17
BAD_IMU_CONFIG = 18

COUNT = len(STATUSES)


def name(code):
    return STATUSES[code][0] if 0 <= code < COUNT else "unknown"


def message(code):
    return STATUSES[code][1] if 0 <= code < COUNT else "unknown status"


def code_of(status_name):
    """The code of a status name, or -1."""
    for i in range(COUNT):
        if STATUSES[i][0] == status_name:
            return i
    return -1
