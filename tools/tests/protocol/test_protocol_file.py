"""The study protocol file (protocol.study_protocol, protocols/paper.toml, docs/study.md):
validation messages, the seeded wrench draw with the paper's 5/7 split, deterministic
per-participant plans and their counterbalancing."""

from __future__ import annotations

import itertools
import math
import os
import tomllib

import pytest
from conftest import REPO_ROOT

from graspguide.core import _core
from graspguide.protocol import study_protocol as pf


def loads_protocol(text, source="<string>"):
    """A protocol from TOML text, through the loader's own checks (parse_protocol)."""
    return pf.parse_protocol(tomllib.loads(text), source)


PAPER = os.path.join(REPO_ROOT, "protocols", "paper.toml")


@pytest.fixture(scope="module")
def paper():
    return pf.load_protocol(PAPER)


@pytest.fixture(scope="module")
def paper_wrenches(paper):
    return pf.draw_wrenches(paper)


def paper_text() -> str:
    with open(PAPER, encoding="utf-8") as f:
        return f.read()


def edited(old: str, new: str) -> str:
    text = paper_text()
    assert old in text, old
    return text.replace(old, new, 1)


# --------------------------------------------------------------------------------------
# The paper's protocol
# --------------------------------------------------------------------------------------
def test_paper_protocol_values(paper):
    assert paper.threshold_deg == 3.0 and paper.hold_s == 0.5 and paper.timeout_s == 90.0
    assert paper.modalities == ("F+C", "Fperp+C", "F+V", "Fperp+V")
    assert paper.contact_counts == (3, 4)
    assert paper.wrench_count == 12 and paper.single_motor == 5
    assert paper.familiarization_s == 120.0
    # the example scenes' contacts
    from graspguide.protocol.scene_file import load_scene

    for k in (3, 4):
        scene = load_scene(os.path.join(REPO_ROOT, "tools", "examples", f"scene_paper_{k}.toml"))
        assert [x for c in paper.hands[k] for x in c] == pytest.approx(
            [x for c in scene.contacts for x in c]
        )
    assert paper.sessions_per_participant == 8


def test_config_hash_is_stable_and_sensitive(paper):
    again = pf.load_protocol(PAPER)
    assert again.config_hash == paper.config_hash
    assert len(paper.config_hash) == 64
    other = loads_protocol(edited("seed = 2019", "seed = 2020"))
    assert other.config_hash != paper.config_hash


def _core_motors(protocol, k, policy, wrench):
    """The rule, straight from the binding: mode C, at the start orientation, PWM > 0."""
    r = _core.solve(
        contacts=[list(c) for c in protocol.hands[k]],
        wrench=list(wrench),
        policy=policy,
        mode="C",
        constraints=protocol.constraints,
        orientation=list(protocol.start_quat),
        y_axis=list(protocol.y_axis),
        scalar="double",
        decomposition="structured",
        max_iterations=_core.kDefaultMaxIterations,
    )
    assert r["status"] == "ok"
    return sum(1 for p in r["pwm"] if p > 0)


def test_paper_split_5_single_7_multi(paper, paper_wrenches):
    ws = paper_wrenches
    assert [w.id for w in ws] == [f"W{i:02d}" for i in range(1, 13)]
    singles = [w for w in ws if _core_motors(paper, 3, "Fperp", w.wrench) == 1]
    assert len(singles) == 5
    assert sum(1 for w in ws if _core_motors(paper, 3, "Fperp", w.wrench) > 1) == 7
    assert {w.id for w in singles} == {w.id for w in ws if w.wrench_class == "single"}
    for w in ws:
        assert w.single_motor["k3/Fperp"] == (w.wrench_class == "single")
        for key, flag in w.single_motor.items():
            k, policy = int(key[1]), key.split("/")[1]
            assert flag == (_core_motors(paper, k, policy, w.wrench) == 1)
        lo, hi = paper.start_error_deg
        assert lo <= w.start_error_deg <= hi


def test_draw_is_deterministic_and_seeded(paper, paper_wrenches):
    assert pf.draw_wrenches(pf.load_protocol(PAPER)) == paper_wrenches
    other = pf.draw_wrenches(loads_protocol(edited("seed = 2019", "seed = 7")))
    assert [w.wrench for w in other] != [w.wrench for w in paper_wrenches]
    assert sum(w.wrench_class == "single" for w in other) == 5


