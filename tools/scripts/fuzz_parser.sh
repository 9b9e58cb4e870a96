#!/usr/bin/env bash
# The frame-parser harness alone: tools/scripts/fuzz.sh does the work (and fuzzes the device too).
#
#   bash tools/scripts/fuzz_parser.sh [SECONDS]      # default 60
exec bash "$(dirname "${BASH_SOURCE[0]}")/fuzz.sh" "$@" frame_parser
