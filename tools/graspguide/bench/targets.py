"""Instruction counts of Algorithm 1 on Cortex-M4F and Cortex-M7 under QEMU
(``graspguide bench --target m4f|m7|m7d``: float on both, and double on the M7's double
FPU).

The stage-count images (src/harness/stage_counts/, ``pio run -e m4f_stages -e m7_stages
-e m7_stages_double``) run on qemu-system-arm with ``-icount shift=0`` (one instruction per
virtual nanosecond) and semihosting. The harness prints::

    CAL <empty> <ticks of 200,000 instructions> <ticks of 600,000 instructions>
    SCALAR float|double
    COLUMNS name k status ref_status pwm0 .. ref0 .. <stage> <stage> .. [svd_status svd0 ..]
    S <one scene, one value per column>
    STACK <bytes>
    END <scenes>

or ``HALT <reason> <code>`` when the image traps. Every value is read by its column's
name, and the stages are whatever columns the harness names besides the known ones, so
the harness can add or drop stages without a change here. Stage values are SysTick ticks
(25 MHz against the 1 GHz virtual clock: 40 instructions), -1 where a scene did not
reach the stage. ``svd_status`` and ``svd0``.. are the SVD reference route's answer on the
same scene, judged against the reference like the structured route's.

Counts are deterministic, so the regression baseline (tools/perf/stage_baseline.json) is
compared exactly: a median or maximum more than 10 % and more than one tick above it is a
regression.
"""

from __future__ import annotations

import json
import re
import shutil
import statistics
import subprocess
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from graspguide.bench import baseline_file
from graspguide.bench.pio_build import pio_env, pio_executable, run_build


@dataclass(frozen=True)
class Target:
    name: str  # the --target choice
    key: str  # the JSON's and the baseline's top-level key
    env: str  # PlatformIO environment of the stage-count image
    machine: str  # QEMU board with that CPU


TARGETS = {
    t.name: t
    for t in (
        Target("m4f", "cortex-m4f", "m4f_stages", "mps2-an386"),
        Target("m7", "cortex-m7", "m7_stages", "mps2-an500"),
        Target("m7d", "cortex-m7-double", "m7_stages_double", "mps2-an500"),
    )
}
BASELINE = Path("tools", "perf", "stage_baseline.json")  # relative to the repository
TOLERANCE = 0.10
INSTRUCTIONS_PER_TICK = 40  # 1 GHz virtual clock (-icount shift=0) / 25 MHz SysTick
# The calibration loops: 2 instructions an iteration, 100,000 and 300,000 iterations.
CALIBRATION_INSTRUCTIONS = 400_000
# The float core refuses these far-offset hands as imprecise where float64 still solves
# them (docs/algorithm.md): a documented refusal, not a disagreement.
FLOAT_ONLY_REFUSALS = frozenset({"imprecise_contacts"})
# The harness's scene table stores every input in float; the reference solved the float64
# inputs of test/data/known_answers.json. Where float's rounding moves a contact by more
# than this share of the hand's size (its farthest contact from the centroid), the target
# solved another hand, so its PWM is not compared (the 1e6 m offsets: 0.6; a hand near the
# origin: 1e-7).
KNOWN_ANSWERS = Path("test", "data", "known_answers.json")  # relative to the repository
INPUT_ROUNDING_MAX = 1e-4
SCALARS = ("float", "double")
# Columns every harness version prints; the stages are read off COLUMNS.
REQUIRED_COLUMNS = ("name", "k", "status", "ref_status", "full_cold", "fixed")
# A per-motor column is a word and a motor index (pwm0, ref3, svd1): outputs, not stages.
_PER_MOTOR = re.compile(r"([a-z]+)(\d)")
QEMU_TIMEOUT_S = 300.0  # a run takes well under a second; a hang must not stall the tests
BUILD_TIMEOUT_S = 1800.0  # a cold build of both images compiles the core twice


class TargetError(RuntimeError):
    """The target figures cannot be measured; the message says what to do."""


class ToolMissing(TargetError):
    """QEMU, the ARM compiler or PlatformIO is not installed."""


class ImageMissing(TargetError):
    """The stage-count image has not been built."""


class BuildFailed(TargetError):
    """``pio run`` failed or timed out."""


class QemuTimeout(TargetError):
    """QEMU did not finish in time (and was killed)."""


class TargetHalted(TargetError):
    """The image trapped: the harness printed ``HALT <reason> <code>``."""