def test_split_with_policy_F_is_refused_with_the_reason():
    text = edited('split_policy = "Fperp"', 'split_policy = "F"')
    text = text.replace("max_draws = 100000", "max_draws = 300")
    p = loads_protocol(text, "x.toml")
    with pytest.raises(pf.ProtocolFileError) as e:
        pf.draw_wrenches(p)
    msg = str(e.value)
    assert "x.toml" in msg and "split_policy" in msg and "Fperp" in msg and "max_draws" in msg


# --------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "old,new,needles",
    [
        ("[familiarization]", "[familiarisation]", ["[familiarisation]", "unknown table"]),
        ("seed = 2019", "seed = 2019\nsed = 1", ["[study] sed", "unknown key", "seed"]),
        ("seed = 2019\n", "", ["[study] seed", "missing"]),
        ("threshold_deg = 3.0", "threshold_deg = 181", ["[trial] threshold_deg", "[0, 180]"]),
        ("threshold_deg = 3.0", 'threshold_deg = "3"', ["[trial] threshold_deg", "number"]),
        ("hold_s = 0.5", "hold_s = 95.0", ["[trial] hold_s", "must not exceed timeout_s"]),
        (
            "start_quat = [1.0, 0.0, 0.0, 0.0]",
            "start_quat = [1.0, 1.0, 0.0, 0.0]",
            ["[trial] start_quat", "unit quaternion"],
        ),
        ('constraints = "paper"', 'constraints = "strict"', ["[trial] constraints", "'paper'"]),
        ('units = "m"', 'units = "cm"', ["[hand] units", "'mm'"]),
        (
            'modalities = ["F+C", "Fperp+C", "F+V", "Fperp+V"]',
            'modalities = ["F+C", "F+X"]',
            ["[conditions] modalities", "'Fperp+V'"],
        ),
        (
            'modalities = ["F+C", "Fperp+C", "F+V", "Fperp+V"]',
            'modalities = ["F+C", "F+C"]',
            ["[conditions] modalities", "twice"],
        ),
        ("contact_counts = [3, 4]", "contact_counts = [3, 5]", ["[conditions] contact_counts"]),
        (
            'modality_order = "balanced_latin_square"',
            'modality_order = "latin"',
            ["[conditions] modality_order", "balanced_latin_square"],
        ),
        ("single_motor = 5", "single_motor = 13", ["[wrenches] single_motor", "0..12"]),
        ("count = 12", "count = 0", ["[wrenches] count"]),
        (
            "start_error_deg = [20.0, 120.0]",
            "start_error_deg = [2.0, 120.0]",
            ["[wrenches] start_error_deg", "threshold_deg"],
        ),
        (
            "start_error_deg = [20.0, 120.0]",
            "start_error_deg = [120.0, 20.0]",
            ["[wrenches] start_error_deg", "min < max"],
        ),
        (
            "middle = [-0.010, 0.100, 0.040]\n\n[hand.k4]",
            "\n[hand.k4]",
            ["[hand.k3]", "missing middle"],
        ),
        (
            "palm   = [0.0, 0.045, 0.0]",
            "pinky = [0.0, 0.045, 0.0]",
            ["[hand.k4] pinky", "unknown contact"],
        ),
        ("trials = 4", "trials = -1", ["[familiarization] trials"]),
    ],
)
def test_validation_errors_name_the_key(old, new, needles):
    with pytest.raises(pf.ProtocolFileError) as e:
        loads_protocol(edited(old, new), "my.toml")
    msg = str(e.value)
    assert msg.startswith("my.toml: ")
    for n in needles:
        assert n in msg, (n, msg)


# --------------------------------------------------------------------------------------
# Ranges: every number of the file, below, above, NaN/inf and of the wrong type
# --------------------------------------------------------------------------------------
def set_key(table: str, key: str, literal: str) -> str:
    """paper.toml with ``key`` of ``[table]`` set to the TOML ``literal``."""
    text = paper_text()
    start = text.index(f"\n[{table}]") + 1
    end_of_table = text.find("\n[", start)
    at = text.find(f"\n{key} ", start, None if end_of_table < 0 else end_of_table) + 1
    if at == 0:  # a key the file leaves at its default: add it under the table's header
        at = text.index("\n", start) + 1
        return text[:at] + f"{key} = {literal}\n" + text[at:]
    end = text.index("\n", at)
    return text[:at] + f"{key} = {literal}" + text[end:]


