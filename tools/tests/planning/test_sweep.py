"""`graspguide sweep` (graspguide.planning.sweep): the speed-accuracy trade, SIMULATED.

A tiny sweep end to end against the simulated device with the virtual participant (the
JSON has every point with sane fields, the PNG is a PNG, a second run resumes without
running anything), bad arguments, the derived protocols, and one property that holds by
construction: with an open-loop source (the same pose trajectory whatever the threshold)
a larger threshold never makes the same trial take longer, nor turns a success into a
failure."""

from __future__ import annotations

import csv
import json
import os

import pytest
from conftest import REPO_ROOT

from graspguide import cli
from graspguide.cli import sweep as sweep_command
from graspguide.planning import sweep as sw
from graspguide.protocol import study_protocol as pf

TESTS_DIR = os.path.dirname(os.path.abspath(__file__))
REPO = REPO_ROOT
PAPER = os.path.join(REPO, "protocols", "paper.toml")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _no_pythonpath(monkeypatch):
    # the runner subprocesses must import the installed package (with graspguide.core._core)
    monkeypatch.delenv("PYTHONPATH", raising=False)


def _sweep(out, *extra):
    return cli.main(
        [
            "sweep",
            "--protocol",
            PAPER,
            "--participants",
            "1",
            "--wrenches",
            "1",
            "--contacts",
            "3",
            "--out",
            str(out),
            "--jobs",
            "2",
            *extra,
        ]
    )


# --------------------------------------------------------------------------------------
# End to end
# --------------------------------------------------------------------------------------
def test_tiny_sweep_end_to_end_and_resume(tmp_path, capsys):
    out = tmp_path / "sweep"
    code = _sweep(out, "--thresholds", "3,10", "--rates", "30,100", "--modalities", "F+C,F+V")
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "SIMULATED" in printed

    data = json.loads((out / "sweep.json").read_text())
    assert data["format"] == sw.SWEEP_FORMAT
    assert data["simulated"] is True and "SIMULATED" in data["note"]
    assert data["modalities"] == ["F+C", "F+V"]
    assert data["contact_counts"] == [3]
    assert data["base"] == {"threshold_deg": 3.0, "pose_rate_hz": 100.0}
    # one factor at a time around 3 deg / 100 Hz: (3, 30), (3, 100), (10, 100)
    keys = sorted((p["threshold_deg"], p["pose_rate_hz"]) for p in data["points"])
    assert keys == [(3.0, 30.0), (3.0, 100.0), (10.0, 100.0)]
    axes = {(p["threshold_deg"], p["pose_rate_hz"]): set(p["axes"]) for p in data["points"]}
    assert axes[(3.0, 100.0)] == {"threshold", "rate"}
    assert axes[(10.0, 100.0)] == {"threshold"} and axes[(3.0, 30.0)] == {"rate"}
    for p in data["points"]:
        assert set(p["modalities"]) == {"F+C", "F+V"}
        assert set(p["modes"]) == {"C", "V"}
        assert set(p["modes_by_contacts"]) == {"k3/C", "k3/V"}
        assert p["modes_by_contacts"]["k3/V"] == p["modalities"]["F+V"]  # k = 3 only
        assert "participant:" in p["source"]
        assert f"task_threshold_deg={p['threshold_deg']:g}" in p["source"]
        assert f"rate_hz={p['pose_rate_hz']:g}" in p["source"]
        for s in list(p["modalities"].values()) + [p["all"]]:
            assert s["trials"] >= 1 and 0 <= s["successes"] <= s["trials"]
            assert s["success_rate"] == pytest.approx(s["successes"] / s["trials"], abs=1e-4)
            for key in ("completion_median_s", "completion_mean_s"):
                assert 0.0 < s[key] <= data["timeout_s"]
            if s["successes"]:
                assert 0.0 < s["success_completion_median_s"] < data["timeout_s"]
            else:
                assert s["success_completion_median_s"] is None
                assert s["completion_mean_s"] == data["timeout_s"]  # failures count 90 s
            assert s["poses"] > 0
        assert p["all"]["trials"] == data["trials_per_point"] == 2
    # every point's trials are the runner's, marked simulated
    for p in data["points"]:
        with open(out / p["folder"] / "U1" / "trials.jsonl") as f:
            recs = [json.loads(line) for line in f]
        assert len(recs) == 2 and all(r["simulated"] for r in recs)
    png = (out / "sweep.png").read_bytes()
    assert png[:8] == PNG_MAGIC and len(png) > 10_000
    import matplotlib.image as mpimg

    img = mpimg.imread(str(out / "sweep.png"))
    assert img.shape[0] > 400 and img.shape[1] > 600

    # a second run resumes: nothing left to run, the same figures
    code = _sweep(out, "--thresholds", "3,10", "--rates", "30,100", "--modalities", "F+C,F+V")
    printed = capsys.readouterr().out
    assert code == 0
    assert "0 runner processes to run" in printed
    again = json.loads((out / "sweep.json").read_text())
    assert again["points"] == data["points"]


