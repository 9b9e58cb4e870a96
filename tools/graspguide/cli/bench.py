"""`graspguide bench`: the host benchmark (graspguide.bench.host_bench), or with
--target the instruction counts on a microcontroller (graspguide.bench.targets) or the
cycles of the per-frame layer on the ATmega328P (graspguide.bench.avr_target);
`graspguide bench agreement MODE`: the float core against the float64 reference on paper
scenes (graspguide.bench.float_agreement)."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

from graspguide.cli.common import int_arg, positive_float
from graspguide.exit_codes import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, fail, report

HELP = (
    "host benchmark: full frame and QP alone vs DAQP, quadprog, OSQP, "
    "scipy, with accuracy against the float64 reference; --target: "
    "instruction counts on Cortex-M4F/M7 under QEMU, per-frame cycles on the "
    "ATmega328P under simavr"
)
DESCRIPTION = (
    "Time this project's full frame (in C++ and per Python call) and its QP "
    "alone next to DAQP, quadprog, OSQP and scipy on the same instances, "
    "judge every answer against the float64 reference, print a table. "
    "Columns: tools/README.md, 'graspguide bench'. "
    "With --target m4f or m7: build the stage-count image, run it under QEMU "
    "(-icount), print the instructions of every stage over the scene set and "
    "compare them with the regression baseline; exit 1 when a median or "
    "maximum grew more than 10 % or a status differs from the float64 reference. "
    "With --target avr: the per-frame layer's cycles on the ATmega328P at 8 MHz "
    "under simavr (frame, trial, watchdog), its flash and RAM, against "
    "tools/perf/avr_baseline.json. "
    "`graspguide bench agreement MODE`: does the float core give the float64 reference's "
    "constraint model and PWM (within 1 count) on paper scenes, on the host or on the "
    "Cortex-M4F under QEMU (`graspguide bench agreement --help`)."
)
RAW_DESCRIPTION = False

TARGET_CHOICES = ("m4f", "m7", "m7d", "avr")
# Options of one mode only: their dest, and the flag a message names.
HOST_ONLY = {
    "instances": "--instances",
    "seed": "--seed",
    "k": "--k",
    "quick": "--quick",
    "solvers": "--solvers",
    "max_passes": "--max-passes",
    "accuracy_scenes": "--accuracy-scenes",
}
TARGET_ONLY = {
    "no_build": "--no-build",
    "update_baseline": "--update-baseline",
    "baseline": "--baseline",
    "raw": "--raw",
    "qemu_timeout": "--qemu-timeout",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--instances",
        type=int,
        default=None,
        metavar="N",
        help="random hands per k, 0..100000 (default 200, --quick 20); each runs "
        "with the paper and the normal model, next to the paper's hand scenes",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=1,
        metavar="S",
        help="seed of the random hands, >= 0 (default 1)",
    )
    p.add_argument(
        "--k", choices=("3", "4", "both"), default="both", help="contact counts (default both)"
    )
    p.add_argument(
        "--quick", action="store_true", help="fewer instances, repetitions and passes (a smoke run)"
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        default=None,
        help="also write the full report (every figure, every failure) as JSON",
    )
    p.add_argument(
        "--solvers",
        default="daqp,quadprog,osqp,scipy-slsqp",
        metavar="LIST",
        help="peer solvers, comma-separated (default: daqp,quadprog,osqp,scipy-slsqp)",
    )
    p.add_argument(
        "--max-passes",
        type=int,
        default=None,
        metavar="N",
        help="cap on the passes of a noisy series, >= 1 (default 8, --quick 4)",
    )
    p.add_argument(
        "--accuracy-scenes",
        type=int,
        default=0,
        metavar="N",
        help="also judge every frame route (float/double, structured/svd) on N more "
        "random hands per k against the float64 reference, 0..100000 (default 0: the "
        "accuracy columns then rest on the timed instances only; the reference takes "
        "about 10 ms a scene)",
    )
    t = p.add_argument_group("microcontroller targets (--target)")
    t.add_argument(
        "--target",
        dest="targets",
        action="append",
        choices=TARGET_CHOICES,
        default=None,
        help="instead of the host benchmark, count instructions on this target under "
        "QEMU: m4f (Cortex-M4F, mps2-an386), m7 (Cortex-M7, mps2-an500), m7d (the same "
        "M7 with the core in double on its double FPU), or the per-frame "
        "layer's cycles on avr (ATmega328P at 8 MHz, simavr); repeatable. "
        '--json then writes {"cortex-m4f": {"k3": {STAGE: {"median", "max"}}, '
        '..., "pwm_vs_float64", "svd_pwm_vs_float64", "stack_bytes"}, '
        '"atmega328p": {"cycles": {PART: {"median", "max"}}, "flash_bytes", '
        '"ram_static_bytes", "stack_bytes", ...}}',
    )
    t.add_argument(
        "--no-build",
        action="store_true",
        help="run the images as they are (default: `pio run -e m4f_stages` etc. first, "
        "which rebuilds only what changed)",
    )
    t.add_argument(
        "--update-baseline",
        action="store_true",
        help="write the figures as the new regression baseline instead of comparing",
    )
    t.add_argument(
        "--baseline",
        metavar="FILE",
        default=None,
        help="the regression baseline (default: tools/perf/stage_baseline.json of the "
        "repository; --target avr's is tools/perf/avr_baseline.json)",
    )
    t.add_argument(
        "--raw", metavar="DIR", default=None, help="keep each target's raw output lines in DIR"
    )
    t.add_argument(
        "--qemu-timeout",
        type=positive_float,
        default=None,
        metavar="S",
        help="seconds QEMU may run one image before it is killed (default 300)",
    )
    _add_agreement(p)


AGREEMENT_DESCRIPTION = """\
Does the float core give the float64 reference's constraint model and PWM (within 1
count) on `paper` scenes: hand-like contacts (the nominal hand, each coordinate moved by
up to scene_generators.PERTURBATION_M), a unit force in a uniform direction, no moment,
k = 3 and 4, policies F and Fperp, mode C (seed 17; scene pNNNNNN is the NNNNNN-th of its
set); plus the hard hands of test/data/hard_hands.json. The test
tools/tests/core/test_float_paper_agreement.py checks the same scenes and band.