def _trial_cases():
    """(table, key, below, above, accepted range) of the trial fields, from the core's
    TRIAL_LIMITS: the reader must accept what the core accepts, nothing else."""
    units = {"threshold_deg": "degrees", "hold_s": "seconds", "timeout_s": "seconds"}
    out = []
    for key, r in _core.TRIAL_LIMITS.items():
        low = "(" if r["min_exclusive"] else "["
        below = r["min"] if r["min_exclusive"] else r["min"] - 0.5
        out.append(
            (
                "trial",
                key,
                repr(below),
                repr(r["max"] + 0.5),
                f"{low}{r['min']:g}, {r['max']:g}] {units[key]}",
            )
        )
    return out


# The ranges docs/study.md documents for the other numbers.
RANGE_CASES = _trial_cases() + [
    ("study", "seed", "-1", None, "0..9223372036854775807"),
    ("study", "participants", "0", "10001", "1..10000"),
    ("study", "pose_rate_hz", "4.99", "2000.5", "[5, 2000] poses per second"),
    ("wrenches", "count", "0", "1001", "1..1000"),
    ("wrenches", "single_motor", "-1", "13", "0..12"),
    ("wrenches", "force_N", "0.0", "1000.5", "(0, 1000] N"),
    ("wrenches", "moment_max_Nm", "-0.001", "100.5", "[0, 100] N m"),
    ("wrenches", "max_draws", "0", "10000001", "1..10000000"),
    ("wrenches", "start_error_deg", "[-1.0, 120.0]", "[20.0, 180.5]", "<= 180 degrees"),
    ("familiarization", "duration_s", "-0.5", "3600.5", "[0, 3600] seconds"),
    ("familiarization", "trials", "-1", "101", "0..100"),
]
INTEGER_KEYS = {"seed", "participants", "count", "single_motor", "max_draws", "trials"}


def _range_params():
    for table, key, below, above, accepted in RANGE_CASES:
        ident = f"{table}.{key}"
        is_list = key == "start_error_deg"
        bad = {
            "below": below,
            "above": above,
            "nan": "[nan, 120.0]" if is_list else "nan",
            "inf": "[20.0, inf]" if is_list else "inf",
            "-inf": None if is_list else "-inf",
            "string": '"12"',
            "bool": "true",
        }
        for case, literal in bad.items():
            if literal is not None:
                yield pytest.param(table, key, literal, accepted, id=f"{ident}-{case}")


@pytest.mark.parametrize("table,key,literal,accepted", list(_range_params()))
def test_every_number_is_range_checked_and_named(table, key, literal, accepted):
    with pytest.raises(pf.ProtocolFileError) as e:
        loads_protocol(set_key(table, key, literal), "my.toml")
    msg = str(e.value)
    assert msg.startswith(f"my.toml: [{table}] {key}: "), msg
    if key in INTEGER_KEYS and not literal.lstrip("-").isdigit():
        assert "integer" in msg and accepted in msg, msg
    else:
        assert accepted in msg, msg


@pytest.mark.parametrize(
    "table,key,value",
    [
        ("trial", "threshold_deg", 0.0),
        ("trial", "threshold_deg", 19.0),
        ("trial", "hold_s", 0.0),
        ("trial", "timeout_s", 1800.0),
        ("trial", "hold_s", 90.0),
        ("study", "pose_rate_hz", 5.0),
        ("study", "pose_rate_hz", 2000.0),
        ("familiarization", "duration_s", 0.0),
        ("familiarization", "duration_s", 3600.0),
    ],
)
def test_range_ends_are_accepted(table, key, value):
    p = loads_protocol(set_key(table, key, repr(value)))
    assert p.to_dict()[table][key] == value


@pytest.mark.parametrize(
    "key,value", [("timeout_s", "9.3e12"), ("hold_s", "1e13"), ("timeout_s", "1e30")]
)
def test_values_that_overflowed_the_trial_clock_are_refused(key, value):
    """timeout_s = 9.3e12 and hold_s = 1e13 were accepted and overflowed the core's int64
    microseconds (an instant failure or an unearned success)."""
    with pytest.raises(pf.ProtocolFileError, match=rf"\[trial\] {key}: must be in"):
        loads_protocol(set_key("trial", key, value))


