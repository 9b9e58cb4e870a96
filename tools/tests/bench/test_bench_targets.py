"""graspguide bench --target: the parser of the stage-count harness's output, the summary,
the baseline rule and the command's errors, on synthetic harness output (a fake QEMU
prints it). The real run under QEMU is a case of tools/run-tests.sh."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from graspguide.bench import targets

TICK = targets.INSTRUCTIONS_PER_TICK
# Today's harness columns; the stages among them are read off this line.
COLUMNS = (
    "name k status ref_status pwm0 pwm1 pwm2 pwm3 ref0 ref1 ref2 ref3 frames grasp qp "
    "full_cold full_warm fixed svd_status svd0 svd1 svd2 svd3"
).split()
STAGES = ["frames", "grasp", "qp", "full_cold", "full_warm", "fixed"]


def scene(
    name,
    k,
    ticks,
    status="ok",
    ref_status="ok",
    pwm=(10, 20, 30, 0),
    ref=None,
    svd=None,
    svd_status=None,
):
    """One scene as a dict keyed by column name; ``ticks`` for every stage. The SVD
    route answers as the structured one unless ``svd``/``svd_status`` say otherwise."""
    row = {"name": name, "k": k, "status": status, "ref_status": ref_status}
    ref = pwm if ref is None else ref
    svd = pwm if svd is None else svd
    for i in range(4):
        row[f"pwm{i}"], row[f"ref{i}"], row[f"svd{i}"] = pwm[i], ref[i], svd[i]
    row["svd_status"] = status if svd_status is None else svd_status
    row.update(ticks)
    return row


def harness_lines(
    rows, columns=COLUMNS, stack=1500, end=True, cal=(0, 5000, 15000), scalar="float"
):
    # SCALAR goes last of the header lines' kind the parser reads anywhere: the scene
    # lines keep their line numbers (3, 4, ...) in the messages tested below.
    lines = ["CAL " + " ".join(map(str, cal)), "COLUMNS " + " ".join(columns)]
    lines += ["S " + " ".join(str(r[c]) for c in columns) for r in rows]
    lines.append(f"SCALAR {scalar}")
    lines.append(f"STACK {stack}")
    if end:
        lines.append(f"END {len(rows)}")
    return lines


def uniform(value, stages=STAGES):
    return {s: value for s in stages}


ROWS = [
    scene("a3", 3, uniform(10)),
    scene("b3", 3, uniform(20)),
    scene("c3", 3, uniform(60)),
    # Refused by both, its later stages did not run: not in the figures.
    scene("d3", 3, {**uniform(-1), "frames": 999}, "zero_force", "zero_force", (0, 0, 0, 0)),
    scene("a4", 4, uniform(30), pwm=(5, 6, 7, 8), ref=(5, 6, 8, 8)),
    scene("b4", 4, uniform(50), pwm=(5, 6, 7, 8), ref=(5, 9, 7, 8)),
    # The float core's documented refusal of a hand float64 still solves.
    scene("e4", 4, uniform(-1), "imprecise_contacts", "ok", (0, 0, 0, 0), (1, 2, 3, 4)),
]


# --------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------
def test_values_are_read_by_column_name_and_the_stages_come_from_columns():
    # The harness may reorder, drop and add stage columns: the parser follows COLUMNS.
    columns = [c for c in COLUMNS if c not in ("full_warm", "svd0", "svd1", "svd2", "svd3")]
    columns = columns[:4] + ["full_structured"] + list(reversed(columns[4:]))
    rows = [{**r, "full_structured": 7} for r in ROWS]
    run = targets.parse(harness_lines(rows, columns))
    assert run.stages == [c for c in columns if c in STAGES or c == "full_structured"]
    assert "svd_status" not in run.stages and "pwm0" not in run.stages
    assert [r.name for r in run.rows] == [r["name"] for r in ROWS]
    for parsed, row in zip(run.rows, rows):
        assert parsed.k == row["k"] and parsed.status == row["status"]
        assert parsed.ref_status == row["ref_status"]
        assert parsed.pwm == tuple(row[f"pwm{i}"] for i in range(4))
        assert parsed.ref == tuple(row[f"ref{i}"] for i in range(4))
        assert parsed.ticks == {s: row[s] for s in run.stages}
    assert run.stack_bytes == 1500


def test_lines_that_are_not_the_harness_are_skipped():
    lines = harness_lines(ROWS)
    lines.insert(0, "qemu-system-arm: warning: something about the board")
    lines.insert(3, "")
    assert len(targets.parse(lines).rows) == len(ROWS)


def test_a_halt_line_is_a_typed_error_with_its_reason_and_the_last_scene():
    lines = harness_lines(ROWS[:2], end=False)[:-1] + ["HALT 3 17"]
    with pytest.raises(targets.TargetHalted, match="after scene b3: HALT 3 17"):
        targets.parse(lines)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda ls: ls[:-1], "without its END line, the last scene e4"),
        (lambda ls: ls[:-1] + ["END 99"], f"END says 99 scenes, the output has {len(ROWS)}"),
        (lambda ls: [ls[0]] + ls[2:], "a scene line before the COLUMNS line"),
        (lambda ls: [x for x in ls if not x.startswith("STACK")], "END before the STACK line"),
        (lambda ls: [x for x in ls if not x.startswith("SCALAR")], "END before the SCALAR line"),
        (
            lambda ls: [x.replace("SCALAR float", "SCALAR half") for x in ls],
            "SCALAR is 'half', not one of",
        ),
        (
            lambda ls: [ls[0], ls[1].replace(" svd3", "")] + ls[2:],
            "per-motor columns differ in count: 4 pwm, 4 ref, 3 svd",
        ),
        (lambda ls: ls[1:], "END before the CAL line"),
        (lambda ls: ls[:2] + [ls[2] + " 5"] + ls[3:], "line 3: 24 values for 23 columns"),
        (lambda ls: ls[:2] + [ls[2].replace(" 10 ", " ten ", 1)] + ls[3:], "line 3: "),
        (lambda ls: [ls[0], ls[1].replace(" fixed", "")] + ls[2:], "COLUMNS lacks fixed"),
        (
            lambda ls: [ls[0], ls[1].replace(" ref0", " rf0")] + ls[2:],
            "needs ref0, .* it has: ref1 ref2 ref3",
        ),
        (lambda ls: ["CAL 0 5000 17000"] + ls[1:], "expected 40 .*-icount shift=0"),
    ],
)
def test_malformed_output_is_a_clear_error(edit, message):
    with pytest.raises(targets.BadOutput, match=message):
        targets.parse(edit(harness_lines(ROWS)))


def test_a_value_that_is_not_an_integer_names_its_column_and_scene():
    rows = [dict(ROWS[0], qp="1.5")]
    with pytest.raises(targets.BadOutput, match="line 3: qp of scene a3 is '1.5'"):
        targets.parse(harness_lines(rows))


# --------------------------------------------------------------------------------------
# Summary and its JSON
# --------------------------------------------------------------------------------------
def test_summary_counts_accepted_scenes_only_and_agreement_with_the_reference():
    s = targets.summarize(targets.parse(harness_lines(ROWS)))
    assert s["scenes"] == len(ROWS) and s["stack_bytes"] == 1500 and s["stages"] == STAGES
    assert s["k3"]["scenes"] == 4 and s["k3"]["accepted"] == 3
    assert s["k4"]["scenes"] == 3 and s["k4"]["accepted"] == 2
    for k, ticks in (("k3", [10, 20, 60]), ("k4", [30, 50])):
        for stage in STAGES:  # d3's frames (999) and e4's -1 are not accepted scenes
            mid = sorted(ticks)[len(ticks) // 2] if len(ticks) % 2 else sum(ticks) / 2
            assert s[k][stage] == {"median": mid * TICK, "max": max(ticks) * TICK, "n": len(ticks)}
    assert s["k3"]["slowest_scene"] == "c3" and s["k4"]["slowest_scene"] == "b4"
    # a3, b3, c3 exact; a4 differs by 1 count, b4 by 3.
    assert s["pwm_vs_float64"] == {
        "compared": 5,
        "exact": 3,
        "within_1": 4,
        "within_1_share": 4 / 5,
        "max_diff": 3,
        "input_rounded": 0,
    }
    st = s["status_vs_float64"]
    assert (st["same"], st["float_only_refusals"], st["different"]) == (6, 1, 0)
    assert s["scalar"] == "float"
    # The fixture's SVD route answers as the structured one: the same figures.
    assert s["svd_pwm_vs_float64"] == s["pwm_vs_float64"]
    assert s["svd_status_vs_float64"] == st


def test_the_svd_route_is_judged_on_its_own_columns():
    rows = [
        scene("a3", 3, uniform(10), pwm=(5, 6, 7, 0), svd=(5, 6, 9, 0)),
        scene("b3", 3, uniform(10), pwm=(5, 6, 7, 0)),
        scene("c4", 4, uniform(10), svd_status="rank_deficient"),
    ]
    s = targets.summarize(targets.parse(harness_lines(rows, scalar="double")))
    assert s["scalar"] == "double"
    assert (s["pwm_vs_float64"]["within_1"], s["pwm_vs_float64"]["compared"]) == (3, 3)
    p = s["svd_pwm_vs_float64"]
    assert (p["within_1"], p["compared"], p["max_diff"]) == (1, 2, 2)
    assert s["svd_status_vs_float64"]["differences"] == ["c4: rank_deficient vs reference ok"]
    text = targets.format_table({"cortex-m7-double": s})
    assert "cortex-m7-double (double)" in text
    assert "double svd PWM vs float64 reference: 1/2 within 1 count (1 exact, max 2)" in text
    # A status the SVD route alone gets wrong fails the check like the structured one's.
    result = targets.check({"cortex-m7-double": s}, {})
    assert result.failed and result.status_failures == ["cortex-m7-double"]


def test_an_older_harness_without_svd_columns_has_no_svd_figures():
    columns = [c for c in COLUMNS if not c.startswith("svd")]
    s = targets.summarize(targets.parse(harness_lines(ROWS, columns)))
    assert "svd_pwm_vs_float64" not in s and "pwm_vs_float64" in s


def known_answers(path: Path, cases) -> Path:
    """A known_answers.json of (name, contacts) cases, as the harness's scenes' source."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"cases": [{"name": n, "contacts": c} for n, c in cases]}))
    return path


