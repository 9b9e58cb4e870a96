#!/usr/bin/env bash
# The main job: set up what is missing (tools/bootstrap.sh, idempotent), then
# `graspguide demo`: the paper's user study end to end, SIMULATED (the simulated device on
# a virtual clock and 8 virtual participants through protocols/paper.toml), then its
# analysis (Tables I-II beside the paper's, the trial-level ANOVA, the mixed model and
# contacts x modality; the figures and report.md in logs/demo-study/analysis/).
# Killed or interrupted, the same command resumes the study (every trial exactly once).
# Extra arguments go to `graspguide demo` (--participants, --jobs, --out, --protocol).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh" >&2
exec "$ROOT/.venv/bin/graspguide" demo --protocol "$ROOT/protocols/paper.toml" \
    --out "$ROOT/logs/demo-study" "$@"
