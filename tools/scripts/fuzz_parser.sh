#!/usr/bin/env bash
# Fuzzes the link's FrameParser and generated decoders with libFuzzer (+ASan, +UBSan).
#
#   bash tools/scripts/fuzz_parser.sh [SECONDS]      # default 60
#
# Builds test/fuzz/fuzz_frame_parser.cpp with clang, seeds it with the golden frames
# (test/data/golden_frames.json), runs it for SECONDS, and prints
#   fuzz: N inputs run, M crashes in S s
# Exits non-zero on a crash (the reproducer is in build/fuzz/artifacts/). Installs
# Debian's clang and its libFuzzer runtime when they are missing. Not part of
# tools/run-tests.sh: it is too slow for every run.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"

DEFAULT_BUDGET_S=60
BUDGET_S="${1:-$DEFAULT_BUDGET_S}"
[[ $BUDGET_S =~ ^[0-9]+$ && $BUDGET_S -gt 0 ]] || { echo "usage: $0 [SECONDS]" >&2; exit 2; }
# Long enough for several largest frames back to back, short enough to stay fast.
MAX_INPUT_BYTES=1024

OUT="$ROOT/build/fuzz"
BIN="$OUT/fuzz_frame_parser"
SEEDS="$OUT/seeds"
CORPUS="$OUT/corpus"
ARTIFACTS="$OUT/artifacts"
LOG="$OUT/fuzz.log"
SRC="$ROOT/test/fuzz/fuzz_frame_parser.cpp"
GOLDEN="$ROOT/test/data/golden_frames.json"
FLAGS=(-std=c++17 -O1 -g -fno-omit-frame-pointer -fsanitize=fuzzer,address,undefined
       -fno-sanitize-recover=undefined -Wall -Wextra -I"$ROOT/lib/graspguide_link/src")

say() { printf 'fuzz_parser: %s\n' "$*"; }
die() { printf 'fuzz_parser: ERROR: %s\n' "$*" >&2; exit 2; }

mkdir -p "$OUT" "$SEEDS" "$CORPUS"

# --- clang with libFuzzer -------------------------------------------------------------
can_build() {
    command -v clang++ >/dev/null 2>&1 &&
        printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }\n' |
        clang++ -x c++ -fsanitize=fuzzer,address,undefined - -o "$OUT/probe" >/dev/null 2>&1
}
if ! can_build; then
    SUDO=()
    if [[ $(id -u) -ne 0 ]]; then
        command -v sudo >/dev/null 2>&1 || die "clang with libFuzzer is missing and there is no root/sudo to install it"
        SUDO=(sudo)
    fi
    export DEBIAN_FRONTEND=noninteractive
    say "installing Debian's clang"
    "${SUDO[@]}" apt-get update -qq
    "${SUDO[@]}" apt-get install -y -qq --no-install-recommends clang >/dev/null
    major="$(clang++ --version | sed -n 's/.*clang version \([0-9]*\).*/\1/p' | head -n1)"
    if ! can_build; then
        say "installing libclang-rt-$major-dev (libFuzzer runtime)"
        "${SUDO[@]}" apt-get install -y -qq --no-install-recommends "libclang-rt-$major-dev" >/dev/null
    fi
    can_build || die "clang++ cannot link -fsanitize=fuzzer (libFuzzer runtime missing)"
fi
rm -f "$OUT/probe"

# --- build ------------------------------------------------------------------------------
say "building $(realpath --relative-to="$ROOT" "$BIN") with $(clang++ --version | head -n1)"
clang++ "${FLAGS[@]}" "$SRC" -o "$BIN"

# --- seed corpus from the golden frames ---------------------------------------------------
python3 - "$GOLDEN" "$SEEDS" <<'EOF'
import json, os, sys
frames = json.load(open(sys.argv[1], encoding="utf-8"))["frames"]
out = sys.argv[2]
wires = [bytes.fromhex(f["hex"]) for f in frames]
for f, w in zip(frames, wires):
    open(os.path.join(out, f["name"]), "wb").write(w)
# Every frame back to back, and garbage before a frame: the parser's usual day.
open(os.path.join(out, "all_back_to_back"), "wb").write(b"".join(wires))
open(os.path.join(out, "garbage_then_frame"), "wb").write(b"\x13\x37\xff\x00" + wires[1])
EOF

# --- run ------------------------------------------------------------------------------
rm -rf "$ARTIFACTS"
mkdir -p "$ARTIFACTS"
say "running for ${BUDGET_S} s (log: $(realpath --relative-to="$ROOT" "$LOG"))"
start_s=$(date +%s)
set +e
"$BIN" -max_total_time="$BUDGET_S" -max_len="$MAX_INPUT_BYTES" -print_final_stats=1 \
    -artifact_prefix="$ARTIFACTS/" "$CORPUS" "$SEEDS" >"$LOG" 2>&1
rc=$?
set -e
elapsed_s=$(( $(date +%s) - start_s ))

runs="$(sed -n 's/^stat::number_of_executed_units: *\([0-9]*\).*/\1/p' "$LOG" | tail -n1)"
if [[ -z $runs ]]; then  # a crash can cut the final stats short: take the last status line
    runs="$(sed -n 's/^#\([0-9][0-9]*\).*/\1/p' "$LOG" | tail -n1)"
fi
crashes="$(find "$ARTIFACTS" -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' \
    -o -name 'oom-*' \) | wc -l)"
if ((rc != 0 && crashes == 0)); then
    crashes=1  # the fuzzer died without leaving an artifact: still a failure
fi
tail -n 5 "$LOG"
echo "fuzz: ${runs:-0} inputs run, $crashes crashes in $elapsed_s s"
if ((crashes > 0)); then
    say "reproduce with: $BIN <artifact>   (artifacts in $ARTIFACTS)"
    exit 1
fi
