#!/usr/bin/env bash
# The main job: set up what is missing (tools/bootstrap.sh, idempotent), then run
# `graspguide solve` on the example requests and print one JSON answer per request.
# Extra arguments go to `graspguide solve` (e.g. --scalar float).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh" >&2
exec "$ROOT/.venv/bin/graspguide" solve --input "$ROOT/tools/examples/solve_requests.jsonl" "$@"