HAND = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.04], [-0.01, 0.1, 0.04]]


def test_scenes_whose_inputs_float_cannot_hold_are_left_out_of_the_pwm_comparison(tmp_path):
    far = [[1e6 + x for x in p] for p in HAND]  # float's spacing at 1e6 is 0.0625
    path = known_answers(
        tmp_path / "ka.json",
        [("a3", HAND), ("b3", far), ("c3", [[float("nan"), 0.0, 0.0]] + HAND[1:])],
    )
    rounded = targets.float_rounded_scenes(path)
    assert rounded == {"b3"}
    rows = [
        scene("a3", 3, uniform(10)),
        scene("b3", 3, uniform(10), pwm=(90, 0, 0, 0), ref=(10, 200, 30, 0)),
    ]
    s = targets.summarize(targets.parse(harness_lines(rows, scalar="double")), rounded)
    p = s["pwm_vs_float64"]
    assert (p["compared"], p["within_1"], p["input_rounded"]) == (1, 1, 1)
    assert s["status_vs_float64"]["same"] == 2  # its status is still compared
    assert "1 left out (inputs float cannot hold)" in targets.format_table({"t": s})
    # Without the rule the same run disagrees: the rule is what leaves b3 out.
    assert targets.summarize(targets.parse(harness_lines(rows)))["pwm_vs_float64"]["max_diff"]