def _pose_rows(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [(r["t_s"], r["qw"], r["qx"], r["qy"], r["qz"]) for r in rows]


def test_larger_threshold_never_makes_the_same_trajectory_take_longer(tmp_path, capsys):
    """By construction: an open-loop source (synthetic, seeded per participant and trial)
    sends the same poses whatever the threshold, and the device completes a trial the
    first time the error has stayed below the threshold for hold_s; the times below a
    larger threshold include those below a smaller one, so the completion time can only
    shrink and a success stays a success."""
    out = tmp_path / "mono"
    code = _sweep(
        out,
        "--thresholds",
        "1,3,10",
        "--rates",
        "100",
        "--wrenches",
        "2",
        "--modalities",
        "F+V",
        "--source",
        "synthetic",
    )
    capsys.readouterr()
    assert code == 0
    data = json.loads((out / "sweep.json").read_text())
    pts = {p["threshold_deg"]: p for p in data["points"] if "threshold" in p["axes"]}
    assert sorted(pts) == [1.0, 3.0, 10.0]
    recs = {}
    for t, p in pts.items():
        with open(out / p["folder"] / "U1" / "trials.jsonl") as f:
            recs[t] = {r["trial_index"]: r for r in map(json.loads, f)}
    assert all(len(r) == 2 for r in recs.values())
    strictly = 0
    for small, large in ((1.0, 3.0), (3.0, 10.0)):
        for idx, a in recs[small].items():
            b = recs[large][idx]
            assert b["wrench_id"] == a["wrench_id"]
            # the same trajectory: identical poses up to the shorter trial's end
            pa = _pose_rows(out / pts[small]["folder"] / "U1" / "frames" / f"trial-{idx:04d}.csv")
            pb = _pose_rows(out / pts[large]["folder"] / "U1" / "frames" / f"trial-{idx:04d}.csv")
            n = min(len(pa), len(pb))
            assert n > 10 and pa[:n] == pb[:n]
            assert b["completion_s"] <= a["completion_s"] + 1e-9
            assert b["success"] or not a["success"]
            strictly += b["completion_s"] < a["completion_s"] - 1e-6
    assert strictly >= 1  # and the threshold does matter
    tp = data["threshold_pairs"]["all"]
    assert tp["pairs"] == 4 and tp["larger_threshold_took_longer"] == 0


# --------------------------------------------------------------------------------------
# Bad arguments
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, words",
    [
        (["--thresholds", "0,3"], ["--thresholds", "> 0"]),
        (["--thresholds", "-2"], ["--thresholds", "out of range"]),
        (["--thresholds", "3,abc"], ["--thresholds", "not a number"]),
        (["--thresholds", "3,,5"], ["--thresholds", "comma-separated"]),
        (["--rates", "0"], ["--rates", "> 0"]),
        (["--rates", "100,-30"], ["--rates", "out of range"]),
        (["--modalities", "F+X"], ["unknown modality", "F+X", "Fperp+V"]),
        (["--modalities", "W"], ["unknown modality", "'W'"]),
        (["--contacts", "5"], ["--contacts"]),
        (["--thresholds", "25"], ["threshold 25", "start error"]),
        (["--source", "participant:nonsense=1"], ["unknown participant key", '"nonsense"']),
    ],
)
def test_bad_arguments_give_a_clear_error(tmp_path, capsys, args, words):
    code = cli.main(["sweep", "--protocol", PAPER, "--out", str(tmp_path / "x"), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("graspguide sweep: error: ")
    for w in words:
        assert w in err
    assert not (tmp_path / "x" / "sweep.json").exists()


def test_bad_integer_options_are_refused_by_the_parser(capsys):
    for args in (["--participants", "0"], ["--wrenches", "x"], ["--jobs", "-1"]):
        with pytest.raises(SystemExit) as e:
            cli.main(["sweep", "--protocol", PAPER, *args])
        assert e.value.code == 2
    assert "must be between" in capsys.readouterr().err


# --------------------------------------------------------------------------------------
# Pieces
# --------------------------------------------------------------------------------------
def test_points_one_factor_at_a_time_and_grid():
    pts = sw.sweep_points([1, 3, 10], [30, 100], 3.0, 100.0)
    assert [p.key for p in pts] == [(1, 100), (3, 30), (3, 100), (10, 100)]
    grid = sw.sweep_points([1, 10], [30, 100], 3.0, 100.0, grid=True)
    keys = {p.key for p in grid}
    assert keys == {(1, 100), (10, 100), (3, 30), (3, 100), (1, 30), (10, 30)}
    assert {p.key: p.axes for p in grid}[(1, 30)] == ("grid",)


def test_derived_protocol_keeps_geometry_and_seed_and_round_trips(tmp_path):
    base = pf.load_protocol(PAPER)
    d = sw.derive_protocol(base, 5.0, 60.0, 4)
    assert (d.threshold_deg, d.pose_rate_hz, d.wrench_count) == (5.0, 60.0, 4)
    assert d.single_motor == 2 and d.familiarization_trials == 0
    assert d.seed == base.seed and d.hands == base.hands and d.hold_s == base.hold_s
    assert d.timeout_s == base.timeout_s and d.modalities == base.modalities
    # the same wrenches as the paper's draw, the first of each class
    full = {w.id: w for w in pf.draw_wrenches(base)}
    fulls = [w.wrench for w in full.values()]
    for w in pf.draw_wrenches(d):
        assert w.wrench in fulls
    path = tmp_path / "p.toml"
    path.write_text(sw.protocol_toml(d))
    assert pf.load_protocol(str(path)).config_hash == d.config_hash
    with pytest.raises(sw.SweepError, match="start error"):
        sw.derive_protocol(base, 20.0, 100.0, 4)


def test_point_source_tells_the_participant_the_point():
    pt = sw.Point(5.0, 60.0, ("threshold",))
    assert (
        sw.point_source("participant", pt, 0.5)
        == "participant:task_threshold_deg=5,task_hold_s=0.5,rate_hz=60"
    )
    assert (
        sw.point_source("participant:task_threshold_deg=3,weber_frac=0.3", pt, 0.5)
        == "participant:task_threshold_deg=3,weber_frac=0.3,task_hold_s=0.5,rate_hz=60"
    )
    assert sw.point_source("synthetic", pt, 0.5) == "synthetic"


def test_summarize_counts_failures_as_the_timeout():
    recs = [
        {"success": True, "completion_s": 10.0, "final_error_deg": 1.0, "poses": 5},
        {"success": True, "completion_s": 20.0, "final_error_deg": 1.0, "poses": 5},
        {"success": False, "completion_s": 90.0, "final_error_deg": 9.0, "poses": 5},
    ]
    s = sw.summarize(recs)
    assert s["successes"] == 2 and s["success_rate"] == pytest.approx(2 / 3, abs=1e-4)
    assert s["completion_median_s"] == 20.0
    assert s["completion_mean_s"] == 40.0
    assert s["completion_sd_s"] == pytest.approx(43.589, abs=1e-3)
    assert s["success_completion_median_s"] == 15.0


def test_register_adds_the_subcommand():
    parser = cli.build_parser()
    args = parser.parse_args(
        [
            "sweep",
            "--thresholds",
            "1,2",
            "--rates",
            "50",
            "--participants",
            "3",
            "--wrenches",
            "2",
            "--jobs",
            "1",
        ]
    )
    assert args.handler is sweep_command.run
    assert (args.thresholds, args.rates, args.participants, args.wrenches, args.jobs) == (
        "1,2",
        "50",
        3,
        2,
        1,
    )
