#!/usr/bin/env bash
# GraspGuide test run. Two tiers (`bash tools/run-tests.sh --help` lists them):
#   full (no option; what .ci/run executes):
#   1. tools/bootstrap.sh        (Debian packages, Eigen check, .venv, ./tools)
#   2. tools/scripts/check_style.sh  (ruff lint and format, mypy, clang-format, every
#      generator's --check, the import layers; each is 1 case)
#   3. pio test -e native        (GoogleTest suites in test/test_*/, offline), and the
#      Arduino board compiled on the host against a stub of the Arduino API (1 case)
#   4. tools/install-arm.sh      (ARM toolchain and QEMU, installed once), then
#      pio run -e cortex_m4f, m4f_firmware, m4f_stages, m7_stages, m7_stages_double, m4f_imu and the QEMU
#      stage counts vs tools/perf/stage_baseline.json (each is 1 case), and the
#      per-frame layer's cycles on the ATmega328P under simavr (1 case)
#   5. pytest tools/tests        (if that directory exists; its QEMU firmware test
#      runs the m4f_firmware image of step 4)
#   --fast: steps 1, 2, the native GoogleTest suites of step 3 and the pytest tests not
#      marked `cross` or `slow` (tools/tests/conftest.py says which are): no cross
#      toolchain, emulator or simulator of another CPU, and no Arduino stub compile.
#      It says that it is the fast tier and how many tests it left out.
# Output of every stage goes to the console. Test cases are counted from
# machine-readable reports (PlatformIO's JSON report, pytest's JUnit XML), and
# the run ends with exactly one line "N passed, N failed, N skipped".
# A check that cannot run prints "SKIPPED: <what> (<why>)" and counts as skipped,
# pytest's skips included: no skip is silent. With CI=true (.ci/run sets it) a
# firmware check that cannot run is a failure, and so is every pytest skip but the
# hardware tests' (tools/tests/conftest.py). GRASPGUIDE_NO_ARM=1 leaves the ARM
# toolchain out (its checks are then skipped, or failed under CI).
# A stage that errors (bootstrap failure, build error, crashing test program,
# pytest collection error, ...) always counts as at least one failure, and
# the script exits non-zero if anything failed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

usage() {
    cat <<'EOF'
usage: bash tools/run-tests.sh [--fast] [--help]

The test command, in two tiers. Both end with one line "N passed, N failed, N skipped"
and exit non-zero if anything failed.

  (no option)  the full run, what .ci/run calls (with CI=true: no check may skip):
               bootstrap, style checks, pio test -e native, the Arduino board compiled
               against a stub of the Arduino API, the ARM builds and their stage counts
               under QEMU, the per-frame layer under simavr, and every pytest test in
               tools/tests.
  --fast       the developer's loop (about 3 minutes with warm builds): bootstrap, style
               checks, pio test -e native and the pytest tests that are not marked
               `cross` (they launch QEMU, arm-none-eabi, avr-gcc or simavr, arduino-cli
               or mpy-cross) or `slow` (tools/tests/conftest.py marks them). It leaves
               out the Arduino stub compile, the ARM and AVR builds, and says how many
               pytest tests it left out.
  --help       this text.

One room's Python tests:  .venv/bin/python -m pytest tools/tests/<room>
Only the fast ones:       .venv/bin/python -m pytest tools/tests -m "not cross and not slow"
EOF
}

FAST=0
for arg in "$@"; do
    case $arg in
        --fast) FAST=1 ;;
        -h | --help)
            usage
            exit 0
            ;;
        *)
            echo "run-tests: unknown option '$arg'" >&2
            usage >&2
            exit 2
            ;;
    esac
done
# The pytest tests the fast tier leaves out (markers registered in tools/pyproject.toml).
FAST_DESELECT="cross or slow"

PASSED=0
FAILED=0
SKIPPED=0
STAGE_ERRORS=()

REPORT_DIR="$(mktemp -d "${TMPDIR:-/tmp}/graspguide-tests.XXXXXX")"
trap 'rm -rf "$REPORT_DIR"' EXIT

banner() { printf '\n===== %s =====\n' "$*"; }

