#!/usr/bin/env bash
# The main job: set up what is missing (tools/bootstrap.sh, idempotent), then stream a
# synthetic hand to the simulated device through one guided trial (paper's 4-contact scene,
# virtual clock) and log the session under logs/. Extra arguments go to `graspguide stream`.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh" >&2
LOG="$ROOT/logs/main-$(date -u +%Y%m%dT%H%M%SZ)"
exec "$ROOT/.venv/bin/graspguide" stream --port sim --virtual-clock \
    --scene "$ROOT/tools/examples/scene_paper_4.toml" --wrench 0.4,-1,0.3 \
    --source synthetic --log "$LOG" "$@"