@pytest.mark.parametrize(
    "content, message",
    [("{", "cannot read the scenes' float64 inputs"), ('{"cases": [{"name": "x"}]}', "contacts")],
)
def test_unreadable_known_answers_are_a_clear_error(tmp_path, content, message):
    path = tmp_path / "ka.json"
    path.write_text(content)
    with pytest.raises(targets.TargetError, match=message):
        targets.float_rounded_scenes(path)


def test_a_status_other_than_the_documented_refusal_is_a_failure():
    rows = ROWS + [scene("f4", 4, uniform(-1), "qp_iteration_limit", "ok", (0, 0, 0, 0))]
    results = {"cortex-m4f": targets.summarize(targets.parse(harness_lines(rows)))}
    assert results["cortex-m4f"]["status_vs_float64"]["differences"] == [
        "f4: qp_iteration_limit vs reference ok"
    ]
    result = targets.check(results, {"cortex-m4f": targets.slim(results["cortex-m4f"])})
    assert result.failed and result.status_failures == ["cortex-m4f"]
    assert "FAIL cortex-m4f: statuses differ" in "\n".join(result.lines())


def test_a_stage_no_accepted_scene_reached_has_no_figures():
    rows = [scene("a3", 3, {**uniform(10), "qp": -1})]
    s = targets.summarize(targets.parse(harness_lines(rows)))
    assert s["k3"]["qp"] == {"median": None, "max": None, "n": 0}
    assert "qp" not in targets.slim(s)["k3"]
    assert "qp" in targets.format_table({"cortex-m4f": s})


