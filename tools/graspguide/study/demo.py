"""`graspguide demo`: the paper's user study end to end, SIMULATED.

One command runs the simulated device (virtual clock) and N virtual participants (U1..UN,
:class:`graspguide.participant.model.VirtualParticipant`) through a study protocol (default
``protocols/paper.toml``), then its analysis (:mod:`graspguide.analysis.study_analysis`): it
prints Tables I-II beside the paper's and every reading of the statistics and writes the figures,
the Markdown report and the CSV tables to ``OUT/analysis/``.

Each participant is one ``graspguide trial --port sim --source participant`` process
with its own simulated device; ``--jobs`` of them run at a time (default: the CPU
count). Their output goes to ``OUT/demo-logs/PID.log``.

``--hostless``: each participant runs host-less instead (``graspguide trial --hostless``,
graspguide.hostless.runner): the plan stored on the simulated device, the trials run by
the device from a simulated IMU and button, the log downloaded; default study folder
``logs/demo-hostless``.

Resume: the study folder ``OUT`` (default ``logs/demo-study`` in the repository) is the
runner's (docs/study.md): completed trials are fsync'ed to the participant's trial
records one line each, so killing the demo at any point and running the same command again completes
the study with every trial exactly once; a completed study run again is only analysed
again. Everything here is labelled SIMULATED: no human took part.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time

from graspguide.exit_codes import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, fail
from graspguide.records.files import ParticipantFiles
from graspguide.study.jobs import (
    TrialJob,
    count_lines,
    default_protocol,
    run_trial_jobs,
)
from graspguide.study.jobs import (
    default_out as _default_out,
)


def default_out(hostless: bool = False) -> str:
    return _default_out("demo-hostless" if hostless else "demo-study")


@dataclasses.dataclass
class HostlessTrialJob(TrialJob):
    """A participant's `graspguide trial --hostless` (its device store in its folder)."""

    def command(self) -> list[str]:
        return [*super().command(), "--hostless"]


def _status(protocol, out: str, pid: str) -> tuple[int, int, bool]:
    """(completed trials, planned trials, complete incl. TLX) of a participant."""
    from graspguide.protocol.study_protocol import plan, session_order
    from graspguide.records.storage import read_jsonl

    planned = len(plan(protocol, pid))
    files = ParticipantFiles.of(out, pid)
    try:
        done = {r.get("trial_index") for r in read_jsonl(files.trials).records}
        tlx = {r.get("session") for r in read_jsonl(files.tlx).records}
    except Exception:
        return 0, planned, False  # let the runner report what is wrong
    sessions = {s.session for s in session_order(protocol, pid)}
    return len(done), planned, len(done) >= planned and sessions <= tlx


def run(
    *,
    participants: int,
    protocol: str | None = None,
    out: str | None = None,
    jobs: int | None = None,
    source: str = "participant",
    hostless: bool = False,
) -> int:
    """`graspguide demo`: ``participants`` virtual participants through ``protocol``
    (default protocols/paper.toml) into the study folder ``out`` (default
    logs/demo-study, logs/demo-hostless with ``hostless``), ``jobs`` at a time (default
    the CPU count), host-less on the simulated device with ``hostless``, then the
    analysis. Returns the exit code."""
    from graspguide.protocol.study_protocol import ProtocolFileError, load_protocol
    from graspguide.run_errors import RunnerError
    from graspguide.sources.trial_sources import open_runner_source

    t0 = time.monotonic()
    protocol_path = protocol or default_protocol()
    out = out or default_out(hostless)
    jobs = jobs or os.cpu_count() or 1
    try:
        loaded = load_protocol(protocol_path)
        if not source.startswith("participant"):
            raise RunnerError(
                "--source must be the virtual participant: participant[:key=value,...]", usage=True
            )
        open_runner_source(source, loaded, "U1")  # checks the spec
    except (ProtocolFileError, RunnerError) as e:
        return fail("demo", e, EXIT_USAGE)
    pids = [f"U{i}" for i in range(1, participants + 1)]
    logs = os.path.join(out, "demo-logs")
    os.makedirs(logs, exist_ok=True)
    print(
        f"SIMULATED {'host-less ' if hostless else ''}study (virtual participants, not human "
        f"data): protocol {protocol_path}, "
        f"{len(pids)} participants {pids[0]}..{pids[-1]}, source {source}, "
        f"{min(jobs, len(pids))} at a time; study folder {out}",
        flush=True,
    )

    status = {pid: _status(loaded, out, pid) for pid in pids}
    total = sum(s[1] for s in status.values())
    todo = [pid for pid in pids if not status[pid][2]]
    before = sum(s[0] for s in status.values())
    if not todo:
        print(f"the study in {out} is complete ({total} trials): analysing it again", flush=True)
    elif before:
        print(
            f"resuming: {before} of {total} trials already completed are kept and not run again",
            flush=True,
        )

    code = _run_participants(source, protocol_path, out, logs, todo, jobs, total, status, hostless)
    if code != EXIT_OK:
        return code
    run_s = time.monotonic() - t0
    return _analyse(out, run_s, t0)


