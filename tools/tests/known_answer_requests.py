"""The known answers (test/data/known_answers.json) as `graspguide solve` request lines,
shared by the CLI, simulated-device and QEMU firmware tests."""

from __future__ import annotations

import json
import math
import os

import pytest

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
KNOWN_ANSWERS = os.path.join(REPO_ROOT, "test", "data", "known_answers.json")
NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def decode_numbers(x):
    """The JSON file spells non-finite numbers as strings; these are the floats."""
    if isinstance(x, str):
        return NON_FINITE[x]
    if isinstance(x, list):
        return [decode_numbers(v) for v in x]
    return x


def load_cases():
    if not os.path.exists(KNOWN_ANSWERS):
        pytest.fail(f"{KNOWN_ANSWERS} is missing: run `python tools/scripts/gen_known_answers.py`")
    with open(KNOWN_ANSWERS, encoding="utf-8") as f:
        cases = json.load(f)["cases"]
    assert cases, "no known-answer cases"
    return cases


def request_lines(cases):
    """One JSON request line per case, in order. "units": "any": the cases include hands
    of 0.1 mm and 10 m (the core's scale tests), which `graspguide solve` would otherwise
    refuse as contacts in another unit than metres."""
    lines = []
    for case in cases:
        req = {
            key: decode_numbers(case[key])
            for key in ("contacts", "wrench", "y_axis", "orientation")
        }
        req.update(
            policy=case["policy"], mode=case["mode"], constraints=case["constraints"], units="any"
        )
        lines.append(json.dumps(req, allow_nan=True))
    return lines