class BadOutput(TargetError):
    """The harness's output is not what this parser reads (missing line, wrong field)."""


# --------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SceneRow:
    name: str
    k: int
    status: str
    ref_status: str
    pwm: tuple[int, ...]  # the target's PWM, structured route
    ref: tuple[int, ...]  # the float64 reference's
    ticks: dict[str, int]  # stage -> SysTick ticks, -1 where the stage did not run
    svd_status: str | None = None  # the SVD route's, when the harness prints it
    svd: tuple[int, ...] | None = None


@dataclass
class StageRun:
    stages: list[str]  # in the harness's column order
    rows: list[SceneRow] = field(default_factory=list)
    stack_bytes: int = 0
    empty_ticks: int = 0
    scalar: str = "float"  # the core's scalar in the image (its SCALAR line)


def stage_columns(columns: Sequence[str]) -> list[str]:
    """The stages among the harness's ``columns``: all but the scene's name and k, the
    statuses (``*status``) and the per-motor outputs (a word and a motor index)."""
    return [
        c
        for c in columns
        if c not in ("name", "k") and not c.endswith("status") and not _PER_MOTOR.fullmatch(c)
    ]


def _motor_columns(columns: Sequence[str], word: str) -> list[str]:
    """``word``0, ``word``1, ...: one column a motor, in motor order."""
    found = sorted(
        (int(m.group(2)), c)
        for c in columns
        if (m := _PER_MOTOR.fullmatch(c)) and m.group(1) == word
    )
    if not found or [i for i, _ in found] != list(range(len(found))):
        have = " ".join(c for _, c in found) or "none"
        raise BadOutput(f"COLUMNS needs {word}0, {word}1, ... one a motor; it has: {have}")
    return [c for _, c in found]


