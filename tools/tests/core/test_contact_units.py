"""Contacts in another unit than stated are refused where poses enter the host (replay
files, tracker adapters), with the likely unit: the same check as scene and protocol
files and `graspguide solve` (graspguide.core.units.hand_span_problem)."""

from __future__ import annotations

import pytest

from graspguide.sources import poses as src
from graspguide.sources.source_spec import open_source

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
HEAD = "t_s,qw,qx,qy,qz," + ",".join(
    f"{n}_{a}" for n in ("thumb", "index", "middle") for a in "xyz"
)


def replay(tmp_path, scale, rows=3, bad_row=None):
    lines = [HEAD]
    for i in range(rows):
        s = scale if bad_row in (None, i) else 1.0
        lines.append(f"{i * 0.01},1,0,0,0," + ",".join(str(v * s) for c in HAND3 for v in c))
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_replay_in_millimetres_read_as_metres_names_the_line_and_the_fix(tmp_path):
    path = replay(tmp_path, 1000.0, bad_row=2)  # rows 0, 1 in metres, row 2 in mm
    with pytest.raises(src.SourceError) as e:
        open_source("replay:" + path)
    msg = str(e.value)
    assert msg.startswith(path + ":4: contacts span 77.9"), msg
    assert "looks like millimetres" in msg and "--tracker mm/z/right/wxyz" in msg


def test_replay_in_millimetres_with_a_millimetre_convention_is_read(tmp_path):
    path = replay(tmp_path, 1000.0)
    got = list(open_source("replay:" + path, tracker="mm/z/right/wxyz"))
    assert [x for c in got[0][2] for x in c] == pytest.approx([x for c in HAND3 for x in c])
    with pytest.raises(src.SourceError, match="looks like metres"):
        open_source("replay:" + replay(tmp_path, 1.0), tracker="mm/z/right/wxyz")


def test_replay_of_a_hand_of_no_unit_says_to_check(tmp_path):
    with pytest.raises(src.SourceError, match="check their unit"):
        open_source("replay:" + replay(tmp_path, 1e-5))


class _Tracker(src.TrackerAdapter):
    name, rate_hz = "lab-tracker", 100.0
    convention = src.TRACKER_PRESETS["optitrack"]  # declares metres

    def __init__(self, scale):
        self.scale = scale

    def raw_samples(self):
        for i in range(3):
            yield i / 100.0, (0.0, 0.0, 0.0, 1.0), [[v * self.scale for v in c] for c in HAND3]


def test_adapter_with_contacts_in_another_unit_than_declared():
    assert len(list(_Tracker(1.0))) == 3
    with pytest.raises(src.SourceError) as e:
        list(_Tracker(1000.0))
    msg = str(e.value)
    assert msg.startswith("lab-tracker: the tracker's contacts at t=0.0: contacts span 77.9")
    assert "TrackerConvention(units='mm'" in msg


def test_contacts_at_one_point_are_left_to_the_device(tmp_path):
    path = tmp_path / "same.csv"
    path.write_text(HEAD + "\n0,1,0,0,0," + ",".join(["0.05"] * 9) + "\n")
    assert list(open_source("replay:" + str(path)))[0][2] == [[0.05] * 3] * 3
