"""Lab Streaming Layer outlets of a run (docs/lab-streams.md): a telemetry stream (one
float32 sample per TELEMETRY) and a marker stream (one string per trial event), so EEG,
EMG and eye-tracking recordings (LabRecorder) can be aligned with the guidance.

:class:`LabStreams` is a :class:`graspguide.records.events.TrialObserver`: `stream`
and `trial` hand it their events and TELEMETRY and do not know LSL otherwise.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Sequence
from typing import Any

from graspguide.core.vocabulary import FINGERS

#: The telemetry stream's channels, in order: (label, unit, LSL channel type).
TELEMETRY_CHANNELS: tuple[tuple[str, str, str], ...] = (
    ("error_deg", "degrees", "GuidanceError"),
    ("alpha", "pwm_counts", "ModeVGain"),
    *((f"pwm_{finger}", "pwm_counts", "MotorDuty") for finger in FINGERS),
    ("status", "solver_status_code", "Status"),
    # the pose's trial time: matches a sample to the session log even on the virtual
    # clock, where LSL's own timestamps are wall time
    ("trial_time_s", "seconds", "TrialTime"),
)
TELEMETRY_TYPE = "GraspGuide"
MARKER_TYPE = "Markers"

# liblsl reads its configuration from these (docs/lab-streams.md); when none exists the
# outlets run with liblsl's defaults but its INFO log lines are silenced.
_CONFIG_FILES = ("lsl_api.cfg", "~/lsl_api.cfg", "/etc/lsl_api.cfg")
_QUIET_CONFIG = "[log]\nlevel = -2\n"


class LabStreamsError(RuntimeError):
    """LSL cannot be used here; the message says why and what to do."""


class LabStreamsUsageError(LabStreamsError):
    """A bad stream setting (the name); the message says what to fix."""


def _load_pylsl(configure_log: bool) -> Any:
    """pylsl with its bundled liblsl loaded, or LabStreamsError."""
    try:
        import pylsl  # type: ignore[import-untyped]
    except (ImportError, RuntimeError, OSError) as e:
        raise LabStreamsError(
            f"cannot load pylsl/liblsl ({e}); install the pinned pylsl "
            "(tools/requirements-dev.txt: its wheel carries liblsl) or set PYLSL_LIB to a "
            "liblsl.so"
        ) from None
    if configure_log and not _lab_config_present():
        try:
            pylsl.set_config_content(_QUIET_CONFIG)
        except Exception:  # liblsl already configured in this process: keep its config
            pass
    return pylsl


def _lab_config_present() -> bool:
    if os.environ.get("LSLAPICFG"):
        return True
    return any(os.path.exists(os.path.expanduser(p)) for p in _CONFIG_FILES)


def _flags(name: str) -> int:
    """An interface's flags (SIOCGIFFLAGS) in this process's network namespace."""
    import fcntl
    import socket
    import struct

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        req = struct.pack("16sH14x", name.encode()[:15], 0)
        return struct.unpack("16sH14x", fcntl.ioctl(sock.fileno(), 0x8913, req))[1]


def interfaces_up(names=None, flags=_flags) -> list[str] | None:
    """The network interfaces that are up (the loopback included), or None where the
    system cannot say (no if_nameindex, no SIOCGIFFLAGS)."""
    import socket

    try:
        names = [n for _, n in socket.if_nameindex()] if names is None else names
        return sorted(n for n in names if flags(n) & 0x1)  # IFF_UP
    except (OSError, AttributeError, ImportError):
        return None


def network_problem(names=None, flags=_flags) -> str | None:
    """Why LSL cannot reach anyone from here, or None. liblsl itself only logs this and
    publishes streams nobody can find."""
    up = interfaces_up(names, flags)
    if up is not None and not up:
        return (
            "no network interface is up, not even the loopback: no LSL recorder could "
            "find the streams; bring one up (ip link set lo up) and run again"
        )
    return None


def source_id(name: str, participant: str, session: str, kind: str) -> str:
    """A stream's source_id: the same for the same name, participant and session, so a
    recorder (LabRecorder) re-links to the stream after the run restarts."""
    return f"graspguide/{name}/{participant or '-'}/{session or '-'}/{kind}"


def marker_text(name: str, fields: dict[str, Any]) -> str:
    """A marker's string: compact JSON, the event's name first (``{"event":"trial_start",
    "trial_index":3}``); non-finite numbers become null (JSON has no NaN)."""

    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        if isinstance(v, dict):
            return {str(k): clean(x) for k, x in v.items()}
        return v

    body = {"event": name, **{k: clean(v) for k, v in fields.items()}}
    return json.dumps(body, separators=(",", ":"), default=str)


class LabStreams:
    """The two LSL outlets of a run; a context manager and a TrialObserver.

    ``name`` prefixes the streams' names (``NAME-Telemetry``, ``NAME-Markers``);
    ``nominal_rate_hz`` is the pose rate in real time, 0 for irregular (the virtual
    clock); ``simulated`` marks a run without a person (the virtual participant) in the
    streams' descriptions. ``linger_s``: on close, how long to keep outlets that have a
    consumer open so their last samples reach it."""

    def __init__(
        self,
        name: str = "GraspGuide",
        *,
        participant: str = "",
        session: str = "",
        nominal_rate_hz: float = 0.0,
        simulated: bool = False,
        extra: dict[str, Any] | None = None,
        linger_s: float = 0.5,
    ):
        if not name or any(c in name for c in "/\n\r\t"):
            raise LabStreamsUsageError(
                f"--lsl name {name!r} must be non-empty without '/' or line breaks "
                "(e.g. --lsl GraspGuide)"
            )
        if not (math.isfinite(nominal_rate_hz) and nominal_rate_hz >= 0):
            raise LabStreamsUsageError(
                f"nominal_rate_hz must be >= 0 (0: irregular), got {nominal_rate_hz}"
            )
        self.name = name
        self.participant = participant
        self.session = session
        self.nominal_rate_hz = float(nominal_rate_hz)
        self.simulated = simulated
        self.extra = dict(extra or {})
        self.linger_s = linger_s
        self.telemetry_name = f"{name}-Telemetry"
        self.marker_name = f"{name}-Markers"
        self.telemetry_outlet: Any = None
        self.marker_outlet: Any = None
        self.samples = 0
        self.markers = 0

    # ---- lifetime
    def open(self) -> LabStreams:
        lsl = _load_pylsl(configure_log=True)
        problem = network_problem()
        if problem:
            raise LabStreamsError(problem)
        try:
            tel = lsl.StreamInfo(
                self.telemetry_name,
                TELEMETRY_TYPE,
                len(TELEMETRY_CHANNELS),
                self.nominal_rate_hz or lsl.IRREGULAR_RATE,
                lsl.cf_float32,
                source_id(self.name, self.participant, self.session, "telemetry"),
            )
            channels = tel.desc().append_child("channels")
            for label, unit, kind in TELEMETRY_CHANNELS:
                ch = channels.append_child("channel")
                ch.append_child_value("label", label)
                ch.append_child_value("unit", unit)
                ch.append_child_value("type", kind)
            self._describe(tel)
            markers = lsl.StreamInfo(
                self.marker_name,
                MARKER_TYPE,
                1,
                lsl.IRREGULAR_RATE,
                lsl.cf_string,
                source_id(self.name, self.participant, self.session, "markers"),
            )
            markers.desc().append_child("channels").append_child("channel").append_child_value(
                "label", "event_json"
            )
            self._describe(markers)
            self.telemetry_outlet = lsl.StreamOutlet(tel)
            self.marker_outlet = lsl.StreamOutlet(markers)
        except LabStreamsError:
            raise
        except Exception as e:
            self.close()
            raise LabStreamsError(
                f"cannot open the LSL outlets ({e}); LSL needs a network interface that is "
                "up (the loopback is enough: see docs/lab-streams.md for lsl_api.cfg with "
                "KnownPeers = {127.0.0.1})"
            ) from None
        return self

    def _describe(self, info: Any) -> None:
        desc = info.desc()
        acq = desc.append_child("acquisition")
        acq.append_child_value("manufacturer", "GraspGuide")
        acq.append_child_value("participant", self.participant)
        acq.append_child_value("session", self.session)
        # The virtual participant's runs say so in every recording that holds them.
        acq.append_child_value("simulated", "true" if self.simulated else "false")
        for key, value in self.extra.items():
            acq.append_child_value(str(key), str(value))

    def __enter__(self) -> LabStreams:
        return self.open() if self.telemetry_outlet is None else self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def wait_for_consumers(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for a consumer (a recorder) on both streams; True when
        both have one. Samples pushed before a consumer connects are not recorded."""
        deadline = time.monotonic() + timeout_s
        for outlet in (self.telemetry_outlet, self.marker_outlet):
            left = deadline - time.monotonic()
            if outlet is None or not outlet.wait_for_consumers(max(left, 0.0)):
                return False
        return True

    def close(self) -> None:
        outlets = [o for o in (self.telemetry_outlet, self.marker_outlet) if o is not None]
        self.telemetry_outlet = self.marker_outlet = None
        # liblsl sends from its own threads: give a connected consumer time for the tail
        # of the run before the outlets (and their buffers) go.
        if self.linger_s > 0 and any(o.have_consumers() for o in outlets):
            time.sleep(self.linger_s)
        outlets.clear()  # the last references: liblsl closes the outlets now

    # ---- TrialObserver
    def on_event(self, name: str, **fields: Any) -> None:
        if self.marker_outlet is None:
            return
        self.marker_outlet.push_sample([marker_text(name, fields)])
        self.markers += 1

    def on_telemetry(
        self,
        t_s: float,
        error_deg: float,
        alpha: float,
        pwm: Sequence[int],
        status: int,
    ) -> None:
        if self.telemetry_outlet is None:
            return
        duty = [float(x) for x in pwm[: len(FINGERS)]]
        duty += [0.0] * (len(FINGERS) - len(duty))
        self.telemetry_outlet.push_sample(
            [float(error_deg), float(alpha), *duty, float(int(status)), float(t_s)]
        )
        self.samples += 1