def _run_participants(
    source: str,
    protocol_path: str,
    out: str,
    logs: str,
    todo: list[str],
    jobs: int,
    total: int,
    status: dict[str, tuple[int, int, bool]],
    hostless: bool = False,
) -> int:
    if not todo:
        return EXIT_OK
    job = HostlessTrialJob if hostless else TrialJob
    tasks = [job(protocol_path, out, pid, source, os.path.join(logs, f"{pid}.log")) for pid in todo]
    next_report = [time.monotonic() + 5.0]

    def done_trials() -> int:
        return sum(count_lines(ParticipantFiles.of(out, pid).trials) for pid in status)

    def on_exit(job: TrialJob, rc: int) -> None:
        if rc == 0:
            print(
                f"{job.participant}: done, {job.completed_trials()}/"
                f"{status[job.participant][1]} trials (simulated)",
                flush=True,
            )
        else:
            print(
                f"{job.participant}: `graspguide trial` exited with {rc}; see {job.log}",
                file=sys.stderr,
                flush=True,
            )

    def on_tick(running: list[TrialJob]) -> None:
        if time.monotonic() >= next_report[0]:
            next_report[0] = time.monotonic() + 10.0
            print(
                f"  {done_trials()}/{total} trials done; running "
                f"{', '.join(j.participant for j in running)}",
                flush=True,
            )

    interrupted, failed = run_trial_jobs(tasks, jobs, on_exit, on_tick, poll_s=0.1)
    if interrupted:
        print(
            f"\ngraspguide demo: interrupted with {done_trials()}/{total} trials done; "
            "completed trials are saved: run the same command again to resume",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if failed:
        print(
            "graspguide demo: error: "
            + ", ".join(f"{j.participant} (exit {c})" for j, c in failed)
            + f" failed; their logs are in {logs}; completed trials are kept: fix the cause "
            "and run the same command again",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    return EXIT_OK


def _analyse(out: str, run_s: float, t0: float) -> int:
    from graspguide.analysis.paper_tables import AnalysisError
    from graspguide.analysis.study_analysis import analyze_study, summary_text, write_outputs

    target = os.path.join(out, "analysis")
    try:
        res = analyze_study([out])
        written = write_outputs(res, target)
    except AnalysisError as e:
        print(f"graspguide demo: error: the analysis failed: {e}", file=sys.stderr)
        return EXIT_FAILURE
    print()
    print(summary_text(res))
    print()
    print(f"Wrote {', '.join(p.name for p in written)} to {target}")
    print(
        f"SIMULATED study: {len(res.base.participants)} virtual participants; trials "
        f"{run_s:.1f} s, total {time.monotonic() - t0:.1f} s wall time"
    )
    return EXIT_OK


__all__ = ["run", "default_out", "default_protocol"]
