"""Many `graspguide trial` processes at a time, each with its own simulated device: what
`graspguide demo` and `graspguide sweep` share. A job is one participant of one study
folder; the runner inside it resumes, so a killed pool loses no completed trial."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

from graspguide.records.files import ParticipantFiles


@dataclasses.dataclass
class TrialJob:
    protocol_path: str
    study_dir: str
    participant: str
    source: str
    log: str
    tag: Any = None  # the caller's (what the job stands for, for its messages)

    def command(self) -> list[str]:
        return [
            sys.executable,
            "-m",
            "graspguide",
            "trial",
            "--protocol",
            self.protocol_path,
            "--participant",
            self.participant,
            "--port",
            "sim",
            "--source",
            self.source,
            "--out",
            self.study_dir,
        ]

    def completed_trials(self) -> int:
        return count_lines(ParticipantFiles.of(self.study_dir, self.participant).trials)


def repo_root() -> str | None:
    try:
        from graspguide.repo_root import find_repo_root

        return find_repo_root()
    except Exception:  # pragma: no cover - informational default only
        return None


def default_protocol() -> str:
    root = repo_root()
    return os.path.join(root or "", "protocols", "paper.toml")


def default_out(name: str) -> str:
    root = repo_root()
    return os.path.join(root, "logs", name) if root else name


def count_lines(path: str) -> int:
    try:
        with open(path, "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return 0


def run_trial_jobs(
    jobs: list[TrialJob],
    max_jobs: int,
    on_exit: Callable[[TrialJob, int], None],
    on_tick: Callable[[list[TrialJob]], None] | None = None,
    poll_s: float = 0.05,
) -> tuple[bool, list[tuple[TrialJob, int]]]:
    """Runs the jobs, ``max_jobs`` at a time; ``on_exit(job, returncode)`` as each ends,
    ``on_tick(running jobs)`` every poll. SIGTERM/SIGHUP/Ctrl-C stop the running runners
    with SIGTERM (each sends STOP and keeps its completed trials). Returns (interrupted,
    failed jobs with their return codes)."""

    def _interrupt(signum, frame):
        raise KeyboardInterrupt

    from graspguide.devices.sim import die_with_parent

    # A pool killed with SIGKILL leaves no runner holding a participant's folder.
    preexec = die_with_parent()
    old = {s: signal.signal(s, _interrupt) for s in (signal.SIGTERM, signal.SIGHUP)}
    queue = list(jobs)
    running: list[tuple[TrialJob, subprocess.Popen, Any]] = []
    failed: list[tuple[TrialJob, int]] = []
    try:
        while queue or running:
            while queue and len(running) < max_jobs:
                job = queue.pop(0)
                cmd = job.command()
                os.makedirs(os.path.dirname(job.log) or ".", exist_ok=True)
                log = open(job.log, "ab")
                log.write(f"\n$ {' '.join(cmd)}\n".encode())
                log.flush()
                proc = subprocess.Popen(
                    cmd,
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    preexec_fn=preexec,
                )
                running.append((job, proc, log))
            time.sleep(poll_s)
            for item in list(running):
                job, proc, log = item
                rc = proc.poll()
                if rc is None:
                    continue
                log.close()
                running.remove(item)
                if rc != 0:
                    failed.append((job, rc))
                on_exit(job, rc)
            if on_tick is not None and running:
                on_tick([job for job, _, _ in running])
    except KeyboardInterrupt:
        for _, proc, _ in running:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)  # the runner STOPs and exits (130)
        for _, proc, log in running:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            log.close()
        return True, failed
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    return False, failed