def test_json_shape_of_measure(tmp_path, monkeypatch):
    # The documented shape: target -> k3|k4 -> stage -> median|max, plus the agreement
    # and the stack; written exactly as the command writes it.
    fake_qemu(tmp_path, monkeypatch, harness_lines(ROWS))
    root = fake_repo(tmp_path)
    results = targets.measure(root, [targets.TARGETS["m4f"]], build_first=False)
    data = json.loads(json.dumps(results))
    assert list(data) == ["cortex-m4f"]
    m4f = data["cortex-m4f"]
    for k in ("k3", "k4"):
        for stage in STAGES:
            assert set(m4f[k][stage]) == {"median", "max", "n"}
            assert isinstance(m4f[k][stage]["median"], int)
    for route in ("pwm_vs_float64", "svd_pwm_vs_float64"):
        assert {"compared", "exact", "within_1", "within_1_share", "max_diff"} <= set(m4f[route])
    assert m4f["stack_bytes"] == 1500


# --------------------------------------------------------------------------------------
# The baseline rule
# --------------------------------------------------------------------------------------
def base(stage_figures):
    return {"cortex-m4f": {"k4": stage_figures}}


def test_more_than_ten_percent_growth_fails_and_ten_percent_does_not():
    b = base({"qp": {"median": 10_000, "max": 20_000}})
    at_limit = base({"qp": {"median": 11_000, "max": 22_000}})
    assert targets.compare(at_limit, b) == []
    over = base({"qp": {"median": 11_040, "max": 20_000}})
    (f,) = targets.compare(over, b)
    assert f.kind == "grown" and f.where == "cortex-m4f k4 qp median"
    assert "REGRESSION cortex-m4f k4 qp median: 11040 instructions, baseline 10000 (+10.4 %)" in (
        str(f)
    )


def test_one_tick_more_is_the_counters_resolution_not_growth():
    b = base({"grasp": {"median": 5 * TICK, "max": 5 * TICK}})
    assert targets.compare(base({"grasp": {"median": 6 * TICK, "max": 6 * TICK}}), b) == []
    grown = targets.compare(base({"grasp": {"median": 7 * TICK, "max": 5 * TICK}}), b)
    assert [f.where for f in grown] == ["cortex-m4f k4 grasp median"]


