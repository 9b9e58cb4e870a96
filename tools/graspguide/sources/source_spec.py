"""``--source SPEC`` to a :class:`~graspguide.sources.poses.Source`: the one place that
knows every kind of source. It sits apart from :mod:`graspguide.sources.poses` because the
tracker sources (LSL, NatNet, XDF replay) build on the base classes there, so the
dispatch over them cannot live beside those classes without an import cycle."""

from __future__ import annotations

from graspguide.sources.poses import (
    SYNTHETIC_OPTIONS,
    ReplaySource,
    Source,
    SourceError,
    SyntheticSource,
    open_plugin,
    tracker_convention,
    unknown_source,
)


def open_source(spec: str, tracker: str | None = None) -> Source:
    """A Source from ``replay:FILE.csv``, ``synthetic[:rate=..,duration=..,seed=..]`` or
    ``plugin:MODULE:CLASS[:ARG]``. ``tracker`` (a preset name or UNITS/UP/HANDEDNESS/ORDER)
    says in which convention a replay file is written."""
    kind, _, rest = spec.partition(":")
    if tracker is not None and kind not in ("replay", "lsl", "natnet"):
        raise SourceError(
            f"--tracker only applies to replay, lsl and natnet sources (a plugin "
            f"declares its own convention), not to {kind!r}"
        )
    convention = tracker_convention(tracker) if tracker else None
    if kind == "replay":
        if not rest:
            raise SourceError("replay needs a file: --source replay:FILE.csv or FILE.xdf")
        if rest.partition("#")[0].lower().endswith(".xdf"):  # FILE.xdf#name=STREAM
            from graspguide.sources.xdf_replay import XdfReplaySource

            return XdfReplaySource(rest, convention)
        return ReplaySource(rest, convention)
    if kind == "lsl":
        from graspguide.sources.lsl_inlet import open_lsl_source

        return open_lsl_source(rest, convention)
    if kind == "natnet":
        from graspguide.sources.natnet_source import open_natnet_source

        return open_natnet_source(rest, convention)
    if kind == "plugin":
        return open_plugin(rest)
    if kind == "synthetic":
        from graspguide.core.suggest import did_you_mean

        kw: dict[str, float] = {}
        conv = SYNTHETIC_OPTIONS
        for item in filter(None, rest.split(",")):
            key, eq, value = item.partition("=")
            key = key.strip()
            if not eq or key not in conv:
                raise SourceError(
                    f"synthetic: bad option {item!r}{did_you_mean(key, conv)}; options are "
                    f"{', '.join(k + '=N' for k in conv)}"
                )
            try:
                kw[key] = conv[key](value)
            except ValueError:
                raise SourceError(f"synthetic: {key} must be a number, got {value!r}") from None
        return SyntheticSource(**kw)  # type: ignore[arg-type]
    raise unknown_source(spec)


__all__ = ["open_source"]
