"""A trial's frames file, ``OUT/<PID>/frames/trial-NNNN.csv``: one row per POSE sent and
the TELEMETRY that answered it (:data:`FRAME_COLUMNS`), written to a temporary file while
the trial runs and renamed when its record is appended."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from graspguide.records.storage import GUIDANCE_COLUMNS, RecordWriteError

FRAME_COLUMNS = [
    "t_s",  # s since the trial's start (the pose's time)
    "host_time_us",  # us, the host's stamp the device echoes
    "qw",  # the hand's orientation, a unit quaternion
    "qx",
    "qy",
    "qz",
    *GUIDANCE_COLUMNS,  # error_deg (deg), alpha, pwm0..pwm3 (duty 0..255)
    "solver_status",  # 0: solved
    "flags",
]
FRAME_HEADER = ",".join(FRAME_COLUMNS) + "\n"
#: One FRAME_COLUMNS row as csv.writer writes it for these fields (floats by repr, none
#: needs quoting).
_FRAME_ROW = "%r,%d,%r,%r,%r,%r,%r,%r,%d,%d,%d,%d,%d,%d\n"


def frame_rows(stamped: Sequence[Any], tels: Sequence[Any]) -> str:
    """The FRAME_COLUMNS rows of poses sent (t_s, t_us, quat, contacts) and their
    TELEMETRY, as csv.writer writes them: floats by repr (a Telemetry holds its f32
    fields as floats), %d takes the enums' values."""
    row = _FRAME_ROW
    return "".join(
        [
            row
            % (
                round(t_s, 6),
                t_us,
                *quat,
                tel.error_deg,
                tel.alpha,
                *tel.pwm,
                tel.solver_status,
                tel.flags,
            )
            for (t_s, t_us, quat, _), tel in zip(stamped, tels)
        ]
    )


class FramesFile:
    """A trial's frames CSV (a temporary file until the trial is recorded), its header
    written: a write error becomes RecordWriteError naming it (with ``hint``), and the
    partial file is removed on close (it holds no record, and on a full disk its space
    is wanted)."""

    def __init__(self, path: str, hint: str = ""):
        self.path = path
        self.hint = hint
        self.failed = False
        try:
            self.f = open(path, "w", encoding="utf-8", newline="", buffering=1 << 20)
        except OSError as e:
            raise RecordWriteError(path, e, hint) from e
        self.write(FRAME_HEADER)

    def _fault(self, e: OSError) -> RecordWriteError:
        self.failed = True
        return RecordWriteError(self.path, e, self.hint)

    def write(self, text: str) -> None:
        try:
            self.f.write(text)
        except OSError as e:
            raise self._fault(e) from e

    def restart(self) -> None:
        """Empty the file down to its header (the trial runs again)."""
        try:
            self.f.seek(0)
            self.f.truncate()
        except OSError as e:
            raise self._fault(e) from e
        self.write(FRAME_HEADER)

    def sync(self) -> None:
        try:
            self.f.flush()
            os.fsync(self.f.fileno())
        except OSError as e:
            raise self._fault(e) from e

    def close(self) -> None:
        try:
            self.f.close()
        except OSError:
            self.failed = True  # the buffer's rest did not fit either
        if self.failed:
            try:
                os.unlink(self.path)
            except OSError:
                pass


__all__ = ["FRAME_COLUMNS", "FRAME_HEADER", "frame_rows", "FramesFile"]