def test_trial_ranges_are_the_cores_not_a_copy(monkeypatch):
    """The reader takes threshold_deg, hold_s and timeout_s limits from the compiled core:
    narrowing the core's table narrows what the file may say."""
    from graspguide.protocol import scene_file as scene

    narrow = {k: dict(v) for k, v in _core.TRIAL_LIMITS.items()}
    narrow["timeout_s"]["max"] = 60.0
    monkeypatch.setattr(scene, "trial_limits", lambda: narrow)
    with pytest.raises(pf.ProtocolFileError, match=r"timeout_s: must be in \(0, 60\] seconds"):
        loads_protocol(paper_text())


@pytest.mark.parametrize(
    "units,scale,needles",
    [
        (
            "m",
            1000.0,
            ["[hand.k3]", "contacts span 77.9", "looks like millimetres", '[hand] units = "mm"'],
        ),
        (
            "mm",
            1.0,
            ["[hand.k3]", "contacts span 0.0779", "looks like metres", '[hand] units = "m"'],
        ),
        ("m", 100.0, ["[hand.k3]", "looks like centimetres", "millimetres (x 10)"]),
    ],
)
def test_contacts_in_another_unit_than_stated_are_refused(units, scale, needles):
    text = edited('units = "m"', f'units = "{units}"')
    for row in (
        "[0.045, 0.045, 0.035]",
        "[0.015, 0.095, 0.040]",
        "[-0.010, 0.100, 0.040]",
        "[0.0, 0.045, 0.0]",
    ):
        values = [float(x) * scale for x in row.strip("[]").split(",")]
        text = text.replace(row, "[" + ", ".join(repr(v) for v in values) + "]")
    with pytest.raises(pf.ProtocolFileError) as e:
        loads_protocol(text, "my.toml")
    for n in needles:
        assert n in str(e.value), (n, str(e.value))


def test_the_same_hand_in_millimetres_loads_to_the_same_metres(paper):
    text = edited('units = "m"', 'units = "mm"')
    for row in (
        "[0.045, 0.045, 0.035]",
        "[0.015, 0.095, 0.040]",
        "[-0.010, 0.100, 0.040]",
        "[0.0, 0.045, 0.0]",
    ):
        text = text.replace(
            row, "[" + ", ".join(f"{float(x) * 1000:.1f}" for x in row.strip("[]").split(",")) + "]"
        )
    p = loads_protocol(text)
    for k in (3, 4):
        assert [x for c in p.hands[k] for x in c] == pytest.approx(
            [x for c in paper.hands[k] for x in c], abs=1e-15
        )


def test_a_moment_in_newton_millimetres_is_refused():
    """moment_max_Nm = 5 with force_N = 1 (5 N mm written as N m): a 5 m lever arm."""
    with pytest.raises(pf.ProtocolFileError) as e:
        loads_protocol(
            set_key("wrenches", "moment_max_Nm", "5.0").replace(
                'moments = "zero"', 'moments = "drawn"'
            ),
            "my.toml",
        )
    msg = str(e.value)
    assert msg.startswith("my.toml: [wrenches] moment_max_Nm: ")
    assert "looks like N mm" in msg and "divide by 1000" in msg


def test_missing_hand_for_a_used_contact_count():
    text = paper_text()
    start = text.index("[hand.k4]")
    end = text.index("[conditions]")
    with pytest.raises(pf.ProtocolFileError, match=r"\[hand.k4\]: missing: contact_counts"):
        loads_protocol(text[:start] + text[end:])
    # but fine when k = 4 is not used
    text2 = (text[:start] + text[end:]).replace("contact_counts = [3, 4]", "contact_counts = [3]")
    assert loads_protocol(text2).contact_counts == (3,)


