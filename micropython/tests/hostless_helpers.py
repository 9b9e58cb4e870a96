"""Shared by the host-less tests (run inside MicroPython): where the data is, a small valid
plan, and a closeness check that names what differed."""

import json

from graspguide_mp import plan_file as pf

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
HAND4 = HAND3 + [[0.0, 0.045, 0.0]]


def _parent(path):
    i = path.rfind("/")
    return path[:i] if i > 0 else "."


def data_path(name):
    return _parent(__file__) + "/data/" + name


def load_json(name):
    with open(data_path(name)) as f:
        return json.load(f)


def close(got, want, tol, what):
    if not abs(got - want) <= tol:
        raise AssertionError("%s: got %r, want %r (tolerance %g)" % (what, got, want, tol))


def make_plan(n=3, participant=b"U1", rest_s=0.1, wrench=(0.0, -0.6, -0.8, 0.001, 0.0, 0.002)):
    h = pf.PlanHeader()
    h.participant = participant + b"\0" * (pf.PARTICIPANT_BYTES - len(participant))
    h.config_hash = b"\x01\x02\x03\x04\x05\x06\x07\x08"
    h.trial_count = n
    h.rest_s = rest_s
    h.hand_k3 = [list(c) for c in HAND3]
    h.hand_k4 = [list(c) for c in HAND4]
    trials = []
    for i in range(n):
        t = pf.PlanTrial()
        t.trial_index = i + 1
        t.session = 1
        t.session_trial = i + 1
        t.k = 3 + (i % 2)
        t.mode = i % 2
        t.wrench = list(wrench)
        trials.append(t)
    return pf.Plan(h, trials)