modes:
  reference  the float64 reference on the hard and --count random scenes, saved to --out
             (about 10 ms a scene and job)
  host       the float core this interpreter imports against a saved reference
  layered    the test's layered check (float and double cores on every scene, the
             reference where they differ) on --count scenes, no saved reference
  m4f        for each WORKTREE (made by `git worktree add`, never the main checkout: its
             stage_scenes.h is overwritten), the scenes in float with the reference's
             status and PWM, built with `pio run -e m4f_stages` and run on
             qemu-system-arm; agreement there is the status and PWM within 1 count"""

AGREEMENT_EPILOG = """\
examples:
  graspguide bench agreement reference --count 100000 --jobs 2 --out /tmp/float_ref.npz
  graspguide bench agreement host --reference /tmp/float_ref.npz
  graspguide bench agreement layered --count 1000000
  graspguide bench agreement m4f --count 1300 --retry-scenes /tmp/wt_after /tmp/wt_before

exit status: 0 measured, 1 a build, QEMU or file error, 2 a usage error."""


def _scene_name(text: str) -> str:
    """--scene: a random scene's name, p and at least 6 digits (p049778)."""
    if not re.fullmatch(r"p\d{6,}", text):
        raise argparse.ArgumentTypeError(f"want p followed by 6 digits, e.g. p049778; got {text!r}")
    return text


