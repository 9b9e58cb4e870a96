"""The names a user types and a log records, defined once: the force policy, the intensity
mode, the constraint model and the fingers (docs/algorithm.md). Every parser, file reader
and enum mapping takes them from here."""

from __future__ import annotations

POLICIES = ("F", "Fperp")
"""The cue policy: F renders |lambda_i|, Fperp its component normal to the finger pad."""

MODES = ("C", "V")
"""The intensity mode: C constant, V proportional to the error (alpha)."""

CONSTRAINT_MODELS = ("paper", "normal", "none")
"""The displayability constraint of the QP, from the strictest to none."""

FINGERS = ("thumb", "index", "middle", "palm")
"""The contact points, in the order of the motors and of the scene file's contacts."""


def modality(policy: str, mode: str) -> str:
    """The condition's name in the paper's tables, e.g. ``"Fperp+C"``."""
    return f"{policy}+{mode}"


MODALITIES = tuple(modality(policy, mode) for mode in MODES for policy in POLICIES)
"""The four conditions, in the order of the study protocol and the statistics:
F+C, Fperp+C, F+V, Fperp+V."""

PERP_SHOWN = "F⊥"
"""How every figure writes the policy Fperp (the paper's F with the perpendicular sign);
files, logs and the command line keep the ASCII name."""


def shown(name: str) -> str:
    """A policy or modality name as figures print it: ``"Fperp+C"`` -> ``"F⊥+C"``."""
    return name.replace("Fperp", PERP_SHOWN)