def test_new_and_gone_stages_are_reported_not_failed():
    b = base({"full_svd": {"median": 30_000, "max": 40_000}, "qp": {"median": 100, "max": 200}})
    cur = base(
        {"full_structured": {"median": 3_000, "max": 4_000}, "qp": {"median": 80, "max": 90}}
    )
    found = targets.compare(cur, b)
    assert sorted((f.kind, f.where) for f in found) == [
        ("gone", "cortex-m4f k4 full_svd max"),
        ("gone", "cortex-m4f k4 full_svd median"),
        ("new", "cortex-m4f k4 full_structured max"),
        ("new", "cortex-m4f k4 full_structured median"),
    ]
    assert not targets.Check(found, []).failed
    # A target with no baseline at all is one line, not one per figure.
    (f,) = targets.compare({"cortex-m7": cur["cortex-m4f"]}, b)
    assert f.kind == "new" and "cortex-m7" in str(f) and "--update-baseline" in str(f)


def test_baseline_is_written_per_target_and_read_back(tmp_path):
    path = tmp_path / "perf" / "baseline.json"
    m7 = {"k3": {"fixed": {"median": 400, "max": 440}}}
    path.parent.mkdir()
    path.write_text(json.dumps({"cortex-m7": m7}))
    s = targets.summarize(targets.parse(harness_lines(ROWS)))
    targets.write_baseline(path, {"cortex-m4f": s})
    data = targets.load_baseline(path)
    assert data["cortex-m7"] == m7  # the target not measured keeps its figures
    assert data["cortex-m4f"] == targets.slim(s)
    assert not targets.check({"cortex-m4f": s}, data).failed


@pytest.mark.parametrize(
    "content, message",
    [
        ("[1, 2]", "not a JSON object of targets"),
        ('{"cortex-m4f": {"k3": {"qp": {"median": 1}}}}', "cortex-m4f k3 qp is not"),
        ('{"cortex-m4f": {"k3": 5}}', "cortex-m4f k3 is not"),
        ("{", "cannot read the baseline"),
    ],
)
def test_a_bad_baseline_names_the_field(tmp_path, content, message):
    path = tmp_path / "b.json"
    path.write_text(content)
    with pytest.raises(targets.BadBaseline, match=message):
        targets.load_baseline(path)
    with pytest.raises(targets.BadBaseline, match="write it with --update-baseline"):
        targets.load_baseline(tmp_path / "none.json")


# --------------------------------------------------------------------------------------
# Running QEMU (a fake one) and the command
# --------------------------------------------------------------------------------------
def fake_repo(tmp_path: Path) -> Path:
    root = tmp_path / "repo"
    (root / "lib" / "graspguide_link").mkdir(parents=True)
    (root / "platformio.ini").write_text("")
    known_answers(root / targets.KNOWN_ANSWERS, [("a3", HAND)])
    for t in targets.TARGETS.values():
        elf = targets.image_path(root, t)
        elf.parent.mkdir(parents=True)
        elf.write_bytes(b"\x7fELF")
    return root