def _int(text: str, what: str, lineno: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise BadOutput(f"line {lineno}: {what} is {text!r}, not an integer") from None


def _check_calibration(fields: list[str], lineno: int) -> int:
    if len(fields) != 3:
        raise BadOutput(f"line {lineno}: CAL needs 3 values, got {len(fields)}")
    empty, loop_a, loop_b = (_int(v, "a CAL value", lineno) for v in fields)
    # The two loops' difference is free of the call's cost.
    per_tick = CALIBRATION_INSTRUCTIONS / (loop_b - loop_a) if loop_b > loop_a else 0.0
    if abs(per_tick - INSTRUCTIONS_PER_TICK) > 0.5:
        raise BadOutput(
            f"calibration: {per_tick:.2f} instructions per SysTick tick, expected "
            f"{INSTRUCTIONS_PER_TICK} (is QEMU run with -icount shift=0?)"
        )
    return empty


def _halted(reason_code: str, last_scene: str | None) -> TargetHalted:
    after = f" after scene {last_scene}" if last_scene else ""
    return TargetHalted(f"the image trapped{after}: HALT {reason_code} (reason, code)")


def _scene_row(
    v: dict[str, str], stages: list[str], cols: tuple[list[str], ...], lineno: int
) -> SceneRow:
    def ints(names: Sequence[str]) -> tuple[int, ...]:
        return tuple(_int(v[c], f"{c} of scene {v['name']}", lineno) for c in names)

    svd = len(cols) > 2
    return SceneRow(
        name=v["name"],
        k=_int(v["k"], f"k of scene {v['name']}", lineno),
        status=v["status"],
        ref_status=v["ref_status"],
        pwm=ints(cols[0]),
        ref=ints(cols[1]),
        ticks=dict(zip(stages, ints(stages))),
        svd_status=v["svd_status"] if svd else None,
        svd=ints(cols[2]) if svd else None,
    )


def parse(lines: Iterable[str]) -> StageRun:
    """Reads the harness's output (other lines, e.g. QEMU's warnings, are skipped).
    Raises TargetHalted on a HALT line, BadOutput when a line is missing or malformed."""
    columns: list[str] | None = None
    # The PWM columns: the target's, the reference's, and the SVD route's when printed.
    cols: tuple[list[str], ...] = ([], [])
    run: StageRun | None = None
    empty: int | None = None
    stack: int | None = None
    scalar: str | None = None
    lineno = 0
    for lineno, line in enumerate(lines, 1):
        tag, _, rest = line.strip().partition(" ")
        fields = rest.split()
        if tag == "HALT":
            raise _halted(rest, run.rows[-1].name if run and run.rows else None)
        if tag == "CAL":
            empty = _check_calibration(fields, lineno)
        elif tag == "SCALAR":
            if fields not in ([x] for x in SCALARS):
                raise BadOutput(f"line {lineno}: SCALAR is {rest!r}, not one of {SCALARS}")
            scalar = fields[0]
        elif tag == "COLUMNS":
            columns = fields
            missing = [c for c in REQUIRED_COLUMNS if c not in columns]
            if missing:
                raise BadOutput(f"line {lineno}: COLUMNS lacks {', '.join(missing)}")
            run = StageRun(stages=stage_columns(columns))
            cols = (_motor_columns(columns, "pwm"), _motor_columns(columns, "ref"))
            if "svd_status" in columns and "svd0" in columns:
                cols = (*cols, _motor_columns(columns, "svd"))
            if any(len(c) != len(cols[0]) for c in cols):
                counts = ", ".join(f"{len(c)} {c[0][:-1]}" for c in cols)
                raise BadOutput(f"line {lineno}: per-motor columns differ in count: {counts}")
        elif tag == "S":
            if columns is None or run is None:
                raise BadOutput(f"line {lineno}: a scene line before the COLUMNS line")
            if len(fields) != len(columns):
                raise BadOutput(
                    f"line {lineno}: {len(fields)} values for {len(columns)} columns "
                    f"(scene {fields[0] if fields else '?'})"
                )
            run.rows.append(_scene_row(dict(zip(columns, fields)), run.stages, cols, lineno))
        elif tag == "STACK":
            stack = _int(rest.strip(), "STACK", lineno)
        elif tag == "END":
            if run is None or empty is None or stack is None or scalar is None:
                what = (
                    "COLUMNS"
                    if run is None
                    else "CAL"
                    if empty is None
                    else "STACK"
                    if stack is None
                    else "SCALAR"
                )
                raise BadOutput(f"line {lineno}: END before the {what} line")
            scenes = _int(rest.strip(), "END", lineno)
            if scenes != len(run.rows):
                raise BadOutput(f"END says {scenes} scenes, the output has {len(run.rows)}")
            run.stack_bytes = stack
            run.empty_ticks = empty
            run.scalar = scalar
            return run
    last = f", the last scene {run.rows[-1].name}" if run and run.rows else ""
    raise BadOutput(f"the output ended after {lineno} lines without its END line{last}")


# --------------------------------------------------------------------------------------
# Summary and comparison
# --------------------------------------------------------------------------------------
def _stats(values: list[int]) -> dict[str, Any]:
    if not values:
        return {"median": None, "max": None, "n": 0}
    return {"median": int(statistics.median(values)), "max": max(values), "n": len(values)}


def _agreement(
    rows: Sequence[tuple[str, str, str, tuple[int, ...], tuple[int, ...]]],
    rounded: frozenset[str],
) -> tuple[dict[str, Any], dict[str, Any]]:
    """PWM and status of one route against the float64 reference. ``rows``: (scene,
    status, reference status, PWM, reference PWM); ``rounded``: the scenes whose inputs
    float cannot hold (:func:`float_rounded_scenes`), whose PWM is not compared."""
    compared = exact = within1 = left_out = 0
    worst = 0
    same = float_only = 0
    differences: list[str] = []
    for name, status, ref_status, pwm, ref in rows:
        if status == ref_status:
            same += 1
        elif status in FLOAT_ONLY_REFUSALS and ref_status == "ok":
            float_only += 1
        else:
            differences.append(f"{name}: {status} vs reference {ref_status}")
        if status == "ok" and ref_status == "ok":
            if name in rounded:
                left_out += 1
                continue
            d = max(abs(a - b) for a, b in zip(pwm, ref))
            compared += 1
            exact += d == 0
            within1 += d <= 1
            worst = max(worst, d)
    pwm_figures = {
        "compared": compared,
        "exact": exact,
        "within_1": within1,
        "within_1_share": within1 / compared if compared else None,
        "max_diff": worst if compared else None,
        "input_rounded": left_out,
    }
    status_figures = {
        "same": same,
        "float_only_refusals": float_only,
        "different": len(differences),
        "differences": differences,
    }
    return pwm_figures, status_figures


def float_rounded_scenes(known_answers: Path) -> frozenset[str]:
    """The scenes of ``known_answers`` (the harness's scene table's source) whose contacts
    float's rounding moves by more than INPUT_ROUNDING_MAX of the hand's size."""
    try:
        cases = json.loads(known_answers.read_text())["cases"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise TargetError(
            f"cannot read the scenes' float64 inputs from {known_answers}: {e}"
        ) from None
    out = set()
    for c in cases:
        try:
            contacts = np.asarray(c["contacts"], dtype=np.float64)
            name = str(c["name"])
        except (KeyError, TypeError, ValueError) as e:
            raise TargetError(f"{known_answers}: a case without usable contacts: {e}") from None
        if not np.all(np.isfinite(contacts)):
            continue  # a non-finite input is refused whatever the precision
        moved = np.max(np.abs(contacts.astype(np.float32).astype(np.float64) - contacts))
        size = np.max(np.linalg.norm(contacts - contacts.mean(axis=0), axis=1))
        if moved > INPUT_ROUNDING_MAX * size:
            out.add(name)
    return frozenset(out)


def summarize(run: StageRun, rounded: frozenset[str] = frozenset()) -> dict[str, Any]:
    """Per k: the median and maximum instructions of every stage over the scenes the
    target solved; the agreement of the target's PWM and status with the float64
    reference, for the structured route and (when the harness prints it) the SVD route,
    leaving the ``rounded`` scenes (:func:`float_rounded_scenes`) out of the PWM
    comparison; the stack high-water mark."""
    out: dict[str, Any] = {
        "scalar": run.scalar,
        "scenes": len(run.rows),
        "stack_bytes": run.stack_bytes,
        "stages": list(run.stages),
    }
    for k in sorted({r.k for r in run.rows}):
        ok = [r for r in run.rows if r.k == k and r.status == "ok"]
        per_k: dict[str, Any] = {"scenes": sum(r.k == k for r in run.rows), "accepted": len(ok)}
        for stage in run.stages:
            per_k[stage] = _stats(
                [r.ticks[stage] * INSTRUCTIONS_PER_TICK for r in ok if r.ticks[stage] >= 0]
            )
        per_k["slowest_scene"] = max(ok, key=lambda r: r.ticks["full_cold"]).name if ok else None
        out[f"k{k}"] = per_k
    out["pwm_vs_float64"], out["status_vs_float64"] = _agreement(
        [(r.name, r.status, r.ref_status, r.pwm, r.ref) for r in run.rows], rounded
    )
    if run.rows and all(r.svd is not None for r in run.rows):
        out["svd_pwm_vs_float64"], out["svd_status_vs_float64"] = _agreement(
            [(r.name, r.svd_status or "", r.ref_status, r.svd or (), r.ref) for r in run.rows],
            rounded,
        )
    return out


def _k_keys(summary: dict[str, Any]) -> list[str]:
    return [key for key in summary if re.fullmatch(r"k\d+", key)]


def slim(summary: dict[str, Any]) -> dict[str, dict[str, dict[str, int]]]:
    """The baseline's part of one target's summary: k -> stage -> median, max."""
    return {
        k: {
            s: {"median": summary[k][s]["median"], "max": summary[k][s]["max"]}
            for s in summary["stages"]
            if summary[k][s]["n"]
        }
        for k in _k_keys(summary)
    }


@dataclass(frozen=True)
class Finding:
    kind: str  # "grown" (a regression), "new" (no baseline yet), "gone" (not measured now)
    where: str  # "cortex-m4f k4 qp max"
    value: int | None
    baseline: int | None

    def __str__(self) -> str:
        if self.kind == "grown":
            assert self.value is not None and self.baseline is not None
            growth = (
                f"+{100 * (self.value / self.baseline - 1):.1f} %" if self.baseline else "from 0"
            )
            return (
                f"REGRESSION {self.where}: {self.value} instructions, "
                f"baseline {self.baseline} ({growth})"
            )
        if self.kind == "new":
            value = "" if self.value is None else f": {self.value} instructions"
            return f"new {self.where}{value}, no baseline yet (--update-baseline)"
        return f"gone {self.where}: baseline {self.baseline}, not measured now"


def grown(value: int, base: int) -> bool:
    """A stage's count is read off a SysTick that ticks every 40 instructions, at a phase
    any code change before it moves: one tick more is the counter's resolution, not
    growth (a 200-instruction stage is 5 ticks)."""
    return value > max(base * (1 + TOLERANCE), base + INSTRUCTIONS_PER_TICK)


def compare(current: dict[str, Any], baseline: dict[str, Any]) -> list[Finding]:
    """Every figure of ``current`` (target -> slim) against ``baseline`` (same shape).
    Only "grown" findings are failures; a stage with no baseline, or a baseline stage
    the harness no longer reports, is listed for the reader to confirm."""
    found: list[Finding] = []
    for target, cur in current.items():
        base = baseline.get(target)
        if base is None:
            found.append(Finding("new", target, None, None))
            continue
        for k in sorted(set(cur) | set(base)):
            for stage in sorted(set(cur.get(k, {})) | set(base.get(k, {}))):
                for stat in ("median", "max"):
                    c = cur.get(k, {}).get(stage, {}).get(stat)
                    b = base.get(k, {}).get(stage, {}).get(stat)
                    where = f"{target} {k} {stage} {stat}"
                    if b is None and c is not None:
                        found.append(Finding("new", where, c, None))
                    elif c is None and b is not None:
                        found.append(Finding("gone", where, None, b))
                    elif c is not None and b is not None and grown(c, b):
                        found.append(Finding("grown", where, c, b))
    return found


class BadBaseline(TargetError):
    """The baseline file is missing or not target -> k -> stage -> median, max."""


def load_baseline(path: Path) -> dict[str, Any]:
    return baseline_file.read(path, 3, BadBaseline, "baseline", "targets")


def write_baseline(path: Path, results: dict[str, dict[str, Any]]) -> None:
    """Writes the measured targets' figures into ``path``, keeping the other targets'."""
    data = load_baseline(path) if path.exists() else {}
    data.update({target: slim(summary) for target, summary in results.items()})
    baseline_file.write(path, data)


def format_table(results: dict[str, dict[str, Any]]) -> str:
    out: list[str] = []
    for target, r in results.items():
        ks = _k_keys(r)
        out.append(
            f"== {target} ({r['scalar']}): instructions per stage (median / max over accepted "
            f"scenes), {r['scenes']} scenes, stack high-water {r['stack_bytes']} B"
        )
        head = "".join(f"{'k=' + k[1:] + ' median':>12}{'k=' + k[1:] + ' max':>10}" for k in ks)
        out.append(f"{'stage':<15}{head}")
        for stage in r["stages"]:
            cells = "".join(
                f"{r[k][stage]['median']:>12,}{r[k][stage]['max']:>10,}"
                if r[k][stage]["n"]
                else f"{'-':>12}{'-':>10}"
                for k in ks
            )
            out.append(f"{stage:<15}{cells}")
        for route, prefix in (("structured", ""), ("svd", "svd_")):
            if f"{prefix}pwm_vs_float64" not in r:
                continue
            p, s = r[f"{prefix}pwm_vs_float64"], r[f"{prefix}status_vs_float64"]
            rounded = (
                f", {p['input_rounded']} left out (inputs float cannot hold)"
                if p["input_rounded"]
                else ""
            )
            out.append(
                f"{r['scalar']} {route} PWM vs float64 reference: {p['within_1']}/"
                f"{p['compared']} within 1 count ({p['exact']} exact, max "
                f"{'-' if p['max_diff'] is None else p['max_diff']}){rounded}; status: "
                f"{s['same']} same, {s['float_only_refusals']} float-only refusals, "
                f"{s['different']} different"
            )
            out.extend(f"  differs: {d}" for d in s["differences"])
    return "\n".join(out)


# --------------------------------------------------------------------------------------
# Building and running
# --------------------------------------------------------------------------------------
def image_path(root: Path, target: Target) -> Path:
    return root / ".pio" / "build" / target.env / "firmware.elf"


def build_command(targets: Sequence[Target]) -> str:
    return "pio run " + " ".join(f"-e {t.env}" for t in targets)


def build(
    root: Path,
    targets: Sequence[Target],
    timeout_s: float = BUILD_TIMEOUT_S,
    progress: Callable[[str], None] | None = None,
) -> None:
    """``pio run -e <env>`` for each target: pio rebuilds only what changed (about a
    second when nothing did), so the counts are always of the current sources."""
    if shutil.which("arm-none-eabi-g++") is None:
        raise ToolMissing("arm-none-eabi-g++ is not installed: run tools/install-arm.sh")
    pio = pio_executable(root, ToolMissing, ", or pass --no-build to run the images already built")
    cmd = [pio, "run"] + [a for t in targets for a in ("-e", t.env)]
    if progress:
        progress(f"building: {build_command(targets)}")
    run_build(cmd, root, build_command(targets), timeout_s, BuildFailed, pio_env(root))


def qemu_command(qemu: str, machine: str, elf: Path) -> list[str]:
    return [
        qemu,
        "-M",
        machine,
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        "-icount",
        "shift=0",
        "-kernel",
        str(elf),
    ]


def run_image(root: Path, target: Target, timeout_s: float = QEMU_TIMEOUT_S) -> list[str]:
    """The harness's output lines from one run of ``target``'s image under QEMU."""
    elf = image_path(root, target)
    if not elf.exists():
        raise ImageMissing(f"{elf} is missing: build it with `{build_command([target])}`")
    qemu = shutil.which("qemu-system-arm")
    if qemu is None:
        raise ToolMissing("qemu-system-arm is not installed: run tools/install-arm.sh")
    try:
        p = subprocess.run(
            qemu_command(qemu, target.machine, elf),
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        raise QemuTimeout(
            f"{target.key}: QEMU ran {elf} for over {timeout_s:.0f} s and was killed "
            "(a scene that never ends?)"
        ) from None
    # QEMU writes semihosting output (SYS_WRITE0) to its stderr.
    lines = p.stderr.splitlines()
    if p.returncode != 0:
        halt = [ln.split(" ", 1)[1] for ln in lines if ln.startswith("HALT ")]
        if halt:
            scenes = [ln.split()[1] for ln in lines if ln.startswith("S ") and len(ln.split()) > 1]
            raise _halted(halt[0], scenes[-1] if scenes else None)
        tail = "\n".join((lines + p.stdout.splitlines())[-5:])
        raise TargetError(f"{target.key}: QEMU exited {p.returncode} running {elf}:\n{tail}")
    return lines


def measure(
    root: Path,
    targets: Sequence[Target],
    *,
    build_first: bool = True,
    qemu_timeout_s: float = QEMU_TIMEOUT_S,
    raw_dir: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, dict[str, Any]]:
    """Builds (unless ``build_first`` is False), runs and summarises each target:
    target key -> summary."""
    if build_first:
        build(root, targets, progress=progress)
    rounded = float_rounded_scenes(root / KNOWN_ANSWERS)
    results: dict[str, dict[str, Any]] = {}
    for target in targets:
        if progress:
            progress(f"running {target.env} on QEMU {target.machine}")
        lines = run_image(root, target, qemu_timeout_s)
        if raw_dir is not None:
            raw_dir.mkdir(parents=True, exist_ok=True)
            (raw_dir / f"{target.key}.txt").write_text("\n".join(lines) + "\n")
        try:
            results[target.key] = summarize(parse(lines), rounded)
        except BadOutput as e:
            raise BadOutput(f"{target.key} ({image_path(root, target)}): {e}") from None
    return results


@dataclass
class Check:
    findings: list[Finding]
    status_failures: list[str]  # targets whose statuses (either route) differ from the reference

    @property
    def failed(self) -> bool:
        return self.status_failures != [] or any(f.kind == "grown" for f in self.findings)

    def lines(self) -> list[str]:
        out = [str(f) for f in self.findings]
        out += [
            f"FAIL {t}: statuses differ from the float64 reference (listed above)"
            for t in self.status_failures
        ]
        out.append(
            f"baseline check: {'FAILED' if self.failed else 'ok'} (tolerance "
            f"+{int(TOLERANCE * 100)} % per stage, at least one {INSTRUCTIONS_PER_TICK}-"
            "instruction tick, median and max)"
        )
        return out


def check(results: dict[str, dict[str, Any]], baseline: dict[str, Any]) -> Check:
    return Check(
        findings=compare({t: slim(r) for t, r in results.items()}, baseline),
        status_failures=[
            t
            for t, r in results.items()
            if r["status_vs_float64"]["different"]
            or r.get("svd_status_vs_float64", {}).get("different")
        ],
    )


__all__ = [
    "BASELINE",
    "TARGETS",
    "BadBaseline",
    "BadOutput",
    "BuildFailed",
    "Check",
    "Finding",
    "ImageMissing",
    "QemuTimeout",
    "StageRun",
    "Target",
    "TargetError",
    "TargetHalted",
    "ToolMissing",
    "build",
    "check",
    "float_rounded_scenes",
    "compare",
    "format_table",
    "load_baseline",
    "measure",
    "parse",
    "run_image",
    "slim",
    "summarize",
    "write_baseline",
]