def open_lab_streams(
    command: str,
    name: str,
    wait_s: float,
    *,
    participant: str = "",
    session: str = "",
    nominal_rate_hz: float = 0.0,
    simulated: bool = False,
    extra: dict[str, Any] | None = None,
) -> LabStreams:
    """The LSL outlets of ``COMMAND --lsl NAME``, opened, after waiting up to ``wait_s``
    seconds for a recorder (a warning when none came: what is sent before one connects
    is not recorded); raises LabStreamsError."""
    streams = LabStreams(
        name,
        participant=participant,
        session=session,
        nominal_rate_hz=nominal_rate_hz,
        simulated=simulated,
        extra=extra,
    ).open()
    print(
        f"graspguide {command}: LSL: publishing {streams.telemetry_name} and "
        f"{streams.marker_name}" + (" (SIMULATED participant)" if simulated else ""),
        file=sys.stderr,
        flush=True,
    )
    if wait_s > 0 and not streams.wait_for_consumers(wait_s):
        print(
            f"graspguide {command}: warning: no LSL recorder connected within {wait_s:g} s; "
            "streaming anyway (what is sent before one connects is not recorded)",
            file=sys.stderr,
            flush=True,
        )
    return streams


__all__ = [
    "open_lab_streams",
    "LabStreams",
    "LabStreamsError",
    "LabStreamsUsageError",
    "TELEMETRY_CHANNELS",
    "TELEMETRY_TYPE",
    "MARKER_TYPE",
    "marker_text",
    "network_problem",
    "source_id",
]
