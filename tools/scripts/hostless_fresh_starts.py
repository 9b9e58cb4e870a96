"""Fresh starts of the host-less demo, one after another: each `graspguide demo --hostless`
into a new empty folder (a new simulated device and store per participant), optionally
with the host slowed at start (every fsync of each host process sleeps while that process
is young, as on a slow disk). Counts the runs that pass and says how each failed.

    python tools/scripts/hostless_fresh_starts.py --runs 20
    python tools/scripts/hostless_fresh_starts.py --runs 20 --slow-fsync-s 0.3
    python tools/scripts/hostless_fresh_starts.py --runs 20 --short   # 5 trials each
    python tools/scripts/hostless_fresh_starts.py --runs 20 --short --timeout-s 10 \
        --slow-fsync-s 0.3

--short runs protocols/paper.toml cut to its first trials (1 wrench, 3 contacts, one
familiarization trial: 5 trials per participant instead of 100; a full demo of 8 took
25 min on a loaded 2-core machine): every participant still starts a fresh simulated
device and store, which is where a slowed host used to fail.

The slowing is a sitecustomize.py on PYTHONPATH (a temporary folder), which every
`graspguide trial` the demo starts inherits. SIMULATED throughout.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time

SITECUSTOMIZE = textwrap.dedent(
    """
    # Written by tools/scripts/hostless_fresh_starts.py: a slow disk for a young process.
    import os as _os
    import time as _time

    _SLOW_S = float(_os.environ["HOSTLESS_FRESH_SLOW_FSYNC_S"])
    _FOR_S = float(_os.environ["HOSTLESS_FRESH_SLOW_FOR_S"])
    _BORN = _time.monotonic()
    _fsync = _os.fsync


    def _slow_fsync(fd):
        if _time.monotonic() - _BORN < _FOR_S:
            _time.sleep(_SLOW_S)
        return _fsync(fd)


    _os.fsync = _slow_fsync
    """
)


#: --short: protocols/paper.toml with these keys changed (key, new value).
SHORT_KEYS = (
    ("name", '"paper-first-trials"'),
    ("count", "1"),
    ("single_motor", "1"),
    ("contact_counts", "[3]"),
    ("trials", "1"),
)


def short_protocol(paper: str, path: str, timeout_s: float | None = None) -> None:
    """``paper`` (paper.toml) with SHORT_KEYS changed (and its timeout_s, when given),
    written to ``path``."""
    with open(paper, encoding="utf-8") as f:
        text = f.read()
    keys = list(SHORT_KEYS) + ([("timeout_s", repr(float(timeout_s)))] if timeout_s else [])
    for key, value in keys:
        text, n = re.subn(rf"^{key}\s*=\s*[^#\n]*", f"{key} = {value}  ", text, flags=re.M)
        if n != 1:
            raise SystemExit(f"--short: {paper} has {n} lines '{key} = ...', expected one")
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def trials_complete(out: str, protocol: str | None, participants: int) -> int:
    """How many of U1..U<participants> have every planned trial in OUT/PID/trials.jsonl
    (the host-less runs, whatever the analysis after them did)."""
    from graspguide.protocol import study_protocol as pf

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    loaded = pf.load_protocol(protocol or os.path.join(root, "protocols", "paper.toml"))
    complete = 0
    for i in range(1, participants + 1):
        pid = f"U{i}"
        try:
            with open(os.path.join(out, pid, "trials.jsonl"), encoding="utf-8") as f:
                done = {json.loads(line)["trial_index"] for line in f if line.strip()}
        except (OSError, ValueError, KeyError):
            continue
        if done >= {t.trial_index for t in pf.plan(loaded, pid)}:
            complete += 1
    return complete


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python tools/scripts/hostless_fresh_starts.py",
        description="Fresh starts of `graspguide demo --hostless`, counted.",
    )
    p.add_argument("--runs", type=int, default=20, help="fresh starts (default 20)")
    p.add_argument("--participants", type=int, default=8, help="per demo (default 8)")
    p.add_argument("--jobs", type=int, default=2, help="participants at a time (default 2)")
    p.add_argument("--protocol", help="study protocol (default: the demo's, paper.toml)")
    p.add_argument(
        "--short",
        action="store_true",
        help="protocols/paper.toml cut to 5 trials per participant (see above)",
    )
    p.add_argument(
        "--timeout-s",
        type=float,
        help="with --short: the trials' timeout [s] instead of the protocol's 90 s (a "
        "shorter run; the start, where a slowed host failed, is the same)",
    )
    p.add_argument(
        "--slow-fsync-s",
        type=float,
        default=0.0,
        help="every fsync sleeps this long while its process is young (default 0: not slowed)",
    )
    p.add_argument(
        "--slow-for-s",
        type=float,
        default=10.0,
        help="how long a process counts as young [s] (default 10)",
    )
    p.add_argument("--keep", action="store_true", help="keep each run's study folder")
    p.add_argument("--json", help="write the counts and each run's outcome to this file")
    args = p.parse_args(argv)

    env = dict(os.environ)
    site_dir = None
    if args.slow_fsync_s > 0:
        site_dir = tempfile.mkdtemp(prefix="hostless-fresh-site-")
        with open(os.path.join(site_dir, "sitecustomize.py"), "w") as f:
            f.write(SITECUSTOMIZE)
        env["PYTHONPATH"] = site_dir + os.pathsep + env.get("PYTHONPATH", "")
        env["HOSTLESS_FRESH_SLOW_FSYNC_S"] = str(args.slow_fsync_s)
        env["HOSTLESS_FRESH_SLOW_FOR_S"] = str(args.slow_for_s)
    runs = []
    protocol = args.protocol
    if args.short:
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        protocol = os.path.join(tempfile.mkdtemp(prefix="hostless-fresh-p-"), "first.toml")
        short_protocol(
            args.protocol or os.path.join(root, "protocols", "paper.toml"),
            protocol,
            args.timeout_s,
        )
    elif args.timeout_s:
        p.error("--timeout-s goes with --short")
    try:
        for n in range(1, args.runs + 1):
            out = tempfile.mkdtemp(prefix="hostless-fresh-")
            cmd = [sys.executable, "-m", "graspguide", "demo", "--hostless"]
            cmd += ["--participants", str(args.participants), "--jobs", str(args.jobs)]
            if protocol:
                cmd += ["--protocol", protocol]
            cmd += ["--out", out]
            t0 = time.monotonic()
            done = subprocess.run(cmd, env=env, capture_output=True, text=True)
            seconds = time.monotonic() - t0
            why = ""
            if done.returncode != 0:
                lines = [ln for ln in (done.stdout + done.stderr).splitlines() if ln.strip()]
                logs = os.path.join(out, "demo-logs")  # what stopped each participant
                for log in sorted(os.listdir(logs)) if os.path.isdir(logs) else []:
                    with open(os.path.join(logs, log), errors="replace") as f:
                        lines += [f"{log}: {ln}" for ln in f.read().splitlines() if "error" in ln]
                why = " | ".join(lines[-4:])
            complete = trials_complete(out, protocol, args.participants)
            runs.append(
                {
                    "run": n,
                    "exit": done.returncode,
                    "participants_complete": complete,
                    "seconds": round(seconds, 1),
                    "why": why,
                }
            )
            print(
                f"run {n}/{args.runs}: exit {done.returncode} in {seconds:.1f} s, "
                f"{complete} of {args.participants} participants' trials all stored"
                + (f": {why}" if why else ""),
                flush=True,
            )
            if args.keep or done.returncode != 0:
                print(f"  kept: {out}", flush=True)
            else:
                shutil.rmtree(out, ignore_errors=True)
    finally:
        if site_dir:
            shutil.rmtree(site_dir, ignore_errors=True)
    passed = sum(1 for r in runs if r["exit"] == 0)
    in_a_row = 0
    for r in runs:
        in_a_row = in_a_row + 1 if r["exit"] == 0 else 0
    trials_passed = sum(1 for r in runs if r["participants_complete"] == args.participants)
    slowed = (
        f"slowed ({args.slow_fsync_s:g} s per fsync in each process's first {args.slow_for_s:g} s)"
    )
    print(
        f"{passed} of {len(runs)} fresh starts passed (demo exit 0), {in_a_row} in a row at "
        f"the end; in {trials_passed} every participant's trials were all stored; "
        + (slowed if args.slow_fsync_s > 0 else "not slowed")
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "passed": passed,
                    "trials_passed": trials_passed,
                    "runs": runs,
                    "args": vars(args),
                },
                f,
                indent=1,
            )
    return 0 if passed == len(runs) else 1


if __name__ == "__main__":
    sys.exit(main())
