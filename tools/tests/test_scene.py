"""scene.toml loader (graspguide.scene): examples, units, defaults, errors, stable hash."""

from __future__ import annotations

import os

import pytest

from graspguide import scene as gs

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        "examples")
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
    s = gs.loads_scene(MIN3)
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
    t = gs.loads_scene(full)
    assert t.contacts == s.contacts        # mm / 1000 is correctly rounded: exactly equal
    assert t.config_hash() == s.config_hash()
    assert len(s.config_hash()) == 64 and s.config_hash() == gs.loads_scene(MIN3).config_hash()
    assert gs.loads_scene(MIN3.replace('units = "m"', 'units = "m"\n') ).config_hash() == \
        s.config_hash()
    changed = gs.loads_scene(MIN3 + 'policy = "Fperp"\n')
    assert changed.config_hash() != s.config_hash()


def test_hash_is_stable_known_value():
    # canonical JSON: sorted keys, no spaces -> a fixed digest for a fixed configuration
    s = gs.loads_scene(MIN3)
    assert s.canonical_json().startswith('{"constraints":"paper","contacts_m":[[0.045,')
    assert s.config_hash() == gs.config_hash(s.to_dict())


@pytest.mark.parametrize("text, words", [
    (MIN3.replace('units = "m"', 'units = "cm"'), ["units", "'m'", "'mm'"]),
    (MIN3.replace('[scene]\nunits = "m"', "[scene]"), ["units is missing"]),
    (MIN3 + "ring = [0, 0, 0]\n", ["unknown key 'ring'", "[contacts]"]),
    (MIN3 + "[extra]\nx = 1\n", ["unknown table [extra]"]),
    (MIN3.replace("middle = [-0.010, 0.100, 0.040]", ""), ["missing middle"]),
    (MIN3.replace("[0.045, 0.045, 0.035]", "[0.045, 0.045]"), ["thumb", "3 numbers"]),
    (MIN3.replace("[0.045, 0.045, 0.035]", '"0.045"'), ["thumb", "3 numbers"]),
    (MIN3 + 'mode = "X"\n', ["mode", "'C'", "'V'"]),
    (MIN3 + "y_axis = [0, 0, 0]\n", ["y_axis", "zero"]),
    (MIN3 + "[trial]\nhold_s = \"long\"\n", ["[trial] hold_s", "number"]),
    (MIN3 + "[trial]\ntimeout_s = -1\n", ["[trial] timeout_s", "positive"]),
    (MIN3 + "[trial]\nthreshold = 3\n", ["unknown key 'threshold'", "threshold_deg"]),
    ("[scene\n", ["not valid TOML"]),
])
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