def _add_agreement(p: argparse.ArgumentParser) -> None:
    """`graspguide bench agreement MODE` (graspguide.bench.float_agreement)."""
    sub = p.add_subparsers(
        dest="measurement",
        metavar="[agreement MODE]",
        help="without one: the host benchmark, or --target's counts",
    )
    a = sub.add_parser(
        "agreement",
        help="the float core against the float64 reference on paper scenes (host or M4F)",
        description=AGREEMENT_DESCRIPTION,
        epilog=AGREEMENT_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    modes = a.add_subparsers(dest="agreement_mode", metavar="MODE", required=True)
    count = int_arg(0, 100_000_000)
    jobs = int_arg(1, 256)
    r = modes.add_parser("reference", help="save the float64 reference's answers")
    r.add_argument(
        "--count", type=count, default=100_000, metavar="N", help="random scenes (default 100000)"
    )
    r.add_argument("--jobs", type=jobs, default=1, metavar="N", help="processes (default 1)")
    r.add_argument("--out", dest="reference_out", required=True, metavar="FILE.npz")
    h = modes.add_parser("host", help="the imported float core against a saved reference")
    h.add_argument("--reference", dest="reference_in", required=True, metavar="FILE.npz")
    h.add_argument(
        "--json",
        dest="agreement_json",
        default=None,
        metavar="FILE",
        help="also write the figures and every disagreement",
    )
    lay = modes.add_parser("layered", help="the test's layered check on --count scenes")
    lay.add_argument(
        "--count",
        type=count,
        default=1_000_000,
        metavar="N",
        help="random scenes (default 1000000)",
    )
    m = modes.add_parser("m4f", help="the M4F image of each worktree under QEMU")
    m.add_argument(
        "--count", type=count, default=1300, metavar="N", help="random scenes (default 1300)"
    )
    m.add_argument(
        "--jobs", type=jobs, default=2, metavar="N", help="reference processes (default 2)"
    )
    m.add_argument(
        "--scene",
        dest="scene_names",
        type=_scene_name,
        action="append",
        default=[],
        metavar="NAME",
        help="also run this random scene (e.g. p049778), whatever --count; repeatable",
    )
    m.add_argument(
        "--scene-set",
        type=count,
        default=100_000,
        metavar="N",
        help="the size of the set the --scene names come from (100000: the test's; "
        "1000000: `layered`'s default)",
    )
    m.add_argument(
        "--large-set-scenes",
        action="store_true",
        help="also run the hands found on larger sets (large_set in the hard hands)",
    )
    m.add_argument(
        "--retry-scenes",
        action="store_true",
        help="also run the hands the float core retries in double (retry in the hard hands)",
    )
    m.add_argument("worktrees", nargs="+", metavar="WORKTREE")


def _misplaced(args: argparse.Namespace, options: dict[str, str]) -> list[str]:
    parser = args.command_parser
    return [
        flag for dest, flag in options.items() if getattr(args, dest) != parser.get_default(dest)
    ]


def run(args: argparse.Namespace) -> int:
    if args.measurement == "agreement":
        wrong = _misplaced(
            args, {**HOST_ONLY, **TARGET_ONLY, "targets": "--target", "json": "--json"}
        )
        if wrong:
            report("bench", f"{', '.join(wrong)}: not for `bench agreement`")
            return EXIT_USAGE
        return run_agreement(args)
    if args.targets:
        wrong = _misplaced(args, HOST_ONLY)
        if wrong:
            report("bench", f"{', '.join(wrong)}: host benchmark options, not for --target")
            return EXIT_USAGE
        return run_targets(args)
    wrong = _misplaced(args, TARGET_ONLY)
    if wrong:
        report("bench", f"{', '.join(wrong)}: only with --target")
        return EXIT_USAGE
    # graspguide.bench (numpy, the peer solvers) is imported when the command runs, so
    # the other commands do not pay for it at start-up.
    from graspguide.bench import host_bench

    return host_bench.bench_command(
        instances=args.instances,
        seed=args.seed,
        k=args.k,
        quick=args.quick,
        solvers=args.solvers,
        max_passes=args.max_passes,
        accuracy_scenes=args.accuracy_scenes,
        json_path=args.json,
    )


def run_agreement(args: argparse.Namespace) -> int:
    """`graspguide bench agreement MODE`: 0 when measured, 1 on a build, QEMU or file
    error."""
    from graspguide.bench import float_agreement as fa

    try:
        if args.agreement_mode == "reference":
            return fa.reference_command(count=args.count, jobs=args.jobs, out=args.reference_out)
        if args.agreement_mode == "host":
            return fa.host_command(reference_path=args.reference_in, json_path=args.agreement_json)
        if args.agreement_mode == "layered":
            return fa.layered_command(count=args.count)
        return fa.m4f_command(
            worktrees=args.worktrees,
            count=args.count,
            jobs=args.jobs,
            scene_names=args.scene_names,
            scene_set_size=args.scene_set,
            with_large_set=args.large_set_scenes,
            with_retry=args.retry_scenes,
        )
    except (OSError, ValueError, RuntimeError, subprocess.SubprocessError) as e:
        return fail("bench", e)


def run_targets(args: argparse.Namespace) -> int:
    """`graspguide bench --target ...`: 0 when every figure is within the baseline (or
    the baseline was written), 1 on a regression, a status that differs from the float64
    reference, a missing baseline or a run that failed."""
    from graspguide.bench import targets
    from graspguide.repo_root import find_repo_root

    def progress(msg: str) -> None:
        print(f"bench: {msg}", file=sys.stderr, flush=True)

    root_dir = find_repo_root()
    if root_dir is None:
        report(
            "bench",
            "--target needs the GraspGuide repository (platformio.ini, lib/): run from it",
        )
        return EXIT_FAILURE
    root = Path(root_dir)
    chosen = [targets.TARGETS[n] for n in dict.fromkeys(args.targets) if n in targets.TARGETS]
    avr_results: dict = {}
    try:
        results = (
            targets.measure(
                root,
                chosen,
                build_first=not args.no_build,
                qemu_timeout_s=args.qemu_timeout or targets.QEMU_TIMEOUT_S,
                raw_dir=Path(args.raw) if args.raw else None,
                progress=progress,
            )
            if chosen
            else {}
        )
        if "avr" in args.targets:
            from graspguide.bench import avr_target

            avr_results = avr_target.measure(
                root,
                build_first=not args.no_build,
                raw_dir=Path(args.raw) if args.raw else None,
                progress=progress,
            )
    except targets.TargetError as e:
        return fail("bench", e)
    if results:
        print(targets.format_table(results), flush=True)
    if avr_results:
        print(avr_target.format_table(avr_results), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({**results, **avr_results}, indent=2) + "\n")
        progress(f"wrote {args.json}")
    failed = False
    try:
        if results:
            baseline = Path(args.baseline) if args.baseline else root / targets.BASELINE
            if args.update_baseline:
                targets.write_baseline(baseline, results)
                print(f"baseline written: {baseline}")
            result = targets.check(results, targets.load_baseline(baseline))
            print("\n".join(result.lines()), flush=True)
            failed = result.failed
        if avr_results:
            avr_baseline = Path(args.baseline) if args.baseline and not chosen else None
            avr_baseline = avr_baseline or root / avr_target.BASELINE
            if args.update_baseline:
                avr_target.write_baseline(avr_baseline, avr_results)
                print(f"baseline written: {avr_baseline}")
            avr_failed, lines = avr_target.check(
                avr_results, avr_target.load_baseline(avr_baseline)
            )
            print("\n".join(lines), flush=True)
            failed = failed or avr_failed
    except targets.TargetError as e:
        return fail("bench", e)
    return EXIT_FAILURE if failed else EXIT_OK
