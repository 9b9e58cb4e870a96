"""The pose sources of `graspguide trial`: ``--source SPEC`` opened for a protocol and a
participant, as a closed loop (the virtual participant, a plugin class with
begin_trial/step) or an open loop (synthetic, replay, a tracker adapter), each with what
the runner needs to know of it (simulated, live, rate, describe())."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from typing import Any

from graspguide.protocol.study_protocol import PlannedTrial, Protocol, derive_seed
from graspguide.run_errors import RunnerError

#: What a source kind is when it is simulated (the words of the SIMULATED label).
_SIMULATED_SOURCES = {
    "participant": "the virtual participant, not a person",
    "synthetic": "a scripted hand (synthetic), not a person",
    "replay": "a recorded pose stream replayed, not a live person",
    "plugin": "the plugin's source is SIMULATED, not a person",
}


def simulated_device(port: str | None) -> str | None:
    """What the device at ``port`` is when it is a simulation of one, else None."""
    from graspguide.devices.promini_sim import PROMINI_SIM_PORT
    from graspguide.devices.qemu_firmware import QEMU_PORT
    from graspguide.devices.sim import SIM_PORT

    return {
        SIM_PORT: "the simulated device (--port sim), not a board",
        PROMINI_SIM_PORT: "the Pro Mini sketch under simavr (--port promini-sim), not a board",
        QEMU_PORT: "the firmware under QEMU (--port qemu), not a board",
    }.get(port or "")


def simulation(spec: str, source_simulated: bool, port: str | None) -> str | None:
    """The one rule of SIMULATED, for `stream` and `trial`, their records and their
    terminal output: why a run with the source ``spec`` (simulated or not, as the source
    says) on the device ``port`` is simulated, or None for a live person on a board."""
    why = []
    if source_simulated:
        kind = spec.partition(":")[0]
        why.append(_SIMULATED_SOURCES.get(kind, "a simulated source, not a person"))
    device = simulated_device(port)
    if device is not None:
        why.append(device)
    return "; ".join(why) if why else None


def participant_keys(seed: bool) -> list[str]:
    """The keys of ``participant:KEY=VALUE,...``: the virtual participant's parameters
    (ParticipantParams' fields) and ``fingers``, after ``seed`` where the command takes
    one (`stream`; `trial` derives it from the protocol and the participant)."""
    from dataclasses import fields

    from graspguide.participant.model import ParticipantParams

    keys = [f.name for f in fields(ParticipantParams)] + ["fingers"]
    return ["seed", *keys] if seed else keys


def check_participant_keys(spec: str, seed: bool) -> None:
    """ValueError naming an unknown key of the participant spec ``spec`` (what follows
    ``participant:``), the closest known one and every key; the values are the
    participant's to check."""
    from graspguide.core.suggest import unknown_name

    keys = participant_keys(seed)
    for item in filter(None, (x.strip() for x in spec.split(","))):
        key = item.partition("=")[0].strip()
        if key not in keys:
            hint = ""
            if key == "seed":
                hint = (
                    " (the seed comes from the protocol's seed and the participant id: "
                    "the same participant gets the same person on every run)"
                )
            raise ValueError(unknown_name("participant key", key, keys) + hint)


class RunnerSource:
    """What the runner needs of a source. ``closed_loop``: begin_trial/step in lockstep;
    else ``samples(trial)`` yields (t_s, quat, contacts). ``simulated``: no person (TLX
    recorded as absent unless --tlx). ``live``: real-time (a tracker)."""

    closed_loop = False
    simulated = True
    live = False
    rate_hz: float = 100.0

    def describe(self) -> dict[str, Any]:  # pragma: no cover - interface
        raise NotImplementedError


class ClosedLoopSource(RunnerSource):
    closed_loop = True

    def __init__(self, model: Any, spec: str):
        for attr in ("rate_hz", "begin_trial", "step"):
            if not hasattr(model, attr):
                raise RunnerError(
                    f"--source {spec}: {type(model).__name__} has no {attr}; a "
                    "closed-loop source needs rate_hz, SIMULATED, "
                    "begin_trial(...) and step(t_s, pwm)",
                    usage=True,
                )
        self.model = model
        self.spec = spec
        self.rate_hz = float(model.rate_hz)
        if not 0 < self.rate_hz <= 10000:
            raise RunnerError(
                f"--source {spec}: rate_hz must be in (0, 10000], got {model.rate_hz!r}", usage=True
            )
        self.simulated = bool(getattr(model, "SIMULATED", True))

    def describe(self) -> dict[str, Any]:
        d = {
            "source": self.spec,
            "kind": "closed_loop",
            "class": type(self.model).__name__,
            "source_rate_hz": self.rate_hz,
            "simulated": self.simulated,
        }
        extra = getattr(self.model, "describe", None)
        if callable(extra):
            try:
                d["model"] = extra()
            except Exception:  # pragma: no cover - a model's describe is informational
                pass
        return d


class OpenLoopSource(RunnerSource):
    def __init__(
        self,
        spec: str,
        make: Callable[[PlannedTrial], Any],
        rate_hz: float,
        simulated: bool,
        live: bool,
        info: dict[str, Any],
        base: Any = None,
    ):
        self.spec = spec
        self.base = base
        self.make = make
        self.rate_hz = float(rate_hz)
        self.simulated = simulated
        self.live = live
        self.info = info

    def samples(self, trial: PlannedTrial) -> Iterator[tuple[float, Any, Any]]:
        return iter(self.make(trial))

    def stats(self) -> dict[str, Any] | None:
        """What a live tracker source counted so far (its ``stats()``: samples, stalls,
        pauses ...), or None for a source that counts nothing."""
        counted = getattr(self.base, "stats", None) if self.base is not None else None
        return dict(counted()) if callable(counted) else None

    def describe(self) -> dict[str, Any]:
        return {
            **self.info,
            "source": self.spec,
            "kind": "open_loop",
            "rate_hz": self.rate_hz,
            "simulated": self.simulated,
        }


def open_runner_source(spec: str, protocol: Protocol, participant: str) -> RunnerSource:
    """The source of ``--source SPEC`` for this protocol and participant."""
    from graspguide.sources.poses import SourceError, SyntheticSource, TrackerAdapter
    from graspguide.sources.source_spec import open_source

    kind, _, rest = spec.partition(":")
    seed = derive_seed(protocol.seed, "source", participant) % 2**32
    if kind == "participant":
        try:
            from graspguide.participant.model import VirtualParticipant as cls
        except ImportError as e:
            raise RunnerError(
                f"--source {spec}: the virtual participant "
                f"(graspguide.participant.model.VirtualParticipant) is not available: "
                f"{e}",
                usage=True,
            ) from None
        try:
            check_participant_keys(rest, seed=False)
            model = cls.from_spec(rest, seed)
        except (ValueError, TypeError) as e:
            raise RunnerError(f"--source {spec}: {e}", usage=True) from None
        return ClosedLoopSource(model, spec)
    if kind == "plugin":
        module_name, _, tail = rest.partition(":")
        class_name, _, arg = tail.partition(":")
        if not module_name or not class_name:
            raise RunnerError(
                "--source plugin needs a module and a class: plugin:MODULE:CLASS[:ARG]", usage=True
            )
        try:
            cls = getattr(importlib.import_module(module_name), class_name)
        except (ImportError, AttributeError) as e:
            raise RunnerError(
                f"--source {spec}: cannot load {module_name}.{class_name}: {e}", usage=True
            ) from None
        if isinstance(cls, type) and issubclass(cls, TrackerAdapter):
            adapter = cls(arg) if arg else cls()
            return OpenLoopSource(
                spec,
                lambda trial: adapter,
                adapter.rate_hz or 100.0,
                simulated=adapter.simulated,
                live=True,
                info=adapter.describe(),
            )
        try:
            model = (
                cls.from_spec(arg, seed)
                if hasattr(cls, "from_spec")
                else (cls(arg) if arg else cls())
            )
        except (ValueError, TypeError) as e:
            raise RunnerError(f"--source {spec}: {e}", usage=True) from None
        return ClosedLoopSource(model, spec)
    if kind in ("synthetic", "replay"):
        try:
            base = open_source(spec)
        except SourceError as e:
            raise RunnerError(f"--source: {e}", usage=True) from None
        if isinstance(base, SyntheticSource):
            rate = base.rate_hz if "rate=" in rest else protocol.pose_rate_hz

            def make(trial: PlannedTrial) -> SyntheticSource:
                s = SyntheticSource(
                    rate=rate,
                    duration=base.duration,
                    seed=derive_seed(base.seed, participant, trial.trial_index) % 2**32,
                    tremor_deg=base.tremor_deg,
                )
                return s.aim(
                    [list(c) for c in protocol.hands[trial.k]],
                    list(trial.wrench),
                    trial.policy,
                    protocol.constraints,
                    list(protocol.y_axis),
                )

            return OpenLoopSource(spec, make, rate, base.simulated, False, base.describe())
        return OpenLoopSource(
            spec,
            lambda trial: base,
            base.rate_hz or protocol.pose_rate_hz,
            base.simulated,
            False,
            base.describe(),
        )
    if kind in ("lsl", "natnet"):
        return _live_source(spec, protocol)
    from graspguide.sources.poses import unknown_source

    raise RunnerError(f"--source: {unknown_source(spec)}", usage=True)


def _live_source(spec: str, protocol: Protocol) -> OpenLoopSource:
    """A live tracker -- an LSL MoCap stream (graspguide.sources.lsl_inlet) or Motive's
    NatNet stream (graspguide.sources.natnet_source) -- opened once for every trial of the
    run.

    The stream runs on between trials; each trial takes its samples from its START on
    (its first sample is its t_s = 0): what the inlet or socket buffered before -- the hand
    during the rest, the ready prompt -- is dropped, as a replay restarts its file each
    trial."""
    from graspguide.sources.poses import SourceError
    from graspguide.sources.source_spec import open_source

    try:
        base = open_source(spec)
    except SourceError as e:
        raise RunnerError(f"--source: {e}", usage=True) from None

    def make(trial: PlannedTrial) -> Any:
        return _from_now(base)

    return OpenLoopSource(
        spec,
        make,
        base.rate_hz or protocol.pose_rate_hz,
        simulated=bool(base.simulated),
        live=True,
        info=base.describe(),
        base=base,
    )


def _from_now(base: Any) -> Iterator[tuple[float, Any, Any]]:
    """``base``'s samples from now on: what it buffered (an LSL inlet's queue, a NatNet
    socket's frames) is dropped when the trial asks for its first sample (after
    START_TRIAL)."""
    flush = getattr(base, "flush", None)
    if flush is None:
        flush = getattr(getattr(base, "inlet", None), "flush", None)
    if flush is not None:
        flush()
    yield from base


__all__ = [
    "RunnerSource",
    "ClosedLoopSource",
    "OpenLoopSource",
    "open_runner_source",
    "participant_keys",
    "simulation",
    "simulated_device",
    "check_participant_keys",
]
