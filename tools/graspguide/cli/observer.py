"""`graspguide observer`: the ideal-observer bounds of a study protocol, SIMULATED
(graspguide.participant.ideal_observer)."""

from __future__ import annotations

import argparse

from graspguide.cli.common import add_protocol_argument, int_arg

HELP = "ideal-observer bounds: how much success the cue allows per condition (SIMULATED)"

DESCRIPTION = """\
The ideal-observer bounds of a study protocol, SIMULATED (model bounds, never human
data): for every contact count and modality of the protocol, an upper bound on the
success rate of any observer who knows Algorithm 1, the hand and the protocol's wrench
prior, but not the trial's wrench. Mode C: the posterior mass of the best region a
search can cover within the timeout, given which motors are on ("on/off") and given the
levels read once with log-normal noise of SD --weber ("intensity", the bound). Mode V:
the bound is 1 (the intensity tells the error at every pose); beside it, what an
explicit trilaterating observer achieves in the timeout.

Draws --n-prior wrenches from the protocol's prior and --n-trials more (seeded by
--seed), runs the real core on each, and prints a Markdown table; --per-wrench adds the
masses of the protocol's own wrench set; --out writes the same as a Markdown file.
The estimate errs upward with a small prior sample (the safe side for an upper bound):
the figures in docs/ideal-observer.md use --n-prior 100000 --n-trials 1000 (about 50 s
on 2 cores). Definitions and assumptions: docs/ideal-observer.md.

Exit status: 0 done, 1 the --out file cannot be written, 2 usage error or a protocol
file that cannot be used.
"""

EPILOG = """\
examples:
  graspguide observer
  graspguide observer --n-prior 100000 --n-trials 1000 --per-wrench
  graspguide observer --protocol protocols/paper-moments-drawn.toml --out bounds.md
  graspguide observer --weber 0.1 --seed 2
"""


def weber_arg(text: str) -> float:
    """An argparse type: a Weber fraction in (0, 5]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value <= 5:  # NaN fails
        raise argparse.ArgumentTypeError(f"must be in (0, 5], got {value}")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_protocol_argument(p, required=False)
    p.add_argument(
        "--n-prior",
        type=int_arg(10, 10_000_000),
        default=20000,
        metavar="N",
        help="wrenches drawn from the prior for the posterior (default 20000)",
    )
    p.add_argument(
        "--n-trials",
        type=int_arg(1, 1_000_000),
        default=500,
        metavar="N",
        help="further draws the expected bound averages over (default 500)",
    )
    p.add_argument(
        "--seed", type=int_arg(0, 2**63 - 1), default=1, metavar="N", help="seed (default 1)"
    )
    p.add_argument(
        "--weber",
        type=weber_arg,
        default=0.3,
        metavar="SD",
        help="SD of the log-intensity reading of each motor (default 0.3, the fingertip's "
        "amplitude Weber fraction)",
    )
    p.add_argument(
        "--per-wrench",
        action="store_true",
        help="also the mode-C masses of each wrench of the protocol's wrench set",
    )
    p.add_argument(
        "--out",
        "--markdown",
        dest="out",
        default=None,
        metavar="FILE",
        help="also write the report as a Markdown file",
    )


def run(args: argparse.Namespace) -> int:
    from graspguide.participant import ideal_observer

    return ideal_observer.run(
        protocol=args.protocol,
        seed=args.seed,
        n_prior=args.n_prior,
        n_trials=args.n_trials,
        weber=args.weber,
        per_wrench=args.per_wrench,
        out=args.out,
    )
