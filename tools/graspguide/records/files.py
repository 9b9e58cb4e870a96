"""The file names of a run folder, in one place: every writer (the runner, the host-less
download, calibration) and every reader (the analysis, the plots, the demo, the sweep)
builds its paths here.

A study folder ``OUT`` (`graspguide trial --out`)::

    OUT/study.json                       the protocol, its config_hash, the drawn wrenches
    OUT/<PID>/trials.jsonl               one line per completed trial (records.trial)
    OUT/<PID>/tlx.jsonl                  one line per finished session (records.trial)
    OUT/<PID>/plan.json                  the participant's plan
    OUT/<PID>/runs.jsonl                 one line per run start and end
    OUT/<PID>/events.jsonl               the operator's pauses, redos, skips and notes
    OUT/<PID>/calibration.json           the participant's motor calibration
    OUT/<PID>/device_log.json            a host-less download's LOG_INFO and device
    OUT/<PID>/world.jsonl                a host-less run's true errors (simulated world)
    OUT/<PID>/frames/trial-NNNN.csv      a trial's POSEs and TELEMETRY (FRAME_COLUMNS)
    OUT/<PID>/frames/aside/trial-NNNN-attempt-A.csv   an attempt ended by a redo or skip

A session folder (`graspguide stream --log`): the SESSION_* names below.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

STUDY_FILE = "study.json"
TRIALS_FILE = "trials.jsonl"
TLX_FILE = "tlx.jsonl"
PLAN_FILE = "plan.json"
RUNS_FILE = "runs.jsonl"
EVENTS_FILE = "events.jsonl"
CALIBRATION_FILE = "calibration.json"
DEVICE_LOG_FILE = "device_log.json"
WORLD_FILE = "world.jsonl"
LOCK_FILE = ".lock"
FRAMES_DIR = "frames"
ASIDE_DIR = "aside"
# A trial's frames are written under this suffix and renamed when the trial is recorded.
PARTIAL_SUFFIX = ".tmp"
# Where the runner moves a damaged last line: ``<file>.damaged-<time>``.
DAMAGED_SUFFIX = ".damaged-"

# A session folder (graspguide stream --log).
SESSION_SCENE_FILE = "scene.json"
SESSION_DEVICE_FILE = "device.json"
SESSION_CONFIG_FILE = "config.json"
SESSION_POSES_FILE = "poses.csv"
SESSION_TELEMETRY_FILE = "telemetry.csv"
SESSION_RESULTS_FILE = "results.jsonl"
# The files that make a folder a session folder (the plots tell the two kinds apart).
SESSION_MARKERS = (SESSION_TELEMETRY_FILE, SESSION_RESULTS_FILE)


def frames_name(trial_index: int) -> str:
    """``trial-NNNN.csv``: a trial's frames file (in FRAMES_DIR)."""
    return f"trial-{trial_index:04d}.csv"


def aside_name(trial_index: int, attempt: int) -> str:
    """``trial-NNNN-attempt-A.csv``: an ended attempt's frames (in FRAMES_DIR/ASIDE_DIR)."""
    return f"trial-{trial_index:04d}-attempt-{attempt}.csv"


def study_file(out_dir: str) -> str:
    return os.path.join(out_dir, STUDY_FILE)


def participant_dir(out_dir: str, participant: str) -> str:
    return os.path.join(out_dir, participant)


@dataclass(frozen=True)
class ParticipantFiles:
    """The paths of one participant's folder ``OUT/<PID>``."""

    folder: str

    @classmethod
    def of(cls, out_dir: str, participant: str) -> ParticipantFiles:
        return cls(participant_dir(out_dir, participant))

    def _path(self, name: str) -> str:
        return os.path.join(self.folder, name)

    @property
    def trials(self) -> str:
        return self._path(TRIALS_FILE)

    @property
    def tlx(self) -> str:
        return self._path(TLX_FILE)

    @property
    def plan(self) -> str:
        return self._path(PLAN_FILE)

    @property
    def runs(self) -> str:
        return self._path(RUNS_FILE)

    @property
    def events(self) -> str:
        return self._path(EVENTS_FILE)

    @property
    def calibration(self) -> str:
        return self._path(CALIBRATION_FILE)

    @property
    def device_log(self) -> str:
        return self._path(DEVICE_LOG_FILE)

    @property
    def world(self) -> str:
        return self._path(WORLD_FILE)

    @property
    def lock(self) -> str:
        return self._path(LOCK_FILE)

    @property
    def frames_dir(self) -> str:
        return self._path(FRAMES_DIR)

    @property
    def aside_dir(self) -> str:
        return os.path.join(self.frames_dir, ASIDE_DIR)

    def frames(self, trial_index: int) -> str:
        """A recorded trial's frames file."""
        return os.path.join(self.frames_dir, frames_name(trial_index))

    def partial_frames(self, trial_index: int) -> str:
        """The frames file of a trial still running (renamed to :meth:`frames` when the
        trial is recorded)."""
        return self.frames(trial_index) + PARTIAL_SUFFIX

    def aside(self, trial_index: int, attempt: int) -> str:
        return os.path.join(self.aside_dir, aside_name(trial_index, attempt))

    def holds_records(self) -> bool:
        """Whether the folder holds a trials or TLX file (a participant folder)."""
        return os.path.exists(self.trials) or os.path.exists(self.tlx)


__all__ = [
    "STUDY_FILE",
    "TRIALS_FILE",
    "TLX_FILE",
    "PLAN_FILE",
    "RUNS_FILE",
    "EVENTS_FILE",
    "CALIBRATION_FILE",
    "DEVICE_LOG_FILE",
    "WORLD_FILE",
    "LOCK_FILE",
    "FRAMES_DIR",
    "ASIDE_DIR",
    "PARTIAL_SUFFIX",
    "DAMAGED_SUFFIX",
    "SESSION_SCENE_FILE",
    "SESSION_DEVICE_FILE",
    "SESSION_CONFIG_FILE",
    "SESSION_POSES_FILE",
    "SESSION_TELEMETRY_FILE",
    "SESSION_RESULTS_FILE",
    "SESSION_MARKERS",
    "ParticipantFiles",
    "frames_name",
    "aside_name",
    "study_file",
    "participant_dir",
]
