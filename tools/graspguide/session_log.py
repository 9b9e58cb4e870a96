"""A session folder: everything one `graspguide stream` run sent and received.

Files (all UTF-8; the CSVs and JSON Lines are append-only, one record per line, each line
flushed to the OS as soon as it is written, so a crash, SIGKILL or Ctrl-C loses nothing
already written; ``results.jsonl`` is also fsync'ed, so a trial result survives a power
loss too):

* ``scene.json`` -- the normalised scene (metres, defaults filled in);
* ``device.json`` -- the device's HELLO_REPLY;
* ``config.json`` -- scene, wrench, source, port, trial id and ``config_hash`` (sha256 of
  the canonical JSON of scene + wrench, see :mod:`graspguide.scene`);
* ``poses.csv`` -- POSEs sent: ``send_time_s,host_time_us,t_s,qw,qx,qy,qz,has_contacts``;
* ``telemetry.csv`` -- TELEMETRY received: ``recv_time_s,host_time_us,error_deg,alpha,
  pwm0..pwm3,constraints_used,solver_status,iterations,flags,compute_time_us``;
* ``results.jsonl`` -- TRIAL_RESULTs (and the run's end record ``{"event": "end", ...}``).

The JSON files are written whole (temporary file, then rename), so they are either absent
or complete.
"""

from __future__ import annotations

import csv
import enum
import io
import json
import os
import time
from typing import Any, Dict, Optional, Sequence

POSE_COLUMNS = ["send_time_s", "host_time_us", "t_s", "qw", "qx", "qy", "qz", "has_contacts"]
TELEMETRY_COLUMNS = ["recv_time_s", "host_time_us", "error_deg", "alpha", "pwm0", "pwm1",
                     "pwm2", "pwm3", "constraints_used", "solver_status", "iterations", "flags",
                     "compute_time_us"]


def _default(o: Any) -> Any:
    if isinstance(o, enum.Enum):
        return o.name.lower()
    if hasattr(o, "to_dict"):
        return o.to_dict()
    if hasattr(o, "tolist"):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


class _Lines:
    """An append-only text file; every write is one complete line, flushed (and fsync'ed
    when ``sync``)."""

    def __init__(self, path: str, header: Optional[Sequence[str]] = None, sync: bool = False):
        new = not os.path.exists(path) or os.path.getsize(path) == 0
        self.f = open(path, "a", encoding="utf-8", newline="")
        self.sync = sync
        self.lines = 0
        if header is not None and new:
            self.write_row(header)

    def write_line(self, text: str) -> None:
        # One write() call of the whole line: never a half line in the file.
        self.f.write(text + "\n")
        self.f.flush()
        if self.sync:
            os.fsync(self.f.fileno())
        self.lines += 1

    def write_row(self, row: Sequence[Any]) -> None:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="").writerow(row)
        self.write_line(buf.getvalue())

    def close(self) -> None:
        if not self.f.closed:
            self.f.flush()
            os.fsync(self.f.fileno())
            self.f.close()


class SessionLog:
    """Writer of one session folder (created if missing; existing files are appended to)."""

    def __init__(self, folder: str):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)
        self.t0 = time.monotonic()
        self.poses = _Lines(self.path("poses.csv"), POSE_COLUMNS)
        self.telemetry_file = _Lines(self.path("telemetry.csv"), TELEMETRY_COLUMNS)
        self.results = _Lines(self.path("results.jsonl"), sync=True)

    def path(self, name: str) -> str:
        return os.path.join(self.folder, name)

    def now(self) -> float:
        return round(time.monotonic() - self.t0, 6)

    def write_json(self, name: str, data: Any) -> None:
        tmp = self.path(name + ".tmp")
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=2, sort_keys=True, default=_default)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path(name))

    def scene(self, data: Dict[str, Any]) -> None:
        self.write_json("scene.json", data)

    def device(self, hello: Any) -> None:
        self.write_json("device.json", hello)

    def config(self, data: Dict[str, Any]) -> None:
        self.write_json("config.json", data)

    def pose(self, host_time_us: int, t_s: float, quat: Sequence[float],
             has_contacts: bool) -> None:
        self.poses.write_row([self.now(), int(host_time_us), repr(float(t_s))]
                             + [repr(float(x)) for x in quat] + [int(bool(has_contacts))])

    def telemetry(self, tel: Any) -> None:
        d = tel.to_dict() if hasattr(tel, "to_dict") else dict(tel)
        pwm = list(d["pwm"]) + [0] * (4 - len(d["pwm"]))
        self.telemetry_file.write_row(
            [self.now(), d["host_time_us"], repr(float(d["error_deg"])),
             repr(float(d["alpha"]))] + pwm[:4]
            + [_default(d["constraints_used"]) if isinstance(d["constraints_used"], enum.Enum)
               else d["constraints_used"],
               _default(d["solver_status"]) if isinstance(d["solver_status"], enum.Enum)
               else d["solver_status"], d["iterations"], int(d["flags"]),
               d["compute_time_us"]])

    def result(self, record: Any) -> None:
        d = record.to_dict() if hasattr(record, "to_dict") else dict(record)
        d.setdefault("recv_time_s", self.now())
        self.results.write_line(json.dumps(d, sort_keys=True, default=_default))

    def close(self) -> None:
        for f in (self.poses, self.telemetry_file, self.results):
            f.close()

    def __enter__(self) -> "SessionLog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["SessionLog", "POSE_COLUMNS", "TELEMETRY_COLUMNS"]
