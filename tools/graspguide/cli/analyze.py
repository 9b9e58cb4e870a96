"""`graspguide analyze`: the paper's tables, statistics and Figure 4 from study logs
(graspguide.analysis.study_analysis)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from graspguide.exit_codes import EXIT_OK, fail

HELP = "the paper's Tables I-III, statistics and Figure 4 from study logs"

DESCRIPTION = """\
The paper's analysis of a study's logs, and today's beside it: Table I (successes,
failures and success rate per condition), Table II (mean and SD of completion time),
Table III (NASA-TLX mean and SD, C vs V) and the paper's Tables I-II beside them; the
paper's statistics at trial level (trials paired by participant x contacts x wrench,
boxplot outliers among the successes removed with their paired trials, timeouts kept
at 90 s, square root, Shapiro-Wilk, Mauchly, repeated-measures ANOVA with
Greenhouse-Geisser where needed, Bonferroni pairwise tests, degrees of freedom
printed); a linear mixed model (participant random intercept, contacts x modality) and
a two-way contacts x modality ANOVA; the per-participant reading (participant means,
contacts pooled) with Figure 4; a trial-level figure (trials.png/.svg); a Markdown
report. docs/analysis.md says what each reading assumes.

DIR is a study folder (one folder per participant, each with trials.jsonl and
tlx.jsonl) or a participant folder; give several to pool them. Prints every reading;
writes report.md, figure4.png/.svg, trials.png/.svg and CSV tables to --out.
Simulated records make the report and the output say SIMULATED DATA. With a single
participant (a pilot), or a single one left after outlier removal, the tables, the
participant means and Figure 4 are written and the output says that the inferential
statistics (ANOVA, t-tests) need at least 2 participants. A damaged last line of a
trials.jsonl or tlx.jsonl (a run killed mid-write) is left out with a warning that says
how to record it again, and the complete records before it are analysed; report.md lists
it. A damaged line before the last is an error.

Exit status: 0 done, 1 bad or insufficient data (the message says what and where),
2 usage error.
"""

EPILOG = """\
examples:
  graspguide analyze logs/demo-study
  graspguide analyze runs/study runs/hostless --out runs/analysis
  graspguide analyze runs/pilot/U1 --keep-outliers --out runs/pilot/analysis
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "dirs", nargs="+", metavar="DIR", help="study folder(s) or participant folder(s)"
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="where to write report.md, the figures and the CSV tables "
        "(default: analysis/ in the first study folder)",
    )
    p.add_argument(
        "--keep-outliers",
        action="store_true",
        help="do not remove boxplot outliers before the ANOVAs (the paper does)",
    )


def run(args: argparse.Namespace) -> int:
    from graspguide.analysis.paper_tables import AnalysisError, default_out_dir
    from graspguide.analysis.study_analysis import analyze_study, summary_text, write_outputs

    try:
        res = analyze_study(args.dirs, remove_outliers=not args.keep_outliers)
        out = Path(args.out) if args.out else default_out_dir(args.dirs)
        written = write_outputs(res, out)
    except AnalysisError as e:
        return fail("analyze", e)
    for line in res.base.left_out:
        print(f"graspguide analyze: warning: {line}", file=sys.stderr)
    print(summary_text(res))
    print()
    print(f"Wrote {', '.join(p.name for p in written)} to {out}")
    return EXIT_OK