finish() {
    echo
    if ((${#STAGE_ERRORS[@]})); then
        printf 'run-tests: stage error: %s\n' "${STAGE_ERRORS[@]}"
    fi
    if ((FAST)); then
        echo "run-tests: FAST TIER, not the full run: left out the Arduino stub compile," \
            "the ARM builds, QEMU and simavr, and ${FAST_LEFT_OUT:-no} pytest tests" \
            "(marked $FAST_DESELECT); the full run is bash tools/run-tests.sh"
    fi
    echo "$PASSED passed, $FAILED failed, $SKIPPED skipped"
    if ((FAILED > 0 || ${#STAGE_ERRORS[@]} > 0)); then
        exit 1
    fi
    exit 0
}

# One command as one test case: its output on the console and in $REPORT_DIR/LOG.log,
# passed when it exits 0.   run_case TITLE LOG COMMAND...
run_case() {
    local title=$1 log=$2 rc
    shift 2
    banner "$title: $*"
    set +e
    "$@" 2>&1 | tee "$REPORT_DIR/$log.log"
    rc=${PIPESTATUS[0]}
    set -e
    if ((rc == 0)); then
        echo "run-tests: $title: 1 passed, 0 failed"
        PASSED=$((PASSED + 1))
    else
        echo "run-tests: $title: 0 passed, 1 failed (exit code $rc)"
        FAILED=$((FAILED + 1))
    fi
}

is_ci() { [[ ${CI:-} =~ ^(1|[Tt]rue|TRUE|[Yy]es)$ ]]; }

# A check that cannot run.   skip_check WHAT WHY
skip_check() {
    echo "SKIPPED: $1 ($2)"
    SKIPPED=$((SKIPPED + 1))
}

# A firmware check that cannot run: skipped, but failed under CI, which promises that
# every firmware image is built and run.   firmware_unavailable WHAT WHY
firmware_unavailable() {
    if is_ci; then
        echo "FAILED: $1 ($2; CI=true never skips the firmware)"
        FAILED=$((FAILED + 1))
    else
        skip_check "$1" "$2"
    fi
}

# --- 1. bootstrap --------------------------------------------------------------
banner "bootstrap"
if ! bash "$ROOT/tools/bootstrap.sh"; then
    STAGE_ERRORS+=("bootstrap failed")
    FAILED=$((FAILED + 1))
    finish
fi
PY="$ROOT/.venv/bin/python"

# A "SKIPPED: ..." line per skipped case, then "PASSED FAILED(+ERRORED) SKIPPED", of a
# PlatformIO JSON test report.
count_pio_report() {
    "$PY" - "$1" <<'EOF'
import json, sys
data = json.load(open(sys.argv[1], encoding="utf8"))
passed = failed = skipped = 0
for suite in data.get("test_suites", []):
    for case in suite.get("test_cases", []):
        status = case.get("status")
        if status == "PASSED":
            passed += 1
        elif status in ("FAILED", "ERRORED"):
            failed += 1
        elif status == "SKIPPED":
            skipped += 1
            why = " ".join((case.get("message") or "no reason given").split())
            print(f"SKIPPED: pio {suite.get('test_name', '?')}: {case.get('name')} ({why})")
print(passed, failed, skipped)
EOF
}

# The same for a pytest JUnit XML report.
count_junit_report() {
    "$PY" - "$1" <<'EOF'
import sys
import xml.etree.ElementTree as ET
passed = failed = skipped = 0
for case in ET.parse(sys.argv[1]).getroot().iter("testcase"):
    kinds = {child.tag for child in case}
    if kinds & {"failure", "error"}:
        failed += 1
    elif "skipped" in kinds:
        skipped += 1
        why = " ".join((case.find("skipped").get("message") or "no reason given").split())
        print(f"SKIPPED: pytest {case.get('classname')}::{case.get('name')} ({why})")
    else:
        passed += 1
print(passed, failed, skipped)
EOF
}

# read_report COUNT_FUNCTION REPORT: its SKIPPED lines to the console, "P F S" to COUNTS.
read_report() {
    local out
    out="$("$@")" || return 1
    sed '$d' <<<"$out"
    COUNTS="$(tail -n 1 <<<"$out")"
}

# Adds a stage's report to the totals. A stage that exits non-zero with no failed case in
# its report (bad configuration, crash, collection error) still counts as one failure:
# never "0 failed".   tally LABEL EXIT_CODE REPORT COUNT_FUNCTION
tally() {
    local label=$1 rc=$2 report=$3 count=$4 p=0 f=0 s=0
    if [[ -s $report ]] && read_report "$count" "$report"; then
        read -r p f s <<<"$COUNTS"
    else
        STAGE_ERRORS+=("$label wrote no readable report (exit code $rc)")
    fi
    if ((rc != 0 && f == 0)); then
        STAGE_ERRORS+=("$label exited with code $rc")
        f=1
    fi
    echo "run-tests: $label: $p passed, $f failed, $s skipped"
    PASSED=$((PASSED + p))
    FAILED=$((FAILED + f))
    SKIPPED=$((SKIPPED + s))
}

# --- 2. style and generated code ---------------------------------------------------
# The habits, enforced: each check of tools/scripts/check_style.sh is one case.
for check in ruff-lint ruff-format mypy clang-format generated import-layers; do
    run_case "style: $check" "style-$check" bash "$ROOT/tools/scripts/check_style.sh" "$check"
done

# --- 3. PlatformIO / GoogleTest ------------------------------------------------
banner "pio test -e native"
export PLATFORMIO_CORE_DIR="$ROOT/.pio-core"
export PLATFORMIO_DISABLE_UPGRADE_CHECK=true
export PLATFORMIO_SETTING_ENABLE_TELEMETRY=No
# pio treats every folder named test_* below test/ (nested too) as a suite and
# errors out ("Nothing to build") when there is none: skip it in that case.
if [[ -z $(find "$ROOT/test" -mindepth 1 -type d -name 'test_*' -print -quit 2>/dev/null) ]]; then
    echo "run-tests: no GoogleTest suites (test/**/test_*/), skipping pio: 0 test cases"
else
    pio_json="$REPORT_DIR/pio-report.json"
    set +e
    "$ROOT/.venv/bin/pio" test -e native --json-output-path "$pio_json" 2>&1 | tee "$REPORT_DIR/pio.log"
    pio_rc=${PIPESTATUS[0]}
    set -e
    tally pio/GoogleTest "$pio_rc" "$pio_json" count_pio_report
fi

ARM_ENVS=(cortex_m4f m4f_firmware m4f_stages m7_stages m7_stages_double m4f_imu)
# The firmware that --port qemu runs builds into a folder of its own
# (graspguide.devices.builds), as its launcher looks for it there: pio deletes its whole
# build folder when its project checksum changes, and the others' builds must not take
# this one with them.
DEVICE_ENVS=" m4f_firmware "

# The firmware checks: none of them is in the fast tier.
if ((FAST)); then
    echo
    echo "run-tests: fast tier: leaving out the Arduino stub compile, the ARM builds, QEMU and simavr"
else
    # The Arduino board (src/boards/arduino) cannot be built for its real cores here (their
    # toolchains are not obtainable offline); it is compiled and linked on the host against a
    # minimal stub of the Arduino API (src/harness/arduino_api_check), once per board variant.
    # That proves it compiles, not that it runs.
    run_case "Arduino board compile check (host, Arduino API stub)" arduino_check \
        "$ROOT/.venv/bin/pio" run -e arduino_check_generic -e arduino_check_featheresp32 \
        -e arduino_check_teensy40 -e arduino_check_featheresp32_bno055

    # --- 4. Bare-metal ARM builds and QEMU runs -----------------------------------------
    # Before pytest, because its QEMU firmware test needs the m4f_firmware image. Each build
    # is one test case; the stage counts under QEMU (and their check against
    # tools/perf/stage_baseline.json) are one more. The toolchain and QEMU (about 400 MB)
    # are installed here, not by bootstrap.sh, so that tools/run-main.sh does without them.
    arm_why=""
    if [[ -n ${GRASPGUIDE_NO_ARM:-} ]]; then
        arm_why="GRASPGUIDE_NO_ARM is set"
    else
        banner "ARM toolchain and QEMU: tools/install-arm.sh"
        if ! bash "$ROOT/tools/install-arm.sh"; then
            arm_why="tools/install-arm.sh failed, see above"
        elif ! command -v arm-none-eabi-g++ >/dev/null 2>&1; then
            arm_why="arm-none-eabi-g++ not on PATH after tools/install-arm.sh"
        fi
    fi
    for env in "${ARM_ENVS[@]}"; do
        if [[ -z $arm_why && $DEVICE_ENVS == *" $env "* ]]; then
            run_case "$env build" "$env" env PLATFORMIO_BUILD_DIR="$ROOT/.pio/build-$env" \
                "$ROOT/.venv/bin/pio" run -e "$env"
        elif [[ -z $arm_why ]]; then
            run_case "$env build" "$env" "$ROOT/.venv/bin/pio" run -e "$env"
        else
            firmware_unavailable "pio run -e $env" "$arm_why"
        fi
    done
    qemu_why=$arm_why
    if [[ -z $qemu_why ]] && ! command -v qemu-system-arm >/dev/null 2>&1; then
        qemu_why="qemu-system-arm not on PATH after tools/install-arm.sh"
    fi
    if [[ -z $qemu_why ]]; then
        # It runs `pio run` on the three images first (seconds when they are up to date): an
        # image left over from before a failed build is never the one counted.
        run_case "QEMU stage counts within baseline" qemu_stages \
            "$ROOT/.venv/bin/graspguide" bench --target m4f --target m7 --target m7d \
            --json "$REPORT_DIR/qemu_stages.json"
    else
        firmware_unavailable "QEMU stage counts (graspguide bench --target m4f --target m7 --target m7d)" "$qemu_why"
    fi
    if [[ -z $qemu_why ]]; then
        # The gravity estimator's instructions per update (host-less mode), and that the image's
        # estimate tracked its stream.
        run_case "QEMU gravity-estimator cost" imu_cost \
            "$ROOT/.venv/bin/python" "$ROOT/tools/scripts/imu_cost.py" --no-build \
            --json "$REPORT_DIR/imu_cost.json"
    else
        firmware_unavailable "QEMU gravity-estimator cost (tools/scripts/imu_cost.py)" "$qemu_why"
    fi

    # The per-frame layer on the paper's ATmega328P, built with Debian's gcc-avr (installed by
    # bootstrap.sh with avr-libc and simavr) and run cycle-exact under simavr: cycles against
    # tools/perf/avr_baseline.json, PWM against the float64 reference (1 case).
    avr_why=""
    for tool in avr-g++ avr-size avr-nm; do
        if [[ -z $avr_why ]] && ! command -v "$tool" >/dev/null 2>&1; then
            avr_why="$tool not on PATH after tools/bootstrap.sh (Debian's gcc-avr)"
        fi
    done
    if [[ -z $avr_why && ! -f /usr/include/simavr/sim_avr.h ]]; then
        avr_why="simavr's headers missing after tools/bootstrap.sh (Debian's libsimavr-dev)"
    fi
    if [[ -z $avr_why ]]; then
        run_case "AVR per-frame layer within baseline" avr_frame \
            "$ROOT/.venv/bin/graspguide" bench --target avr --json "$REPORT_DIR/avr_frame.json"
    else
        firmware_unavailable "AVR per-frame layer (graspguide bench --target avr)" "$avr_why"
    fi
fi

# --- 5. pytest -----------------------------------------------------------------
if [[ -d $ROOT/tools/tests ]]; then
    banner "pytest tools/tests"
    junit="$REPORT_DIR/pytest-junit.xml"
    set +e
    # OpenBLAS's oldest x86-64 kernel, not the one this CPU picks: an expected value that
    # came from numpy linear algebra on the author's CPU then fails here too, not only on
    # a newcomer's machine (the golden closed loops of test_participant.py once did).
    # test_participant.py also runs the participant under both kernels and compares.
    # The fast tier deselects the tests marked cross or slow (-m); pytest counts them.
    select=()
    ((FAST)) && select=(-m "not ($FAST_DESELECT)")
    OPENBLAS_CORETYPE=Prescott "$PY" -m pytest tools/tests -q "${select[@]}" --junitxml="$junit" 2>&1 |
        tee "$REPORT_DIR/pytest.log"
    py_rc=${PIPESTATUS[0]}
    set -e
    if ((FAST)); then
        FAST_LEFT_OUT="$(grep -Eo '[0-9]+ deselected' "$REPORT_DIR/pytest.log" | tail -n 1 | cut -d' ' -f1)"
    fi
    if ((py_rc == 5)); then
        echo "run-tests: pytest collected no tests: 0 test cases"
    else
        tally pytest "$py_rc" "$junit" count_junit_report
    fi
else
    echo
    echo "run-tests: no tools/tests directory, skipping pytest"
fi

finish
