#!/usr/bin/env bash
# GraspGuide full test run (what .ci/run executes):
#   1. tools/bootstrap.sh        (Debian packages, Eigen check, .venv, ./tools)
#   2. pio test -e native        (GoogleTest suites in test/test_*/, offline)
#   3. pio run -e cortex_m4f, m4f_firmware, m4f_stages, m7_stages and the QEMU
#      stage counts vs tools/perf/stage_baseline.json (only if arm-none-eabi-g++ and
#      qemu-system-arm are on PATH, see tools/install-arm.sh; each is 1 case)
#   4. pytest tools/tests        (if that directory exists)
# Output of every stage goes to the console. Test cases are counted from
# machine-readable reports (PlatformIO's JSON report, pytest's JUnit XML), and
# the run ends with exactly one line "N passed, N failed".
# A stage that errors (bootstrap failure, build error, crashing test program,
# pytest collection error, ...) always counts as at least one failure, and
# the script exits non-zero if anything failed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

PASSED=0
FAILED=0
STAGE_ERRORS=()

REPORT_DIR="$(mktemp -d "${TMPDIR:-/tmp}/graspguide-tests.XXXXXX")"
trap 'rm -rf "$REPORT_DIR"' EXIT

banner() { printf '\n===== %s =====\n' "$*"; }

finish() {
    echo
    if ((${#STAGE_ERRORS[@]})); then
        printf 'run-tests: stage error: %s\n' "${STAGE_ERRORS[@]}"
    fi
    echo "$PASSED passed, $FAILED failed"
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

# --- 1. bootstrap --------------------------------------------------------------
banner "bootstrap"
if ! bash "$ROOT/tools/bootstrap.sh"; then
    STAGE_ERRORS+=("bootstrap failed")
    FAILED=$((FAILED + 1))
    finish
fi
PY="$ROOT/.venv/bin/python"

# Sum PASSED / FAILED(+ERRORED) cases of a PlatformIO JSON test report.
count_pio_report() {
    "$PY" - "$1" <<'EOF'
import json, sys
data = json.load(open(sys.argv[1], encoding="utf8"))
passed = failed = 0
for suite in data.get("test_suites", []):
    for case in suite.get("test_cases", []):
        status = case.get("status")
        if status == "PASSED":
            passed += 1
        elif status in ("FAILED", "ERRORED"):
            failed += 1
print(passed, failed)
EOF
}

# Sum passed / failed(+errors) of a pytest JUnit XML report.
count_junit_report() {
    "$PY" - "$1" <<'EOF'
import sys
import xml.etree.ElementTree as ET
root = ET.parse(sys.argv[1]).getroot()
suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
passed = failed = 0
for s in suites:
    tests, fails, errs, skips = (int(s.get(k, 0)) for k in ("tests", "failures", "errors", "skipped"))
    failed += fails + errs
    passed += tests - fails - errs - skips
print(passed, failed)
EOF
}

# --- 2. PlatformIO / GoogleTest ------------------------------------------------
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
    p=0
    f=0
    if [[ -s $pio_json ]] && counts="$(count_pio_report "$pio_json")"; then
        read -r p f <<<"$counts"
    else
        STAGE_ERRORS+=("pio test wrote no readable report (exit code $pio_rc)")
    fi
    if ((pio_rc != 0 && f == 0)); then
        # e.g. bad platformio.ini, platform/package problems: never "0 failed"
        STAGE_ERRORS+=("pio test exited with code $pio_rc")
        f=1
    fi
    echo "run-tests: pio/GoogleTest: $p passed, $f failed"
    PASSED=$((PASSED + p))
    FAILED=$((FAILED + f))
fi

# --- 3. Bare-metal ARM builds and QEMU runs -----------------------------------------
# Optional: the ARM toolchain and QEMU are large and bootstrap.sh does not install them
# (tools/install-arm.sh does). Before pytest, because its QEMU firmware test needs the
# m4f_firmware image. Each build is one test case; the stage counts under QEMU (and their
# check against tools/perf/stage_baseline.json) are one more.
ARM_ENVS=(cortex_m4f m4f_firmware m4f_stages m7_stages)
if command -v arm-none-eabi-g++ >/dev/null 2>&1; then
    for env in "${ARM_ENVS[@]}"; do
        run_case "$env build" "$env" "$ROOT/.venv/bin/pio" run -e "$env"
    done
    if command -v qemu-system-arm >/dev/null 2>&1; then
        run_case "QEMU stage counts within baseline" qemu_stages \
            "$PY" tools/scripts/qemu_stages.py --json "$REPORT_DIR/qemu_stages.json"
    else
        echo "run-tests: qemu-system-arm not on PATH, skipping the QEMU runs (tools/install-arm.sh installs it)"
    fi
else
    echo
    echo "run-tests: arm-none-eabi-g++ not on PATH, skipping the ARM builds and QEMU runs (tools/install-arm.sh installs them)"
fi

# --- 4. pytest -----------------------------------------------------------------
if [[ -d $ROOT/tools/tests ]]; then
    banner "pytest tools/tests"
    junit="$REPORT_DIR/pytest-junit.xml"
    set +e
    "$PY" -m pytest tools/tests -q --junitxml="$junit" 2>&1 | tee "$REPORT_DIR/pytest.log"
    py_rc=${PIPESTATUS[0]}
    set -e
    p=0
    f=0
    if [[ -s $junit ]] && counts="$(count_junit_report "$junit")"; then
        read -r p f <<<"$counts"
    elif ((py_rc != 5)); then
        STAGE_ERRORS+=("pytest wrote no readable report (exit code $py_rc)")
    fi
    if ((py_rc == 5)); then
        echo "run-tests: pytest collected no tests: 0 test cases"
    elif ((py_rc != 0 && f == 0)); then
        # internal error, usage error, interrupted, ...
        STAGE_ERRORS+=("pytest exited with code $py_rc")
        f=1
    fi
    echo "run-tests: pytest: $p passed, $f failed"
    PASSED=$((PASSED + p))
    FAILED=$((FAILED + f))
else
    echo
    echo "run-tests: no tools/tests directory, skipping pytest"
fi

finish
