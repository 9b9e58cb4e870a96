"""scene.toml loader (graspguide.protocol.scene_file): examples, units, defaults, errors,
stable hash."""

from __future__ import annotations

import os
import tomllib

import pytest
from conftest import TOOLS_DIR

from graspguide.core import _core, units
from graspguide.protocol import scene_file as gs


def loads_scene(text, source="<string>"):
    """A scene from TOML text, through the loader's own checks (parse_scene)."""
    return gs.parse_scene(tomllib.loads(text), source)


EXAMPLES = os.path.join(TOOLS_DIR, "examples")
MIN3 = """
[scene]
units = "m"
[contacts]
thumb = [0.045, 0.045, 0.035]
index = [0.015, 0.095, 0.040]
middle = [-0.010, 0.100, 0.040]
"""


def test_examples_load():
    s4 = gs.load_scene(os.path.join(EXAMPLES, "scene_paper_4.toml"))
    s3 = gs.load_scene(os.path.join(EXAMPLES, "scene_paper_3.toml"))
    assert s4.k == 4 and s3.k == 3
    assert s4.fingers == ("thumb", "index", "middle", "palm")
    # mm -> m: the first three contacts of the 4-contact (mm) file equal the 3-contact (m) one
    for a, b in zip(s4.contacts, s3.contacts):
        assert a == pytest.approx(b, abs=1e-12)
    assert s4.contacts[3] == pytest.approx((0.0, 0.045, 0.0))
    assert (s3.threshold_deg, s3.hold_s, s3.timeout_s) == (3.0, 0.5, 90.0)


def test_defaults_and_hash_is_normalised():
    s = loads_scene(MIN3)
    assert s.y_axis == (0.0, 1.0, 0.0)
    assert (s.constraints, s.policy, s.mode) == ("paper", "F", "C")
    assert (s.threshold_deg, s.hold_s, s.timeout_s) == (3.0, 0.5, 90.0)
    # the same configuration written out in full, in mm, with keys reordered: same hash
    full = """
[trial]
timeout_s = 90
hold_s = 0.5
threshold_deg = 3
[contacts]
mode = "C"
policy = "F"
constraints = "paper"
y_axis = [0, 1, 0]
middle = [-10.0, 100.0, 40.0]
index = [15.0, 95.0, 40.0]
thumb = [45.0, 45.0, 35.0]
[scene]
units = "mm"
"""
    t = loads_scene(full)
    assert t.contacts == s.contacts  # mm / 1000 is correctly rounded: exactly equal
    assert t.config_hash() == s.config_hash()
    assert len(s.config_hash()) == 64 and s.config_hash() == loads_scene(MIN3).config_hash()
    assert (
        loads_scene(MIN3.replace('units = "m"', 'units = "m"\n')).config_hash() == s.config_hash()
    )
    changed = loads_scene(MIN3 + 'policy = "Fperp"\n')
    assert changed.config_hash() != s.config_hash()


def test_hash_is_stable_known_value():
    # canonical JSON: sorted keys, no spaces -> a fixed digest for a fixed configuration
    s = loads_scene(MIN3)
    assert s.canonical_json().startswith('{"constraints":"paper","contacts_m":[[0.045,')
    assert s.config_hash() == gs.config_hash(s.to_dict())


@pytest.mark.parametrize(
    "text, words",
    [
        (MIN3.replace('units = "m"', 'units = "cm"'), ["units", "'m'", "'mm'"]),
        (MIN3.replace('[scene]\nunits = "m"', "[scene]"), ["units is missing"]),
        (MIN3 + "ring = [0, 0, 0]\n", ["unknown key 'ring'", "[contacts]"]),
        (MIN3 + "[extra]\nx = 1\n", ["unknown table [extra]"]),
        (MIN3.replace("middle = [-0.010, 0.100, 0.040]", ""), ["missing middle"]),
        (MIN3.replace("[0.045, 0.045, 0.035]", "[0.045, 0.045]"), ["thumb", "3 numbers"]),
        (MIN3.replace("[0.045, 0.045, 0.035]", '"0.045"'), ["thumb", "3 numbers"]),
        (MIN3 + 'mode = "X"\n', ["mode", "'C'", "'V'"]),
        (MIN3 + "y_axis = [0, 0, 0]\n", ["y_axis", "zero"]),
        (MIN3 + '[trial]\nhold_s = "long"\n', ["[trial] hold_s", "number"]),
        (MIN3 + "[trial]\ntimeout_s = -1\n", ["[trial] timeout_s", "(0, 1800] seconds"]),
        (MIN3 + "[trial]\nthreshold = 3\n", ["unknown key 'threshold'", "threshold_deg"]),
        ("[scene\n", ["not valid TOML"]),
    ],
)
def test_errors_name_file_key_and_fix(tmp_path, text, words):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(gs.SceneError) as e:
        gs.load_scene(str(path))
    msg = str(e.value)
    assert msg.startswith(str(path)), msg
    for w in words:
        assert w in msg, (w, msg)


def test_missing_file():
    with pytest.raises(gs.SceneError, match="cannot read"):
        gs.load_scene("/nonexistent/scene.toml")