def test_unreadable_and_invalid_files(tmp_path):
    with pytest.raises(pf.ProtocolFileError, match="cannot read"):
        pf.load_protocol(str(tmp_path / "none.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("[study\nname = 1\n")
    with pytest.raises(pf.ProtocolFileError, match="not valid TOML"):
        pf.load_protocol(str(bad))


@pytest.mark.parametrize("pid", ["U", "1", "U0", "U 1", "U1/..", "", "x" * 40 + "1"])
def test_bad_participant_ids(pid):
    with pytest.raises(pf.ProtocolFileError, match="participant id"):
        pf.participant_number(pid)


def test_participant_numbers():
    assert pf.participant_number("U1") == 1
    assert pf.participant_number("P07") == 7
    assert pf.participant_number("lab-a_12") == 12


# --------------------------------------------------------------------------------------
# Order and plan
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_balanced_latin_square(n):
    rows = pf.balanced_latin_square(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    for row in rows:
        assert sorted(row) == list(range(n))
    for pos in range(n):
        column = [row[pos] for row in rows]
        assert all(column.count(c) == len(rows) // n for c in range(n))
    pairs = [(row[i], row[i + 1]) for row in rows for i in range(n - 1)]
    assert all(pairs.count(p) == len(rows) // n for p in itertools.permutations(range(n), 2))


def test_plan_is_deterministic(paper, paper_wrenches):
    a = pf.plan(paper, "U1")
    b = pf.plan(pf.load_protocol(PAPER), "U1")
    assert a == b
    assert pf.plan(paper, "U2") != a
    assert len(a) == paper.familiarization_trials + 8 * 12
    assert [t.trial_index for t in a] == list(range(1, len(a) + 1))


def test_plan_structure(paper, paper_wrenches):
    trials = pf.plan(paper, "U3")
    fam = [t for t in trials if t.familiarization]
    assert len(fam) == 4 and all(t.session == 0 for t in fam)
    assert trials[:4] == fam  # familiarization first
    assert {t.modality for t in fam} == set(paper.modalities)
    by_session = {}
    for t in trials[4:]:
        by_session.setdefault(t.session, []).append(t)
    assert sorted(by_session) == list(range(1, 9))
    seen = set()
    for ts in by_session.values():
        assert sorted(t.wrench_id for t in ts) == [w.id for w in paper_wrenches]
        assert len({(t.k, t.modality) for t in ts}) == 1
        seen.add((ts[0].k, ts[0].modality))
        assert [t.session_trial for t in ts] == list(range(1, 13))
        for t in ts:
            w = next(w for w in paper_wrenches if w.id == t.wrench_id)
            assert t.single_motor == w.single_motor[f"k{t.k}/{t.policy}"]
            assert t.wrench_class == w.wrench_class
    assert len(seen) == 8  # every condition once
    # the wrench order is shuffled per session
    orders = {tuple(t.wrench_id for t in ts) for ts in by_session.values()}
    assert len(orders) > 1


def test_counterbalancing_over_4_participants(paper):
    ids = ["U1", "U2", "U3", "U4"]
    orders = {pid: pf.session_order(paper, pid) for pid in ids}
    for block in (0, 1):
        positions = [[s.modality for s in orders[pid][4 * block : 4 * block + 4]] for pid in ids]
        for pos in range(4):
            assert sorted(row[pos] for row in positions) == sorted(paper.modalities)
    firsts = [orders[pid][0].k for pid in ids]
    assert firsts == [3, 4, 3, 4]  # alternating contact-count order
    # each participant: one k block, then the other
    for pid in ids:
        ks = [s.k for s in orders[pid]]
        assert ks[:4] == [ks[0]] * 4 and ks[4:] == [ks[4]] * 4 and ks[0] != ks[4]


def test_counterbalancing_over_8_participants(paper):
    combos = set()
    for n in range(1, 9):
        o = pf.session_order(paper, f"U{n}")
        combos.add((tuple(s.modality for s in o[:4]), o[0].k))
    assert len(combos) == 8  # every row with both contact orders


def test_fixed_and_random_orders():
    fixed = loads_protocol(
        edited('modality_order = "balanced_latin_square"', 'modality_order = "fixed"').replace(
            'contact_order = "alternate"', 'contact_order = "fixed"'
        )
    )
    for pid in ("U1", "U2"):
        o = pf.session_order(fixed, pid)
        assert [(s.k, s.modality) for s in o] == [(k, m) for k in (3, 4) for m in fixed.modalities]
    rnd = loads_protocol(
        edited('modality_order = "balanced_latin_square"', 'modality_order = "random"')
    )
    assert pf.session_order(rnd, "U1") == pf.session_order(rnd, "U1")
    assert {tuple(s.modality for s in pf.session_order(rnd, f"U{n}")) for n in range(1, 9)} != {
        tuple(rnd.modalities)
    }


# --------------------------------------------------------------------------------------
# [wrenches] moments: an explicit factor, "zero" or "drawn"
# --------------------------------------------------------------------------------------
DRAWN = os.path.join(REPO_ROOT, "protocols", "paper-moments-drawn.toml")


def test_the_paper_protocol_draws_pure_forces(paper, paper_wrenches):
    assert paper.moments == "zero" and paper.moment_max_Nm == 0.0
    assert all(w.wrench[3:] == (0.0, 0.0, 0.0) for w in paper_wrenches)
    assert sum(w.wrench_class == "single" for w in paper_wrenches) == 5


def test_the_drawn_level_differs_from_the_paper_file_only_in_the_moments(paper):
    drawn = pf.load_protocol(DRAWN)
    assert drawn.moments == "drawn" and drawn.moment_max_Nm == 0.005
    a, b = paper.to_dict(), drawn.to_dict()
    assert a["wrenches"].pop("moments") == "zero"
    assert b["wrenches"].pop("moments") == "drawn"
    assert (a["wrenches"].pop("moment_max_Nm"), b["wrenches"].pop("moment_max_Nm")) == (0, 0.005)
    a["study"].pop("name")
    b["study"].pop("name")
    assert a == b
    ws = pf.draw_wrenches(drawn)
    moments = [math.sqrt(sum(x * x for x in w.wrench[3:])) for w in ws]
    assert all(0.0 < m <= 0.005 + 1e-4 for m in moments)  # rounded to 4 decimals
    assert sum(w.wrench_class == "single" for w in ws) == 5


def test_the_moments_level_sets_the_candidate_prior(paper):
    import dataclasses
    import random

    drawn = dataclasses.replace(paper, moments="drawn", moment_max_Nm=0.005)
    for p, has_moment in ((paper, False), (drawn, True)):
        rng = random.Random(3)
        ws = [pf.candidate_wrench(rng, p) for _ in range(50)]
        assert all(abs(math.sqrt(sum(x * x for x in w[:3])) - 1.0) < 1e-3 for w in ws)
        assert any(w[3:] != (0.0, 0.0, 0.0) for w in ws) is has_moment


@pytest.mark.parametrize(
    "lines,moments,radius",
    [
        ('moments = "zero"', "zero", 0.0),
        ('moments = "zero"\nmoment_max_Nm = 0.0', "zero", 0.0),  # what to_dict writes back
        ('moments = "drawn"\nmoment_max_Nm = 0.002', "drawn", 0.002),
        ("", "zero", 0.0),  # neither key: the default
        ("moment_max_Nm = 0.0", "zero", 0.0),  # a file from before the key, radius 0
    ],
)
def test_moments_levels_that_load(lines, moments, radius):
    text = edited('moments = "zero"', lines)
    p = loads_protocol(text)
    assert (p.moments, p.moment_max_Nm) == (moments, radius)


@pytest.mark.parametrize(
    "lines,where,says",
    [
        # a file from before the key that draws moments: the fix names both ways
        ("moment_max_Nm = 0.005", "moment_max_Nm", ['add moments = "drawn"', "remove"]),
        ('moments = "some"', "moments", ["'zero', 'drawn'"]),
        ("moments = true", "moments", ["'zero', 'drawn'"]),
        ('moments = "drawn"', "moments", ["needs moment_max_Nm > 0", 'moments = "zero"']),
        ('moments = "drawn"\nmoment_max_Nm = 0.0', "moments", ["needs moment_max_Nm > 0"]),
        ('moments = "zero"\nmoment_max_Nm = 0.005', "moment_max_Nm", ['set moments = "drawn"']),
    ],
)
def test_a_bad_moments_setting_names_the_key_and_the_fix(lines, where, says):
    with pytest.raises(pf.ProtocolFileError) as e:
        loads_protocol(edited('moments = "zero"', lines), "my.toml")
    msg = str(e.value)
    assert msg.startswith(f"my.toml: [wrenches] {where}: "), msg
    for part in says:
        assert part in msg, msg