def fake_qemu(tmp_path, monkeypatch, lines, rc=0, sleep_s=0):
    """A qemu-system-arm first on PATH: prints ``lines`` on stderr, as semihosting does."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    (tmp_path / "out.txt").write_text("\n".join(lines) + "\n")
    qemu = bin_dir / "qemu-system-arm"
    # exec: a timeout kills QEMU itself; no child may keep its pipes open.
    body = f"exec sleep {sleep_s}" if sleep_s else f"cat '{tmp_path / 'out.txt'}' >&2\nexit {rc}"
    qemu.write_text(f"#!/bin/sh\n{body}\n")
    qemu.chmod(qemu.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    return bin_dir


def test_run_image_errors_say_what_to_do(tmp_path, monkeypatch):
    root = fake_repo(tmp_path)
    m4f = targets.TARGETS["m4f"]
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    with pytest.raises(targets.ToolMissing, match="run tools/install-arm.sh"):
        targets.run_image(root, m4f)
    with pytest.raises(targets.ToolMissing, match="arm-none-eabi-g\\+\\+ .*install-arm.sh"):
        targets.build(root, [m4f])
    targets.image_path(root, m4f).unlink()
    with pytest.raises(targets.ImageMissing, match="build it with `pio run -e m4f_stages`"):
        targets.run_image(root, m4f)


def test_qemu_that_hangs_is_killed_at_the_timeout(tmp_path, monkeypatch):
    fake_qemu(tmp_path, monkeypatch, harness_lines(ROWS), sleep_s=30)
    with pytest.raises(targets.QemuTimeout, match="over 1 s and was killed"):
        targets.run_image(fake_repo(tmp_path), targets.TARGETS["m4f"], timeout_s=1.0)


def test_a_trap_under_qemu_is_reported_with_its_halt_line(tmp_path, monkeypatch):
    fake_qemu(tmp_path, monkeypatch, harness_lines(ROWS[:1], end=False) + ["HALT 2 5"], rc=102)
    with pytest.raises(targets.TargetHalted, match="after scene a3: HALT 2 5"):
        targets.run_image(fake_repo(tmp_path), targets.TARGETS["m4f"])
    fake_qemu(tmp_path, monkeypatch, ["qemu-system-arm: could not load kernel"], rc=1)
    with pytest.raises(targets.TargetError, match="QEMU exited 1.*\n.*could not load kernel"):
        targets.run_image(fake_repo(tmp_path / "again"), targets.TARGETS["m4f"])


def graspguide(args, cwd):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return subprocess.run(
        [sys.executable, "-m", "graspguide", "bench", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_command_writes_json_and_fails_on_growth(tmp_path, monkeypatch):
    fake_qemu(tmp_path, monkeypatch, harness_lines(ROWS))
    root = fake_repo(tmp_path)
    out, baseline = tmp_path / "t.json", tmp_path / "base.json"
    args = ["--target", "m4f", "--no-build", "--baseline", str(baseline)]
    p = graspguide(args, root)
    assert p.returncode == 1 and "write it with --update-baseline" in p.stderr, p.stderr
    p = graspguide([*args, "--update-baseline"], root)
    assert p.returncode == 0, p.stderr
    assert "baseline check: ok" in p.stdout
    p = graspguide([*args, "--json", str(out)], root)
    assert p.returncode == 0, p.stderr
    assert json.loads(out.read_text())["cortex-m4f"]["k4"]["qp"]["max"] == 50 * TICK
    # The same image, slower by a fifth in one stage of one scene: a regression.
    data = json.loads(baseline.read_text())
    data["cortex-m4f"]["k4"]["qp"]["max"] = 40 * TICK
    baseline.write_text(json.dumps(data))
    p = graspguide(args, root)
    assert p.returncode == 1
    assert "REGRESSION cortex-m4f k4 qp max: 2000 instructions, baseline 1600" in p.stdout


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--target", "m4f", "--instances", "5"], "--instances: host benchmark options"),
        (["--target", "m7", "--quick", "--k", "3"], "--k, --quick: host benchmark options"),
        (["--update-baseline"], "--update-baseline: only with --target"),
        (["--no-build", "--raw", "d"], "--no-build, --raw: only with --target"),
        (["--target", "m3"], "invalid choice: 'm3'"),
        (["--target", "m4f", "--qemu-timeout", "0"], "must be in (0, 3600]"),
    ],
)
def test_options_of_the_other_mode_are_usage_errors(tmp_path, argv, words):
    p = graspguide(argv, tmp_path)
    assert p.returncode == 2, p.stderr
    assert words in p.stderr, p.stderr