# --------------------------------------------------------------------------------------
# [trial] ranges: the core's (TRIAL_LIMITS), checked on load with the key and the range
# --------------------------------------------------------------------------------------
def _trial_params():
    units = {"threshold_deg": "degrees", "hold_s": "seconds", "timeout_s": "seconds"}
    for key, r in _core.TRIAL_LIMITS.items():
        accepted = f"{'(' if r['min_exclusive'] else '['}{r['min']:g}, {r['max']:g}] {units[key]}"
        below = r["min"] if r["min_exclusive"] else r["min"] - 1e-3
        for case, literal in (
            ("below", repr(below)),
            ("above", repr(r["max"] + 1e-3)),
            ("nan", "nan"),
            ("inf", "inf"),
            ("-inf", "-inf"),
            ("string", '"3"'),
            ("bool", "true"),
            ("list", "[3.0]"),
        ):
            yield pytest.param(key, literal, accepted, id=f"{key}-{case}")


@pytest.mark.parametrize("key,literal,accepted", list(_trial_params()))
def test_trial_fields_out_of_the_cores_range_are_refused(tmp_path, key, literal, accepted):
    path = tmp_path / "s.toml"
    path.write_text(MIN3 + f"[trial]\n{key} = {literal}\n")
    with pytest.raises(gs.SceneError) as e:
        gs.load_scene(str(path))
    msg = str(e.value)
    assert msg.startswith(f"{path}: [trial] {key} must "), msg
    assert accepted in msg, msg


@pytest.mark.parametrize(
    "key,value",
    [("timeout_s", "9.3e12"), ("hold_s", "1e13"), ("timeout_s", "1e30"), ("hold_s", "9.3e12")],
)
def test_values_that_overflowed_the_trial_clock_are_refused(key, value):
    """Accepted before and sent in SET_SCENE: the core's int64 microseconds overflowed
    (an instant failure with completion -9.2e12 s, or a success without the hold)."""
    with pytest.raises(gs.SceneError, match=rf"\[trial\] {key} must be in"):
        loads_scene(MIN3 + f"[trial]\n{key} = {value}\n")


def test_trial_range_ends_and_hold_up_to_the_timeout():
    lim = _core.TRIAL_LIMITS
    s = loads_scene(
        MIN3 + f"[trial]\nthreshold_deg = {lim['threshold_deg']['min']!r}\n"
        f"hold_s = {lim['hold_s']['max']!r}\ntimeout_s = "
        f"{lim['timeout_s']['max']!r}\n"
    )
    assert (s.threshold_deg, s.hold_s, s.timeout_s) == (
        lim["threshold_deg"]["min"],
        lim["hold_s"]["max"],
        lim["timeout_s"]["max"],
    )
    assert loads_scene(MIN3 + "[trial]\nhold_s = 20\ntimeout_s = 20\n").hold_s == 20.0
    with pytest.raises(gs.SceneError, match=r"\[trial\] hold_s must not exceed timeout_s"):
        loads_scene(MIN3 + "[trial]\nhold_s = 20.5\ntimeout_s = 20\n")


# --------------------------------------------------------------------------------------
# Units: contacts must span like a hand in the stated unit
# --------------------------------------------------------------------------------------
def _scaled(units: str, factor: float) -> str:
    rows = {
        "thumb": (0.045, 0.045, 0.035),
        "index": (0.015, 0.095, 0.040),
        "middle": (-0.010, 0.100, 0.040),
    }
    body = "".join(f"{n} = [{', '.join(repr(x * factor) for x in v)}]\n" for n, v in rows.items())
    return f'[scene]\nunits = "{units}"\n[contacts]\n' + body


@pytest.mark.parametrize(
    "units,factor,needles",
    [
        (
            "m",
            1000.0,
            [
                "[contacts]",
                "contacts span 77.9",
                "looks like millimetres",
                'set [scene] units = "mm"',
            ],
        ),
        ("mm", 1.0, ["contacts span 0.0779", "mm", "looks like metres", 'set [scene] units = "m"']),
        ("m", 100.0, ["looks like centimetres", "millimetres (x 10)"]),
        ("m", 1e-5, ["contacts span 7.79", "5 mm to 0.5 m", "check the contact positions"]),
        ("m", 20.0, ["contacts span 1.55", "5 mm to 0.5 m"]),
    ],
)
def test_contacts_in_another_unit_are_refused_with_the_likely_unit(units, factor, needles):
    with pytest.raises(gs.SceneError) as e:
        loads_scene(_scaled(units, factor), "hand.toml")
    msg = str(e.value)
    assert msg.startswith("hand.toml: "), msg
    for n in needles:
        assert n in msg, (n, msg)


@pytest.mark.parametrize("factor", [0.07, 1.0, 6.0])  # spans of 5.5 mm, 78 mm, 0.47 m
def test_hands_from_5_mm_to_half_a_metre_load(factor):
    s = loads_scene(_scaled("m", factor))
    assert units.HAND_SPAN_M[0] <= units.hand_span(s.contacts) <= units.HAND_SPAN_M[1]
    mm = loads_scene(_scaled("mm", 1000 * factor)).contacts
    assert [x for c in mm for x in c] == pytest.approx([x for c in s.contacts for x in c])


def test_moment_unit_check_catches_newton_millimetres():
    hand = loads_scene(MIN3).contacts  # metres, span 78 mm
    assert units.moment_unit_problem(hand, [1, 0, 0, 0.005, 0, 0]) is None  # 5 mm lever
    assert units.moment_unit_problem(hand, [1, 0, 0, 0.7, 0, 0]) is None  # 9 spans
    msg = units.moment_unit_problem(hand, [1, 0, 0, 5, 0, 0])  # 5 N mm as N m
    assert "looks like N mm" in msg and "divide by 1000" in msg
    assert "check the moment" in units.moment_unit_problem(hand, [1, 0, 0, 5000, 0, 0])
    assert units.moment_unit_problem(hand, [0, 0, 0, 5, 0, 0]) is None  # the core's zero_force
