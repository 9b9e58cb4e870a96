"""`graspguide bench agreement`: the float core against the float64 reference on paper
scenes (graspguide.bench.float_agreement), and the hard hands it reads from test/data/."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from graspguide.bench import float_agreement as fa

CLI = [sys.executable, "-m", "graspguide", "bench", "agreement"]


def _env() -> dict:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def _run(*args: str, cwd: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*CLI, *args], capture_output=True, text=True, env=_env(), cwd=cwd, timeout=300
    )


def test_the_hard_hands_file_holds_three_named_lists():
    hard, large, retry = fa.hard_scenes(), fa.large_set_scenes(), fa.retry_scenes()
    assert (len(hard), len(large), len(retry)) == (8, 4, 6)
    for scene in hard + large + retry:
        assert len(scene["contacts"]) in (3, 4)
        assert len(scene["force"]) == 3
        assert scene["policy"] in fa.POLICIES
    for scene in large + retry:
        # Each names its place in the seeded set it was drawn from.
        assert 0 <= int(scene["name"][1:]) < scene["set"]
    names = [s["name"] for s in fa.scene_set(2)]
    assert names == [f"{fa.HARD_PREFIX}{i}" for i in range(8)] + ["p000000", "p000001"]


def test_a_scene_name_picks_that_scene_of_its_set():
    drawn = fa.random_paper_scenes(10)
    (third,) = fa.named_scenes(["p000003"], drawn_from=10)
    assert third == dict(drawn[3], name="p000003")
    with pytest.raises(ValueError, match="not in a set of 10"):
        fa.named_scenes(["p000010"], drawn_from=10)
    with pytest.raises(ValueError, match="expected p followed by 6 digits"):
        fa.named_scenes(["hard_0"], drawn_from=10)


def _harness_line(columns, **values) -> str:
    return "S " + " ".join(str(values.get(c, 0)) for c in columns)


def test_the_m4f_count_groups_hard_and_random_scenes_by_name():
    columns = ["name", "k", "status", "ref_status", "full_cold"]
    columns += [f"pwm{i}" for i in range(4)] + [f"ref{i}" for i in range(4)]
    pwm = {f"pwm{i}": 100 for i in range(3)} | {f"ref{i}": 100 for i in range(3)}
    lines = [
        "COLUMNS " + " ".join(columns),
        _harness_line(
            columns, name="hard_0", k=3, status="ok", ref_status="ok", full_cold=5, **pwm
        ),
        _harness_line(
            columns, name="p000000", k=3, status="ok", ref_status="ok", full_cold=7, **pwm
        ),
        # Two counts off: a disagreement.
        _harness_line(
            columns,
            name="p000001",
            k=3,
            status="ok",
            ref_status="ok",
            full_cold=9,
            **(pwm | {"pwm1": 102}),
        ),
        "STACK 1234",
    ]
    res = fa.m4f_agreement(lines, n_hard=1)
    assert res["hard"] == [1, 1]
    assert res["random"] == [1, 2]
    assert res["stack"] == 1234
    assert len(res["failed"]) == 1 and res["failed"][0].startswith("p000001")
    with pytest.raises(ValueError, match="1 of the 2 hard scenes"):
        fa.m4f_agreement(lines, n_hard=2)


def test_the_m4f_header_holds_every_scene_with_its_reference_answer():
    scenes = fa.scene_set(1)
    answers = [("ok", "paper", [70, 80, 90]) for _ in scenes]
    text = fa.render_header(scenes, answers)
    assert f"kStageSceneCount = {len(scenes)};" in text
    for s in scenes:
        assert f'{{"{s["name"]}", {len(s["contacts"])},' in text
    assert text.count('"ok", {70, 80, 90, 0}}') == len(scenes)


def test_reference_then_host_counts_the_agreement(tmp_path):
    ref = tmp_path / "ref.npz"
    proc = _run("reference", "--count", "4", "--out", str(ref))
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {ref}: 12 scenes" in proc.stdout
    out = tmp_path / "host.json"
    proc = _run("host", "--reference", str(ref), "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    res = json.loads(out.read_text())
    assert (res["hard_scenes"], res["random_scenes"]) == (8, 4)
    assert f"float agrees with float64 on {res['hard_agree']}/8" in proc.stdout
    assert res["hard_agree"] + res["random_agree"] == 12 - len(res["disagreements"])


def test_m4f_refuses_a_main_checkout_and_leaves_its_scenes_alone(tmp_path):
    (tmp_path / ".git").mkdir()
    dest = tmp_path / "src" / "harness" / "stage_counts" / "stage_scenes.h"
    dest.parent.mkdir(parents=True)
    dest.write_text("// the checked-in scenes\n")
    proc = _run("m4f", "--count", "0", "--jobs", "1", str(tmp_path))
    assert proc.returncode == 1, proc.stderr
    assert "is a main checkout" in proc.stderr
    assert dest.read_text() == "// the checked-in scenes\n"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--quick", "agreement", "layered"], "--quick: not for `bench agreement`"),
        (["--target", "m4f", "agreement", "layered"], "--target: not for `bench agreement`"),
        (["agreement"], "required: MODE"),
        (["agreement", "host"], "--reference"),
        (["agreement", "layered", "--count", "-1"], "must be between 0 and"),
        (["agreement", "m4f", "--scene", "hard_0", "wt"], "want p followed by 6 digits"),
    ],
)
def test_usage_errors_exit_2(args, message):
    proc = subprocess.run(
        [sys.executable, "-m", "graspguide", "bench", *args],
        capture_output=True,
        text=True,
        env=_env(),
        timeout=60,
    )
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr
