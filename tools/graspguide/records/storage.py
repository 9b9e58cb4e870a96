"""The records on disk: the JSON Lines files of a study (read by :func:`read_jsonl`, one
reader for the runner, the demo, the sweep and the analysis; appended by
:func:`append_json_line`), and a session folder: everything one `graspguide stream` run
sent and received.

Files (all UTF-8; the CSVs and JSON Lines are append-only, one record per line, each line
flushed to the OS as soon as it is written, so a crash, SIGKILL or Ctrl-C loses nothing
already written; ``results.jsonl`` is also fsync'ed, so a trial result survives a power
loss too):

* ``scene.json`` -- the normalised scene (metres, defaults filled in);
* ``device.json`` -- the device's HELLO_REPLY;
* ``config.json`` -- scene, wrench, source, port, trial id and ``config_hash`` (sha256 of
  the canonical JSON of scene + wrench, see :mod:`graspguide.protocol.scene_file`);
* ``poses.csv`` -- POSEs sent: ``send_time_s,host_time_us,t_s,qw,qx,qy,qz,has_contacts``;
* ``telemetry.csv`` -- TELEMETRY received: ``recv_time_s,host_time_us,error_deg,alpha,
  pwm0..pwm3,constraints_used,solver_status,iterations,flags,compute_time_us``;
* ``results.jsonl`` -- TRIAL_RESULTs (and the run's end record ``{"event": "end", ...}``).

The JSON files are written whole (temporary file, then rename), so they are either absent
or complete. A record is appended whole or not at all: a write the disk cut short (full,
a size limit) is cut back off the file, and :class:`RecordWriteError` says which file and
what to do.
"""

from __future__ import annotations

import csv
import datetime as _dt
import enum
import errno
import io
import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TextIO

from graspguide.records import files

POSE_COLUMNS = ["send_time_s", "host_time_us", "t_s", "qw", "qx", "qy", "qz", "has_contacts"]
# What a TELEMETRY says of the guidance, in the session log and the runner's frames.
GUIDANCE_COLUMNS = ["error_deg", "alpha", "pwm0", "pwm1", "pwm2", "pwm3"]
TELEMETRY_COLUMNS = [
    "recv_time_s",
    "host_time_us",
    *GUIDANCE_COLUMNS,
    "constraints_used",
    "solver_status",
    "iterations",
    "flags",
    "compute_time_us",
]


def _default(o: Any) -> Any:
    if isinstance(o, enum.Enum):
        return o.name.lower()
    if hasattr(o, "to_dict"):
        return o.to_dict()
    if hasattr(o, "tolist"):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


class RecordWriteError(OSError):
    """A file could not be written (disk full, read-only or unwritable folder, a size
    limit). ``str()`` is one line: what happened, which file, what to do. An appended
    record that failed is not in the file (see :func:`append_record`)."""

    def __init__(
        self,
        path: str,
        cause: OSError,
        hint: str = "",
        appended: bool = False,
        cut_back: bool = True,
    ):
        super().__init__(cause.errno, cause.strerror, path)
        reason, todo = _DISK_FAULTS.get(cause.errno, ("", "check the disk and the folder"))
        what = cause.strerror or str(cause) or type(cause).__name__
        if reason and reason.lower() != what.lower():
            what = f"{reason} ({what})"
        if appended:
            what += (
                "; the record was not written, the file holds only whole records"
                if cut_back
                else "; it could not be cut back: its last line is partial"
            )
        self.message = f"cannot write {path}: {what}; {todo}{hint}"

    def __str__(self) -> str:
        return self.message


_WRITE_ELSEWHERE = "use a folder you can write to"
_DISK_FAULTS = {
    errno.ENOSPC: ("the disk is full", "free some space on it"),
    errno.EDQUOT: ("the disk quota is used up", "free some space or raise the quota"),
    errno.EFBIG: (
        "the file reached a size limit (`ulimit -f` or the file system's)",
        "raise the limit or start a new folder",
    ),
    errno.EROFS: ("the folder is on a read-only file system", _WRITE_ELSEWHERE),
    errno.EACCES: ("permission denied", _WRITE_ELSEWHERE + " or fix its permissions"),
    errno.EPERM: ("not permitted", _WRITE_ELSEWHERE + " or fix its permissions"),
    errno.EIO: ("an I/O error (a failing or removed drive?)", "check the drive"),
}


def append_record(fd: int, path: str, data: bytes, sync: bool = False, hint: str = "") -> None:
    """Append ``data`` (one or more whole lines) to ``fd`` (opened O_APPEND) whole or not
    at all: if the disk takes only part of it or refuses it (or the fsync fails), the
    file is cut back to its previous length and RecordWriteError raised."""
    start = os.lseek(fd, 0, os.SEEK_END)
    view = memoryview(data)
    done = 0
    try:
        while done < len(data):
            n = os.write(fd, view[done:])
            if n <= 0:  # pragma: no cover - regular files never take 0 bytes of >0
                raise OSError(errno.EIO, "the write took no bytes")
            done += n  # a short write: the next one says why (ENOSPC, EFBIG, ...)
        if sync:
            os.fsync(fd)
    except OSError as e:
        cut_back = True
        if done:
            try:
                os.ftruncate(fd, start)
            except OSError:
                cut_back = False
        raise RecordWriteError(path, e, hint, appended=True, cut_back=cut_back) from e


def open_append(path: str, hint: str = "") -> int:
    """An O_APPEND descriptor of ``path`` (created if missing); RecordWriteError if not."""
    try:
        return os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as e:
        raise RecordWriteError(path, e, hint) from e


def write_file_whole(
    path: str, write: Callable[[TextIO], object], hint: str = "", replace: bool = True
) -> None:
    """``path`` written whole by ``write(f)`` (a temporary file, fsync, then a rename)
    or left as it was: the one atomic write of the records. ``replace`` False: an
    existing ``path`` is never replaced (a hard link instead of the rename; FileExistsError
    if it exists). RecordWriteError when the disk refuses; no temporary file is left,
    whatever happens (a disk error, data JSON cannot hold, Ctrl-C)."""
    tmp = f"{path}.tmp.{os.getpid()}"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        if replace:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)  # fails with EEXIST instead of replacing
    except OSError as e:
        if e.errno == errno.EEXIST and not replace:
            raise FileExistsError(errno.EEXIST, f"{path} exists", path) from None
        raise RecordWriteError(path, e, hint) from e
    finally:
        try:
            os.unlink(tmp)
        except OSError:
            pass


def write_json_file(
    path: str, data: Any, hint: str = "", replace: bool = True, **dump_args: Any
) -> None:
    """``path`` holding ``data`` as JSON (``json.dump`` with ``dump_args``, then a
    newline), written whole or left as it was (:func:`write_file_whole`)."""

    def write(f: TextIO) -> None:
        json.dump(data, f, **dump_args)
        f.write("\n")

    write_file_whole(path, write, hint, replace)


# --------------------------------------------------------------------------------------
# JSON Lines
# --------------------------------------------------------------------------------------
def dumps_record(obj: Any) -> str:
    """One record as a JSON line's text: sorted keys, ASCII, strict JSON (no NaN)."""
    return json.dumps(
        obj, sort_keys=True, ensure_ascii=True, allow_nan=False, separators=(", ", ": ")
    )


def append_json_line(path: str, obj: Any, hint: str = "") -> None:
    """Append one JSON line, fsync'ed, whole or not at all (RecordWriteError)."""
    data = (dumps_record(obj) + "\n").encode("utf-8")
    fd = open_append(path, hint)
    try:
        append_record(fd, path, data, sync=True, hint=hint)
    finally:
        os.close(fd)


def write_json_lines(path: str, records: Sequence[Any], hint: str = "") -> None:
    """``path`` as JSON Lines (one :func:`dumps_record` line per record), written whole or
    left as it was (:func:`write_file_whole`)."""
    write_file_whole(path, lambda f: f.writelines(dumps_record(r) + "\n" for r in records), hint)


class JsonlDamaged(ValueError):
    """A damaged line with more lines after it: not a cut write, a person must look."""

    def __init__(self, path: str, line: int, reason: str):
        super().__init__(f"{path}:{line}: {reason}")
        self.line = line


@dataclass
class JsonlContents:
    records: list[dict[str, Any]]
    lines: list[int] = field(default_factory=list)  # each record's line number
    damaged_tail: bytes | None = None  # a last line cut short or not an object, if any
    tail_line: int = 0
    # Why the tail is damaged; None: a whole JSON object that only lacks its newline
    # (tail_record), which the runner still redoes and the analysis accepts.
    tail_reason: str | None = None
    tail_record: dict[str, Any] | None = None
    good_size: int = 0  # bytes of the complete, valid prefix


_BOM = b"\xef\xbb\xbf"


def _parse_line(line: bytes) -> tuple[dict[str, Any] | None, str | None]:
    """(the object, None), or (None, what is wrong with the line)."""
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as e:
        return None, f"not UTF-8 text ({e})"
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as e:
        return None, f"malformed JSON ({e.msg} at column {e.colno})"
    except ValueError as e:
        return None, f"malformed JSON ({e})"
    if not isinstance(obj, dict):
        return None, f"expected a JSON object, got {type(obj).__name__}"
    return obj, None


def read_jsonl(path: str | os.PathLike) -> JsonlContents:
    """The records of an append-only JSON Lines file (none if it does not exist; blank
    lines skipped; a UTF-8 BOM ignored). A damaged *last* line (no newline, or not a JSON
    object) is returned as ``damaged_tail``; a damaged earlier line raises JsonlDamaged;
    an unreadable file, OSError."""
    path = os.fspath(path)
    if not os.path.exists(path):
        return JsonlContents([])
    with open(path, "rb") as f:
        data = f.read()
    out = JsonlContents([])
    pos = len(_BOM) if data.startswith(_BOM) else 0
    line_no = 0
    while pos < len(data):
        line_no += 1
        nl = data.find(b"\n", pos)
        end = len(data) if nl == -1 else nl
        line = data[pos:end]
        if line.strip():
            obj, reason = _parse_line(line)
            if nl == -1 or (reason is not None and nl == len(data) - 1):
                # the last line: a write cut short (no newline) or a bad last record
                out.damaged_tail = data[pos:]
                out.tail_line = line_no
                out.tail_reason = reason
                out.tail_record = obj
                out.good_size = pos
                return out
            if obj is None:
                raise JsonlDamaged(path, line_no, reason or "damaged")
            out.records.append(obj)
            out.lines.append(line_no)
        elif nl == -1:
            break
        pos = end + 1
    out.good_size = min(pos, len(data))
    return out


@dataclass(frozen=True)
class LeftOutLine:
    """The damaged last line of a JSON Lines file that :func:`complete_records` leaves
    out; ``str()`` says where, why, what was read and how to run that trial again."""

    path: str
    line: int
    reason: str
    size: int  # bytes
    cut_short: bool  # no newline at its end: a write cut short
    complete: int  # the complete records read before it

    def __str__(self) -> str:
        what = (
            "a write cut short (no newline at its end), e.g. by a run killed mid-write"
            if self.cut_short
            else "damaged"
        )
        return (
            f"{self.path}:{self.line}: the last line is {what}: {self.reason}, {self.size} "
            f"bytes; it is left out and the {self.complete} complete records before it are "
            "read (the file is not changed). To record it again, run the same `graspguide "
            "trial` command for this participant: it moves the line aside to "
            f"{os.path.basename(self.path)}.damaged-<time> and runs what it recorded again"
        )


def complete_records(
    path: str | os.PathLike,
) -> tuple[list[tuple[str, dict[str, Any]]], LeftOutLine | None]:
    """(``FILE:LINE``, record) for every complete record of a JSON Lines file the runner
    appends to, and its damaged last line, left out (None when there is none). Readers of
    finished runs (the analysis, the plots) read the records this way: a run killed
    mid-write leaves at most its last line damaged, and the records before it are whole.
    A last line that only lacks its newline is a complete record. A damaged earlier line
    raises JsonlDamaged (not a cut write: a person must look); an unreadable file,
    OSError."""
    where = os.fspath(path)
    contents = read_jsonl(where)
    out = [(f"{where}:{n}", r) for n, r in zip(contents.lines, contents.records)]
    tail = contents.damaged_tail
    if tail is None:
        return out, None
    if contents.tail_record is not None:
        out.append((f"{where}:{contents.tail_line}", contents.tail_record))
        return out, None
    left_out = LeftOutLine(
        path=where,
        line=contents.tail_line,
        reason=contents.tail_reason or "damaged",
        size=len(tail),
        cut_short=not tail.endswith(b"\n"),
        complete=len(out),
    )
    return out, left_out


def set_aside_damaged_tail(path: str, contents: JsonlContents) -> str:
    """Move a damaged last line to ``PATH.damaged-<time>`` and cut it from the file.
    Returns the new file's path."""
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S%fZ")
    aside = f"{path}.damaged-{stamp}"
    with open(aside, "wb") as f:
        f.write(contents.damaged_tail or b"")
        f.flush()
        os.fsync(f.fileno())
    with open(path, "r+b") as f:
        f.truncate(contents.good_size)
        f.flush()
        os.fsync(f.fileno())
    return aside


# --------------------------------------------------------------------------------------
# A session folder (graspguide stream --log)
# --------------------------------------------------------------------------------------
_HINT = " (or give another --log folder)"


class _Lines:
    """An append-only text file; every write is one complete line, flushed (and fsync'ed
    when ``sync``), or nothing (RecordWriteError)."""

    def __init__(self, path: str, header: Sequence[str] | None = None, sync: bool = False):
        self.path = path
        self.fd = open_append(path, _HINT)
        self.sync = sync
        self.lines = 0
        if header is not None and os.fstat(self.fd).st_size == 0:
            self.write_row(header)

    def write_line(self, text: str) -> None:
        append_record(self.fd, self.path, (text + "\n").encode("utf-8"), self.sync, _HINT)
        self.lines += 1

    def write_row(self, row: Sequence[Any]) -> None:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="").writerow(row)
        self.write_line(buf.getvalue())

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            try:
                os.fsync(fd)
            except OSError as e:
                raise RecordWriteError(self.path, e, _HINT) from e
            finally:
                os.close(fd)


class SessionLog:
    """Writer of one session folder (created if missing; existing files are appended to)."""

    def __init__(self, folder: str):
        self.folder = folder
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as e:
            raise RecordWriteError(folder, e, _HINT) from e
        self.t0 = time.monotonic()
        self.poses = _Lines(self.path(files.SESSION_POSES_FILE), POSE_COLUMNS)
        self.telemetry_file = _Lines(self.path(files.SESSION_TELEMETRY_FILE), TELEMETRY_COLUMNS)
        self.results = _Lines(self.path(files.SESSION_RESULTS_FILE), sync=True)

    def path(self, name: str) -> str:
        return os.path.join(self.folder, name)

    def now(self) -> float:
        return round(time.monotonic() - self.t0, 6)

    def write_json(self, name: str, data: Any) -> None:
        write_json_file(self.path(name), data, _HINT, indent=2, sort_keys=True, default=_default)

    def scene(self, data: dict[str, Any]) -> None:
        self.write_json(files.SESSION_SCENE_FILE, data)

    def device(self, hello: Any) -> None:
        self.write_json(files.SESSION_DEVICE_FILE, hello)

    def config(self, data: dict[str, Any]) -> None:
        self.write_json(files.SESSION_CONFIG_FILE, data)

    def pose(
        self, host_time_us: int, t_s: float, quat: Sequence[float], has_contacts: bool
    ) -> None:
        self.poses.write_row(
            [self.now(), int(host_time_us), repr(float(t_s))]
            + [repr(float(x)) for x in quat]
            + [int(bool(has_contacts))]
        )

    def telemetry(self, tel: Any) -> None:
        d = tel.to_dict() if hasattr(tel, "to_dict") else dict(tel)
        pwm = list(d["pwm"]) + [0] * (4 - len(d["pwm"]))
        self.telemetry_file.write_row(
            [self.now(), d["host_time_us"], repr(float(d["error_deg"])), repr(float(d["alpha"]))]
            + pwm[:4]
            + [
                _default(d["constraints_used"])
                if isinstance(d["constraints_used"], enum.Enum)
                else d["constraints_used"],
                _default(d["solver_status"])
                if isinstance(d["solver_status"], enum.Enum)
                else d["solver_status"],
                d["iterations"],
                int(d["flags"]),
                d["compute_time_us"],
            ]
        )

    def result(self, record: Any) -> None:
        d = record.to_dict() if hasattr(record, "to_dict") else dict(record)
        d.setdefault("recv_time_s", self.now())
        self.results.write_line(json.dumps(d, sort_keys=True, default=_default))

    def close(self) -> None:
        errors = []
        for f in (self.poses, self.telemetry_file, self.results):
            try:
                f.close()
            except RecordWriteError as e:
                errors.append(e)
        if errors:
            raise errors[0]

    def __enter__(self) -> SessionLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = [
    "read_jsonl",
    "complete_records",
    "LeftOutLine",
    "JsonlContents",
    "JsonlDamaged",
    "set_aside_damaged_tail",
    "append_json_line",
    "dumps_record",
    "SessionLog",
    "RecordWriteError",
    "append_record",
    "open_append",
    "write_json_file",
    "write_json_lines",
    "write_file_whole",
    "POSE_COLUMNS",
    "TELEMETRY_COLUMNS",
]
