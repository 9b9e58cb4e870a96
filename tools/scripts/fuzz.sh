#!/usr/bin/env bash
# Fuzzes the link and the device with libFuzzer (+ASan, +UBSan), one harness after another:
#   frame_parser  test/fuzz/fuzz_frame_parser.cpp: any bytes into FrameParser and the decoders
#   device        test/fuzz/fuzz_device.cpp: requests (host-less ones too), field values,
#                 garbage, clock jumps and store faults into LinkDevice, Application and the
#                 host-less runner on an in-memory store, checked against the safety invariants
#
#   bash tools/scripts/fuzz.sh [SECONDS] [HARNESS...]   # SECONDS per harness (default 60),
#                                                        # every harness by default
#
# Builds each harness with clang, seeds it (golden frames; the device harness writes its own
# seeds: a scene, trials, poses, time jumps, host-less runs, store faults), runs it for
# SECONDS and prints
#   fuzz <name>: N inputs run, M crashes in S s
# A crash does not end the run (-fork=1 -ignore_crashes=1), so one run shows every finding it
# reaches; each distinct finding (invariant or sanitizer message) is listed with its smallest
# reproducer. Exits 1 if any harness crashed. Installs Debian's clang and its libFuzzer
# runtime when they are missing. Not part of tools/run-tests.sh: it is too slow for every run.
# Corpora stay in build/fuzz/<name>/corpus, so later runs go on where earlier ones stopped.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"

ALL_HARNESSES=(frame_parser device)
BUDGET_S=60
HARNESSES=()
usage() { echo "usage: $0 [SECONDS] [${ALL_HARNESSES[*]}]" >&2; exit 2; }
for arg in "$@"; do
    if [[ $arg =~ ^[0-9]+$ && $arg -gt 0 ]]; then
        BUDGET_S=$arg
    elif [[ " ${ALL_HARNESSES[*]} " == *" $arg "* ]]; then
        HARNESSES+=("$arg")
    else
        usage
    fi
done
((${#HARNESSES[@]})) || HARNESSES=("${ALL_HARNESSES[@]}")

OUT="$ROOT/build/fuzz"
FLAGS=(-std=c++17 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined
       -fno-sanitize-recover=undefined -Wall -Wextra)
# Crash inputs replayed to name their finding, smallest first: enough to see every kind.
MAX_CLASSIFIED=100

say() { printf 'fuzz: %s\n' "$*"; }
die() { printf 'fuzz: ERROR: %s\n' "$*" >&2; exit 2; }
rel() { realpath --relative-to="$ROOT" "$1"; }

mkdir -p "$OUT"

# --- clang with libFuzzer ---------------------------------------------------------------------
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

# --- per harness: sources, include folders, input size, seeds ------------------------------------
harness_sources() {
    case $1 in
        frame_parser) echo test/fuzz/fuzz_frame_parser.cpp ;;
        device) echo test/fuzz/fuzz_device.cpp lib/graspguide/src/*.cpp ;;
    esac
}
harness_includes() {
    case $1 in
        frame_parser) echo -Ilib/graspguide_link/src ;;
        device) echo -Ilib/graspguide/src -Ilib/graspguide_cue/src -Ilib/graspguide_link/src -Ilib/graspguide_hal/src -Ilib/graspguide_device/src \
                     -Itest -I/usr/include/eigen3 ;;
    esac
}
# Parser: several largest frames back to back. Device: a session of a few hundred requests.
harness_max_len() { case $1 in frame_parser) echo 1024 ;; device) echo 4096 ;; esac; }

write_seeds() {  # name bin seeds_dir
    case $1 in
        frame_parser)
            python3 - "$ROOT/test/data/golden_frames.json" "$3" <<'EOF'
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
            ;;
        device)
            [[ -f /usr/include/eigen3/Eigen/Core ]] || die "Eigen is missing: apt-get install libeigen3-dev"
            GRASPGUIDE_FUZZ_WRITE_SEEDS="$3" "$2" >/dev/null
            ;;
    esac
}

# Rebuilds when a source, a library header or this script is newer than the binary.
build() {  # name bin obj_dir
    local name=$1 bin=$2 obj=$3 src srcs includes pids=() failed=0
    read -r -a srcs <<<"$(harness_sources "$name")"
    read -r -a includes <<<"$(harness_includes "$name")"
    if [[ -x $bin ]] && [[ -z $(find "${srcs[@]}" lib test/common "${BASH_SOURCE[0]}" -newer "$bin" -print -quit) ]]; then
        say "$(rel "$bin") is up to date"
        return
    fi
    say "building $(rel "$bin") with $(clang++ --version | head -n1)"
    rm -rf "$obj"
    mkdir -p "$obj"
    for src in "${srcs[@]}"; do  # the machine's cores compile the sources side by side
        clang++ "${FLAGS[@]}" -fsanitize=fuzzer-no-link "${includes[@]}" -c "$src" \
            -o "$obj/$(basename "$src" .cpp).o" &
        pids+=($!)
    done
    for pid in "${pids[@]}"; do wait "$pid" || failed=1; done
    ((failed == 0)) || die "compiling $name failed"
    clang++ "${FLAGS[@]}" -fsanitize=fuzzer "$obj"/*.o -o "$bin"
}

# The finding a crash input shows: the harness's invariant, else the sanitizer's summary.
finding_of() {  # bin artifact
    local log
    log="$(timeout 120 "$1" "$2" 2>&1 || true)"
    grep -m1 -o 'invariant violated: .*' <<<"$log" ||
        grep -m1 '^SUMMARY: ' <<<"$log" | grep -v 'deadly signal' ||
        grep -m1 -o 'ERROR: libFuzzer: .*' <<<"$log" ||
        echo "unclassified (see $(rel "$2"))"
}

run() {  # name
    local name=$1 dir="$OUT/$1" bin="$OUT/$1/fuzz_$1"
    local seeds="$dir/seeds" corpus="$dir/corpus" artifacts="$dir/artifacts" log="$dir/fuzz.log"
    mkdir -p "$dir" "$corpus"
    build "$name" "$bin" "$dir/obj"
    rm -rf "$seeds" "$artifacts"
    mkdir -p "$seeds" "$artifacts"
    write_seeds "$name" "$bin" "$seeds"

    say "running $name for ${BUDGET_S} s (log: $(rel "$log"))"
    local start_s rc elapsed_s runs crashes
    start_s=$(date +%s)
    set +e
    "$bin" -fork=1 -ignore_crashes=1 -max_total_time="$BUDGET_S" -max_len="$(harness_max_len "$name")" \
        -timeout=30 -print_final_stats=1 -artifact_prefix="$artifacts/" "$corpus" "$seeds" >"$log" 2>&1
    rc=$?
    set -e
    elapsed_s=$(( $(date +%s) - start_s ))

    # Fork mode reports "#N: cov ..." lines (N = inputs run by every job); a plain run also
    # prints stat::number_of_executed_units.
    runs="$(sed -n 's/^stat::number_of_executed_units: *\([0-9]*\).*/\1/p' "$log" | tail -n1)"
    [[ -n $runs ]] || runs="$(sed -n 's/^#\([0-9][0-9]*\).*/\1/p' "$log" | tail -n1)"
    crashes="$(find "$artifacts" -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' \
        -o -name 'oom-*' \) | wc -l)"
    if ((rc != 0 && crashes == 0)); then
        crashes=1  # the fuzzer died without leaving an artifact: still a failure
        tail -n 20 "$log"
    fi
    echo "fuzz $name: ${runs:-0} inputs run, $crashes crashes in $elapsed_s s"
    if ((crashes > 0)); then
        local a f i=0
        declare -A count=() smallest=()
        while read -r _ a; do
            ((i++ < MAX_CLASSIFIED)) || break
            f="$(finding_of "$bin" "$a")"
            count[$f]=$(( ${count[$f]:-0} + 1 ))
            [[ -n ${smallest[$f]:-} ]] || smallest[$f]=$a
        done < <(find "$artifacts" -type f -printf '%s %p\n' | sort -n)
        ((crashes <= MAX_CLASSIFIED)) || say "the $MAX_CLASSIFIED smallest of $crashes crash inputs, by finding:"
        for f in "${!count[@]}"; do
            echo "  ${count[$f]} x $f"
            echo "      reproduce: $(rel "$bin") $(rel "${smallest[$f]}")"
        done
        [[ $name != device ]] ||
            say "GRASPGUIDE_FUZZ_TRACE=1 before a reproduce command prints every request and answer"
        return 1
    fi
}

status=0
for h in "${HARNESSES[@]}"; do
    run "$h" || status=1
done
exit $status
