"""Contacts from markers (graspguide.sources.marker_contacts): the hand-frame contacts
against an independent numpy computation, the hold-then-pause rule for lost markers,
HandTracking (the live sources' per-sample rule: every state and its notices), and
the per-posture re-run rule on a recorded-like 60 s hand at 100 Hz (its re-run rates are
reported in the summary: `python -m pytest -q tools/tests/sources/test_marker_contacts.py`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from graspguide.sources.marker_contacts import (
    HELD,
    PAUSED,
    TRACKED,
    HandTracking,
    MarkerContacts,
    RerunRule,
)

NAMES3 = ("Thumb", "Index", "Middle")
NAMES4 = NAMES3 + ("Palm",)
# the paper's hand (tools/examples/scene_paper_3.toml), plus a palm contact
HAND = np.array(
    [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040], [0.02, 0.03, 0.0]]
)


def rotation(q) -> np.ndarray:
    """The hand -> world matrix of a unit quaternion w, x, y, z (written out here, not the
    package's)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def axis_angle_quat(v) -> np.ndarray:
    """The quaternion of the rotation vector v (radians)."""
    a = float(np.linalg.norm(v))
    if a == 0:
        return np.array([1.0, 0, 0, 0])
    return np.concatenate([[math.cos(a / 2)], np.sin(a / 2) * np.asarray(v) / a])


def qmul(a, b) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def recorded_hand(
    seed: int = 0,
    rate: float = 100.0,
    duration: float = 60.0,
    k: int = 3,
    drift_mm: tuple[float, float] = (1.5, 3.0),
    tremor_mm: float = 0.2,
    noise_mm: float = 0.3,
) -> dict[str, np.ndarray]:
    """A recorded-like MoCap hand, in the world (metres, z up): the rigid body reaches
    0.25 m in 1.5 s then sways (5 mm at 0.2-0.4 Hz) while it turns slowly (up to 40
    degrees over the run) with a 0.3 degree 8-12 Hz tremor; the rigid body is measured with
    0.1 mm and 0.05 degree noise. Each fingertip drifts in the hand frame by 1.5-3 mm (two
    slow sinusoids, 0.03-0.3 Hz, a random direction each), trembles 0.2 mm at 8-12 Hz, and
    its marker has 0.3 mm white noise per axis. Returns t (n), the measured quat (n, 4),
    position (n, 3), markers (n, k, 3) and the true hand-frame contacts (n, k, 3)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    t = np.arange(n) / rate
    # the body
    u = np.clip(t / 1.5, 0, 1)
    reach = u**3 * (10 - 15 * u + 6 * u * u)
    pos = np.array([0.3, 0.1, 0.9]) + np.outer(reach, [0.25, 0.0, -0.05])
    sway_f = rng.uniform(0.2, 0.4, 3)
    pos = pos + 0.005 * np.sin(2 * math.pi * np.outer(t, sway_f) + rng.uniform(0, 6, 3))
    turn_axis = rng.normal(size=3)
    turn_axis /= np.linalg.norm(turn_axis)
    trem_f = rng.uniform(8, 12, 3)
    trem_p = rng.uniform(0, 2 * math.pi, 3)
    quats = np.empty((n, 4))
    for i, ti in enumerate(t):
        base = axis_angle_quat(turn_axis * math.radians(40) * math.sin(math.pi * ti / duration))
        trem = math.radians(0.3) * np.sin(2 * math.pi * trem_f * ti + trem_p)
        quats[i] = qmul(base, axis_angle_quat(trem))
    # the fingertips, in the hand frame
    base = HAND[:k]
    contacts = np.repeat(base[None], n, axis=0)
    for j in range(k):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        amp = rng.uniform(*drift_mm) / 1000.0
        f = rng.uniform(0.03, 0.3, 2)
        ph = rng.uniform(0, 2 * math.pi, 2)
        slow = 0.5 * (
            np.sin(2 * math.pi * f[0] * t + ph[0]) + np.sin(2 * math.pi * f[1] * t + ph[1])
        )
        tremor = tremor_mm / 1000.0 * np.sin(2 * math.pi * rng.uniform(8, 12) * t + ph[0])
        contacts[:, j] += np.outer(amp * slow, d) + np.outer(
            tremor, rng.normal(size=3) / math.sqrt(3)
        )
    markers = np.einsum("nij,nkj->nki", np.array([rotation(q) for q in quats]), contacts)
    markers = markers + pos[:, None, :] + rng.normal(scale=noise_mm / 1000.0, size=markers.shape)
    # what the tracker reports for the body: the true pose with its own noise
    body_q = np.array(
        [qmul(q, axis_angle_quat(rng.normal(scale=math.radians(0.05), size=3))) for q in quats]
    )
    body_p = pos + rng.normal(scale=1e-4, size=pos.shape)
    return {"t": t, "quat": body_q, "pos": body_p, "markers": markers, "contacts": contacts}


def expected_contacts(quat, pos, markers) -> np.ndarray:
    """R^T (p - t), independently."""
    return (np.asarray(markers) - np.asarray(pos)) @ rotation(quat)


@pytest.mark.parametrize("k", [3, 4])
def test_contacts_are_the_markers_in_the_hand_frame(k):
    hand = recorded_hand(seed=k, duration=2.0, k=k)
    tracker = MarkerContacts(NAMES4[:k])
    for i in range(len(hand["t"])):
        upd = tracker.update(hand["t"][i], hand["quat"][i], hand["pos"][i], hand["markers"][i])
        assert upd.state == TRACKED and upd.lost == ()
        want = expected_contacts(hand["quat"][i], hand["pos"][i], hand["markers"][i])
        np.testing.assert_allclose(upd.contacts, want, atol=1e-12)
        # the measured contacts are the true ones but for the noise (0.3 mm/axis, the body's)
        assert np.max(np.abs(np.asarray(upd.contacts) - hand["contacts"][i])) < 0.003


def _with_loss(hand, finger: int, start_s: float, length_s: float):
    markers = hand["markers"].copy()
    lost = (hand["t"] >= start_s) & (hand["t"] < start_s + length_s)
    markers[lost, finger] = np.nan
    return markers, lost


def test_a_short_loss_holds_a_long_one_pauses_then_resumes_without_a_jump():
    hand = recorded_hand(seed=3, duration=3.0)
    markers, short = _with_loss(hand, 1, 0.5, 0.1)
    markers2, long_ = _with_loss(hand, 1, 1.5, 1.0)
    markers[long_] = markers2[long_]
    tracker = MarkerContacts(NAMES3, hold_s=0.2)
    states = []
    before_short = before_long = None
    for i, t in enumerate(hand["t"]):
        upd = tracker.update(t, hand["quat"][i], hand["pos"][i], markers[i])
        states.append(upd.state)
        want = expected_contacts(hand["quat"][i], hand["pos"][i], hand["markers"][i])
        if short[i] or long_[i]:
            assert upd.lost == ("Index",)
        if upd.state == TRACKED:
            np.testing.assert_allclose(upd.contacts, want, atol=1e-12)
            last_seen = want[1]
        elif upd.state == HELD:
            # the lost marker stands at its last hand-frame position; the others are live
            np.testing.assert_allclose(upd.contacts[1], last_seen, atol=1e-12)
            np.testing.assert_allclose(
                np.delete(upd.contacts, 1, 0), np.delete(want, 1, 0), atol=1e-12
            )
            assert upd.lost_for_s <= 0.2 + 1e-9
        else:
            assert upd.contacts is None and upd.lost_for_s > 0.2
        if short[i] and before_short is None:
            before_short = i - 1
        if long_[i] and before_long is None:
            before_long = i - 1
    states = np.array(states)
    # 0.1 s lost: every sample still has contacts
    assert set(states[short]) == {HELD}
    # 1 s lost: held while the last sight is at most 0.2 s old, then paused to the end
    t_seen = hand["t"][before_long]
    held = long_ & (hand["t"] - t_seen <= 0.2 + 1e-9)
    assert set(states[held]) == {HELD} and set(states[long_ & ~held]) == {PAUSED}
    assert tracker.pauses == 1 and tracker.paused == int(np.sum(long_ & ~held))
    # back: tracked again, the contacts near the ones before the loss (drift over 1 s, noise)
    back = int(np.argmax(hand["t"] >= 2.5))
    assert states[back] == TRACKED and states[-1] == TRACKED
    upd_before = expected_contacts(
        hand["quat"][before_long], hand["pos"][before_long], hand["markers"][before_long]
    )
    tracker2 = MarkerContacts(NAMES3)
    resumed = tracker2.update(hand["t"][back], hand["quat"][back], hand["pos"][back], markers[back])
    assert np.max(np.linalg.norm(np.asarray(resumed.contacts) - upd_before, axis=1)) < 0.004


def test_occlusion_flags_count_as_lost_and_a_never_seen_marker_pauses():
    hand = recorded_hand(seed=4, duration=0.5)
    tracker = MarkerContacts(NAMES3, hold_s=0.05)
    first = tracker.update(
        0.0, hand["quat"][0], hand["pos"][0], hand["markers"][0], [False, False, True]
    )
    assert first.state == PAUSED and first.lost == ("Middle",)  # nothing to hold yet
    states = [
        tracker.update(
            t, hand["quat"][i], hand["pos"][i], hand["markers"][i], [False, i > 10, False]
        ).state
        for i, t in enumerate(hand["t"][1:], 1)
    ]
    assert states[:10] == [TRACKED] * 10
    assert HELD in states and states[-1] == PAUSED


def test_the_rerun_rule_sends_exactly_when_a_contact_moved_past_the_tolerance():
    hand = recorded_hand(seed=5, duration=5.0)
    for tol_mm in (0.5, 1.0, 2.0):
        rule = RerunRule(tol_mm / 1000.0)
        sent = None
        for i, t in enumerate(hand["t"]):
            c = expected_contacts(hand["quat"][i], hand["pos"][i], hand["markers"][i])
            moved = math.inf if sent is None else np.max(np.linalg.norm(c - sent, axis=1))
            out = rule.choose(t, c.tolist())
            if moved > tol_mm / 1000.0:
                assert out is not None
                np.testing.assert_allclose(out, c, atol=0)
                sent = c
            else:
                assert out is None
            # what the device holds is never further than the tolerance from the hand
            assert np.max(np.linalg.norm(c - sent, axis=1)) <= tol_mm / 1000.0
        stats = rule.stats()
        assert stats["poses"] == len(hand["t"]) and 1 <= stats["reruns"] <= len(hand["t"])


def test_rerun_rates_on_a_recorded_like_hand(report_figure):
    """The figures of docs/lab-streams.md: 60 s at 100 Hz, per tolerance."""
    hand = recorded_hand(seed=11, duration=60.0)
    rates = {}
    for tol_mm in (0.5, 1.0, 2.0):
        tracker = MarkerContacts(NAMES3)
        rule = RerunRule(tol_mm / 1000.0)
        for i, t in enumerate(hand["t"]):
            upd = tracker.update(t, hand["quat"][i], hand["pos"][i], hand["markers"][i])
            rule.choose(t, upd.contacts)
        s = rule.stats()
        assert s["poses"] == 6000
        rates[tol_mm] = s
        report_figure(
            f"lsl contacts: re-runs at tol {tol_mm:g} mm",
            f"{s['reruns_per_s']:.2f}/s, {s['reruns_per_100']:.1f} per 100 samples "
            f"({s['reruns']} of {s['poses']}; 60 s at 100 Hz, drift 1.5-3 mm, tremor "
            "0.2 mm, marker noise 0.3 mm/axis)",
        )
    # a wider tolerance re-runs less; at 2 mm the noise alone does not trigger it
    assert rates[0.5]["reruns"] > rates[1.0]["reruns"] > rates[2.0]["reruns"] >= 1
    assert rates[2.0]["reruns_per_s"] < 2.0


def test_the_default_tolerance_is_2_mm():
    rule = RerunRule()
    assert rule.choose(0.0, HAND[:3].tolist()) is not None
    assert rule.choose(0.01, (HAND[:3] + [0.0019, 0, 0]).tolist()) is None
    assert rule.choose(0.02, (HAND[:3] + [0.0021, 0, 0]).tolist()) is not None
    assert HandTracking(NAMES3, "Hand", print).rule.tol_m == 0.002


class Hand:
    """A hand at a fixed turn moving along x, its fingertips at HAND (hand frame); sample
    times on a 0.25 s grid (exact in binary), so that hold=0.5 falls on a sample."""

    Q = axis_angle_quat([0.3, -0.5, 0.2])

    def pose(self, t):
        return (self.Q, [0.2 + 0.01 * t, 0.1, 0.9])

    def markers(self, t, shift=0.0):
        quat, pos = self.pose(t)
        return (HAND[:3] + [shift, 0, 0]) @ rotation(quat).T + pos


def tracking(names=NAMES3, **kw):
    said: list[str] = []
    return HandTracking(names, "Hand", said.append, **kw), said


def test_hand_tracking_waits_for_the_first_sight_of_the_body_and_every_marker():
    tr, said = tracking(hold_s=0.5)
    h = Hand()
    assert tr.unseen() == ("rigid body Hand", "marker Thumb", "marker Index", "marker Middle")
    assert tr.update(0.0, None, h.markers(0.0)) is None
    lost_middle = h.markers(0.25)
    lost_middle[2] = np.nan
    assert tr.update(0.25, h.pose(0.25), lost_middle) is None
    assert tr.unseen() == ("marker Middle",)
    assert tr.update(0.5, h.pose(0.5), h.markers(0.5), [False, False, True]) is None
    got = tr.update(0.75, h.pose(0.75), h.markers(0.75))
    assert tr.unseen() == () and got is not None
    np.testing.assert_allclose(got[2], HAND[:3], atol=1e-12)
    # one notice, naming what was awaited then; waiting is not a pause
    assert said == [
        "waiting for the first sight of rigid body Hand, marker Thumb, marker Index, marker "
        "Middle: no POSE sent until then"
    ]
    st = tr.stats()
    assert (st["samples"], st["waiting"], st["paused"], st["pauses"]) == (4, 3, 0, 0)


def test_hand_tracking_body_lost_holds_the_pose_then_pauses_then_resumes():
    tr, said = tracking(hold_s=0.5)
    h = Hand()
    t = 0.0
    first = tr.update(t, h.pose(t), h.markers(t))
    assert first is not None
    # the body lost, the markers still seen (and moved 5 mm): the last pose and contacts
    # stand in; the markers are not put in the frame of a stale pose
    for t in (0.25, 0.5):
        got = tr.update(t, None, h.markers(t, shift=0.005))
        assert got is not None and got[0] == t
        np.testing.assert_allclose(got[1], Hand.Q / np.linalg.norm(Hand.Q), atol=1e-12)
        np.testing.assert_allclose(got[2], HAND[:3], atol=1e-12)
    assert said == []  # a hold is not said
    for t in (0.75, 1.0, 1.25):  # longer than hold: paused, said once
        assert tr.update(t, None, h.markers(t)) is None
    assert said == [
        "rigid body Hand lost for more than 0.5 s: paused, no POSE sent (the device's "
        "watchdog turns the motors off 200 ms after the last POSE) until it is seen again"
    ]
    # back: the new pose and the markers where they are now (no jump: the true ones)
    got = tr.update(1.5, h.pose(1.5), h.markers(1.5, shift=0.001))
    assert got is not None
    np.testing.assert_allclose(got[1], Hand.Q / np.linalg.norm(Hand.Q), atol=1e-12)
    np.testing.assert_allclose(got[2], HAND[:3] + [0.001, 0, 0], atol=1e-12)
    assert said[1:] == ["rigid body Hand and every marker seen again: POSEs resume"]
    st = tr.stats()
    assert (st["samples"], st["body_lost"], st["held"], st["paused"], st["pauses"]) == (
        7,
        5,
        2,
        3,
        1,
    )


def test_hand_tracking_marker_lost_holds_then_pauses_once_per_episode():
    tr, said = tracking(hold_s=0.5)
    h = Hand()
    states = []
    lost = {0.5, 0.75, 1.0, 1.25, 1.5, 2.5, 2.75, 3.0, 3.25}  # two episodes of the index
    for k in range(16):
        t = k * 0.25
        m = h.markers(t, shift=0.0001 * k)
        if t in lost:
            m[1] = np.nan
        got = tr.update(t, h.pose(t), m)
        states.append(got is not None)
        if got is not None:
            want = HAND[:3] + [0.0001 * k, 0, 0]
            if t in lost:  # the index where it was last seen, in the hand frame
                last = max(x for x in range(k) if x * 0.25 not in lost)
                want[1] = HAND[1] + [0.0001 * last, 0, 0]
            np.testing.assert_allclose(got[2], want, atol=1e-12)
    # last seen at 0.25: held to 0.75 (0.5 s), paused 1.0-1.5; again at 2.25: held to 2.75
    assert [k * 0.25 for k in range(16) if not states[k]] == [1.0, 1.25, 1.5, 3.0, 3.25]
    pause = (
        "marker Index lost for more than 0.5 s: paused, no POSE sent (the device's watchdog "
        "turns the motors off 200 ms after the last POSE) until it is seen again"
    )
    resume = "rigid body Hand and every marker seen again: POSEs resume"
    assert said == [pause, resume, pause, resume]
    st = tr.stats()
    assert (st["samples"], st["held"], st["paused"], st["pauses"], st["body_lost"]) == (
        16,
        4,
        5,
        2,
        0,
    )


def test_hand_tracking_one_episode_whatever_its_causes():
    tr, said = tracking(hold_s=0.5)
    h = Hand()
    tr.update(0.0, h.pose(0.0), h.markers(0.0))
    m = h.markers(0.25)
    m[0] = np.nan
    assert tr.update(0.25, h.pose(0.25), m) is not None  # thumb held
    assert tr.update(0.5, None, None) is not None  # and the body: both held
    assert tr.update(1.0, None, None) is None  # the body first past hold: paused
    m = h.markers(1.25)
    m[0] = np.nan
    assert tr.update(1.25, h.pose(1.25), m) is None  # the body back, the thumb still lost
    assert tr.update(1.5, h.pose(1.5), h.markers(1.5)) is not None
    assert len(said) == 2 and said[0].startswith("rigid body Hand lost for more than 0.5 s")
    assert said[1].endswith("POSEs resume")
    st = tr.stats()
    assert (st["held"], st["paused"], st["pauses"], st["body_lost"]) == (2, 2, 1, 2)


def test_hand_tracking_names_only_the_markers_lost_past_hold():
    tr, said = tracking(hold_s=0.5)
    h = Hand()
    for k, flags in enumerate([(0, 0, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (1, 1, 0)]):
        tr.update(k * 0.25, h.pose(k * 0.25), h.markers(k * 0.25), [bool(f) for f in flags])
    # at 1.0 s the index is 0.75 s gone, the thumb just lost (held): only the index named
    assert len(said) == 1 and said[0].startswith("marker Index lost for more than 0.5 s")


def test_hand_tracking_occlusion_flags_and_poses_only():
    tr, said = tracking(hold_s=0.25)
    h = Hand()
    tr.update(0.0, h.pose(0.0), h.markers(0.0))
    # the tracker's flag: the position it sends with it is ignored
    got = tr.update(0.25, h.pose(0.25), h.markers(0.25, shift=0.01), [False, True, False])
    assert got is not None
    np.testing.assert_allclose(got[2][1], HAND[1], atol=1e-12)
    np.testing.assert_allclose(got[2][0], HAND[0] + [0.01, 0, 0], atol=1e-12)
    # without markers: poses only, the contacts always None, a lost body still pauses
    tr, said = tracking(names=())
    assert tr.unseen() == ("rigid body Hand",)
    got = tr.update(0.0, h.pose(0.0))
    assert got is not None and got[2] is None and tr.send(0.0, got) == (0.0, got[1], None)
    assert tr.update(0.25, None) is None and len(said) == 1
    st = tr.stats()
    assert (st["poses"], st["paused"], st["pauses"]) == (1, 1, 1) and "reruns" not in st


def test_hand_tracking_send_applies_the_rerun_rule():
    tr, _ = tracking(hold_s=0.5, tol_m=0.002)
    h = Hand()
    out = []
    for k in range(8):  # the fingertips slide 0.75 mm a sample
        t = k * 0.25
        got = tr.update(t, h.pose(t), h.markers(t, shift=0.00075 * k))
        out.append(tr.send(t, got))
    # sent at 0; then when 2 mm is passed: 2.25 mm at k=3, 4.5 mm at k=6
    assert [k for k, s in enumerate(out) if s[2] is not None] == [0, 3, 6]
    np.testing.assert_allclose(out[3][2], HAND[:3] + [0.00225, 0, 0], atol=1e-12)
    st = tr.stats()
    assert (st["poses"], st["reruns"], st["tol_mm"]) == (8, 3, 2.0)
    # a new run (the next trial): its first POSE carries the contacts, unmoved as they are
    again = tr.update(2.0, h.pose(2.0), h.markers(2.0, shift=0.00075 * 7))
    assert tr.send(2.0, again)[2] is None
    tr.new_run()
    np.testing.assert_allclose(tr.send(2.0, again)[2], HAND[:3] + [0.00525, 0, 0], atol=1e-12)


def test_bad_arguments():
    with pytest.raises(ValueError, match="3 or 4 markers"):
        MarkerContacts(("Thumb", "Index"))
    with pytest.raises(ValueError, match="hold"):
        MarkerContacts(NAMES3, hold_s=-1)
    with pytest.raises(ValueError, match="tolerance"):
        RerunRule(float("nan"))
