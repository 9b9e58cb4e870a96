"""`graspguide solve` request lines with one fault each, and the good request they
start from: the CLI tests check the core's answer to each, the device tests that the
simulated device answers them alike."""

from __future__ import annotations

import json
import math

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
HAND4 = HAND3 + [[0.0, 0.045, 0.0]]
GOOD = {"contacts": HAND3, "wrench": [0.3, -1.2, -0.8, 0, 0, 0]}
GOOD_LINE = json.dumps(GOOD)


def request_with(**changes):
    r = dict(GOOD)
    r.update(changes)
    return json.dumps({k: v for k, v in r.items() if v is not DROP}, allow_nan=True)


DROP = object()

BAD_CASES = [
    # (id, line, code, words the message must contain)
    ("not_json", b"hello", "bad_json", ["JSON"]),
    ("truncated", b'{"contacts": [[1, 2, 3]', "bad_json", ["JSON"]),
    ("single_quotes", b"{'contacts': 1}", "bad_json", ["double quotes"]),
    ("two_objects", (GOOD_LINE + " " + GOOD_LINE).encode(), "bad_json", ["one JSON object"]),
    ("array", b"[1, 2, 3]", "bad_json", ["object"]),
    ("string", b'"contacts"', "bad_json", ["object"]),
    ("number", b"42", "bad_json", ["object"]),
    ("null", b"null", "bad_json", ["object"]),
    ("non_utf8", b'{"contacts": "\xff\xfe"}', "bad_json", ["UTF-8"]),
    ("latin1", '{"policy": "Fé"}'.encode("latin-1"), "bad_json", ["UTF-8"]),
    ("deep_nesting", b"[" * 200000 + b"]" * 200000, "bad_json", ["nested"]),
    ("deep_in_field", b'{"contacts": ' + b"[" * 5000 + b"]" * 5000 + b"}", "bad_json", ["nested"]),
    ("long_line", b'{"contacts": "' + b"x" * (3 << 20) + b'"}', "bad_json", ["long"]),
    (
        "missing_contacts",
        json.dumps({"wrench": GOOD["wrench"]}).encode(),
        "bad_request",
        ["contacts"],
    ),
    ("missing_both", b"{}", "bad_request", ["contacts", "wrench"]),
    (
        "typo_field",
        request_with(contsraints="normal").encode(),
        "bad_request",
        ["contsraints", "constraints"],
    ),
    ("unknown_field", request_with(id=7).encode(), "bad_request", ['"id"']),
    (
        "duplicate_field",
        b'{"contacts": 1, "contacts": 2, "wrench": 3}',
        "bad_request",
        ["more than once"],
    ),
    (
        "bool_in_wrench",
        request_with(wrench=[True, 0, 0, 0, 0, 0]).encode(),
        "bad_request",
        ["wrench[0]", "boolean"],
    ),
    (
        "string_in_wrench",
        request_with(wrench=["1", 0, 0, 0, 0, 0]).encode(),
        "bad_request",
        ["wrench[0]", "string"],
    ),
    (
        "null_in_contacts",
        request_with(contacts=[[1, 2, None]] + HAND3[1:]).encode(),
        "bad_request",
        ["contacts[0][2]"],
    ),
    (
        "bool_in_orientation",
        request_with(orientation=[1, 0, 0, False]).encode(),
        "bad_request",
        ["orientation[3]"],
    ),
    ("wrench_length", request_with(wrench=[1, 2, 3]).encode(), "bad_request", ["wrench", "6"]),
    ("wrench_not_array", request_with(wrench=5).encode(), "bad_request", ["wrench"]),
    ("contacts_not_array", request_with(contacts="thumb").encode(), "bad_request", ["contacts"]),
    (
        "contact_pair",
        request_with(contacts=[[1, 2], [3, 4], [5, 6]]).encode(),
        "bad_request",
        ["contacts[0]", "3"],
    ),
    (
        "contact_not_triple",
        request_with(contacts=[1, 2, 3]).encode(),
        "bad_request",
        ["contacts[0]", "triple"],
    ),
    (
        "orientation_length",
        request_with(orientation=[1, 0, 0]).encode(),
        "bad_request",
        ["orientation", "4"],
    ),
    ("y_axis_length", request_with(y_axis=[0, 1]).encode(), "bad_request", ["y_axis", "3"]),
    ("policy", request_with(policy="G").encode(), "bad_request", ['"F"', '"Fperp"']),
    ("policy_case", request_with(policy="fperp").encode(), "bad_request", ["Fperp"]),
    ("policy_type", request_with(policy=1).encode(), "bad_request", ["policy", '"F"']),
    ("mode", request_with(mode="X").encode(), "bad_request", ['"C"', '"V"']),
    (
        "constraints",
        request_with(constraints="soft").encode(),
        "bad_request",
        ['"paper"', '"normal"', '"none"'],
    ),
    ("constraints_null", request_with(constraints=None).encode(), "bad_request", ["constraints"]),
    ("two_contacts", request_with(contacts=HAND3[:2]).encode(), "bad_contact_count", ["3"]),
    (
        "five_contacts",
        request_with(contacts=HAND4 + [[0, 0, 0.1]]).encode(),
        "bad_contact_count",
        ["4"],
    ),
    ("no_contacts", request_with(contacts=[]).encode(), "bad_contact_count", ["3"]),
    ("nan_token", request_with(wrench=[math.nan, 0, 0, 0, 0, 0]).encode(), "non_finite_input", []),
    (
        "infinity_token",
        request_with(contacts=[[math.inf, 0, 0]] + HAND3[1:]).encode(),
        "non_finite_input",
        [],
    ),
    (
        "neg_infinity_token",
        request_with(orientation=[1, 0, -math.inf, 0]).encode(),
        "non_finite_input",
        [],
    ),
    ("huge_number", request_with().replace("0.3", "1e400").encode(), "non_finite_input", []),
    ("huge_integer", request_with().replace("0.3", "9" * 5000).encode(), "non_finite_input", []),
    ("zero_wrench", request_with(wrench=[0] * 6).encode(), "zero_wrench", []),
    ("zero_force", request_with(wrench=[0, 0, 0, 0.01, 0, 0]).encode(), "zero_force", []),
    ("coincident", request_with(contacts=[HAND3[0]] * 3).encode(), "coincident_contacts", []),
    (
        "collinear",
        request_with(contacts=[[0, 0, 0], [0.01, 0.02, 0], [0.03, 0.06, 0]]).encode(),
        "rank_deficient",
        [],
    ),
    ("bad_axis", request_with(y_axis=[0, 0, 0]).encode(), "bad_axis", []),
    ("bad_quaternion", request_with(orientation=[0, 0, 0, 0]).encode(), "bad_quaternion", []),
    (
        "units_value",
        request_with(units="cm").encode(),
        "bad_request",
        ['"units"', '"m"', '"mm"', '"any"', '"cm"'],
    ),
    ("units_type", request_with(units=1).encode(), "bad_request", ['"units"', '"mm"']),
    (
        "contacts_in_mm",
        request_with(contacts=[[x * 1000 for x in c] for c in HAND3]).encode(),
        "bad_request",
        ["contacts span 77.9", "looks like millimetres", "give metres", '"units": "mm"'],
    ),
    (
        "contacts_in_cm",
        request_with(contacts=[[x * 100 for x in c] for c in HAND3]).encode(),
        "bad_request",
        ["looks like centimetres", "divide by 100"],
    ),
    (
        "contacts_m_said_mm",
        request_with(units="mm").encode(),
        "bad_request",
        ["contacts span 0.0779", "looks like metres", 'drop "units": "mm"'],
    ),
    (
        "hand_of_1_mm",
        request_with(contacts=[[x / 78 for x in c] for c in HAND3]).encode(),
        "bad_request",
        ["contacts span 0.000999", "5 mm to 0.5 m", "check the contact"],
    ),
    (
        "moment_in_N_mm",
        request_with(wrench=[0.3, -1.2, -0.8, 5, 0, -2]).encode(),
        "bad_request",
        ["moment", "lever arm", "looks like N mm", "divide by 1000"],
    ),
    (
        "moment_implausible",
        request_with(wrench=[0.3, -1.2, -0.8, 5000, 0, -2]).encode(),
        "bad_request",
        ["moment", "check the moment"],
    ),
]
