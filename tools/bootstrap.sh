#!/usr/bin/env bash
# GraspGuide developer/CI bootstrap (Debian 12). Idempotent and quick when
# everything is already in place:
#   1. Debian packages (installed as root, `apt-get update` only if needed);
#   2. Eigen must be exactly 3.4.0;
#   3. ./.venv with the pinned tools/requirements-dev.txt (re-installed only
#      when that file changes);
#   4. the Python package in tools/ (if tools/pyproject.toml exists),
#      re-installed only when its sources (tools/, lib/graspguide/, lib/graspguide_cue/) change;
#   5. the simulated device (.pio/build-sim/sim/program, `pio run -e sim`) when
#      platformio.ini has [env:sim]; pio rebuilds only what changed;
#   6. arduino-cli (pinned version, built from Go sources into .tools/arduino-cli/,
#      rebuilt only when the version changes) and its offline config for Debian's AVR core.
# Exports nothing. Set GRASPGUIDE_PYTHON to choose the interpreter for .venv
# (default: python3 on PATH).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

say() { printf 'bootstrap: %s\n' "$*"; }
die() { printf 'bootstrap: ERROR: %s\n' "$*" >&2; exit 1; }

# --- 1. Debian packages ------------------------------------------------------
# gcc-avr, avr-libc, simavr and libsimavr-dev: the per-frame layer built for the ATmega328P
# and its cycle counts (src/harness/avr_cue/).
# arduino-core-avr and universal-ctags: the Pro Mini sketch (promini/) built offline by
# arduino-cli (step 6); golang-go only when no `go` is on PATH, to build arduino-cli (step 6
# checks that the Go found is recent enough).
APT_PACKAGES=(libeigen3-dev libgtest-dev cmake ninja-build g++ python3-venv
    gcc-avr avr-libc simavr libsimavr-dev arduino-core-avr universal-ctags)
command -v go >/dev/null 2>&1 || APT_PACKAGES+=(golang-go)
# shellcheck source=tools/apt-ensure.sh
. "$ROOT/tools/apt-ensure.sh"
apt_ensure "${APT_PACKAGES[@]}"

# --- 2. Eigen 3.4.0 exactly ----------------------------------------------------
EIGEN_MACROS=/usr/include/eigen3/Eigen/src/Core/util/Macros.h
[[ -f $EIGEN_MACROS ]] || die "Eigen not found ($EIGEN_MACROS missing); install libeigen3-dev"
eigen_ver="$(awk '/#define EIGEN_WORLD_VERSION/{w=$3} /#define EIGEN_MAJOR_VERSION/{M=$3}
                  /#define EIGEN_MINOR_VERSION/{m=$3} END{print w "." M "." m}' "$EIGEN_MACROS")"
[[ $eigen_ver == 3.4.0 ]] ||
    die "Eigen 3.4.0 is required, found $eigen_ver in $EIGEN_MACROS (GraspGuide is validated against 3.4.0 only)"
say "Eigen $eigen_ver"

# --- 3. Python venv ------------------------------------------------------------
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
REQS="$ROOT/tools/requirements-dev.txt"
[[ -f $REQS ]] || die "missing $REQS"

if [[ -x $PY ]] && ! "$PY" -c 'import sys' >/dev/null 2>&1; then
    say "existing .venv is broken (base interpreter gone?); recreating it"
    rm -rf "$VENV"
fi
if [[ ! -x $PY ]]; then
    base_py="${GRASPGUIDE_PYTHON:-python3}"
    command -v "$base_py" >/dev/null 2>&1 || die "no '$base_py' on PATH to create .venv"
    say "creating .venv with $("$base_py" --version 2>&1)"
    "$base_py" -m venv "$VENV"
fi

py_id="$("$PY" -c 'import sys; print(sys.version)')"
reqs_hash="$( { cat "$REQS"; echo "$py_id"; } | sha256sum | cut -d' ' -f1)"
REQS_STAMP="$VENV/.graspguide-requirements.sha256"
if [[ ! -f $REQS_STAMP || $(cat "$REQS_STAMP") != "$reqs_hash" ]]; then
    say "installing tools/requirements-dev.txt into .venv"
    "$PY" -m pip install --quiet --disable-pip-version-check -r "$REQS"
    echo "$reqs_hash" >"$REQS_STAMP"
    rm -f "$VENV/.graspguide-tools.sha256" # new environment: reinstall tools too
else
    say ".venv requirements up to date"
fi

# --- 4. The Python package in tools/ -------------------------------------------
if [[ -f $ROOT/tools/pyproject.toml ]]; then
    # Everything that can change what `pip install ./tools` builds.
    src_dirs=(tools)
    [[ -d lib/graspguide ]] && src_dirs+=(lib/graspguide)
    [[ -d lib/graspguide_cue ]] && src_dirs+=(lib/graspguide_cue)
    src_hash="$(
        {
            find "${src_dirs[@]}" -type f \
                -not -path 'tools/pio/*' -not -path 'tools/tests/*' \
                -not -path 'tools/build/*' -not -path 'tools/dist/*' \
                -not -path '*/__pycache__/*' -not -path '*.egg-info/*' \
                -not -path '*/.pytest_cache/*' -not -name '*.pyc' \
                -not -name 'bootstrap.sh' -not -name 'run-tests.sh' \
                -not -name 'requirements-dev.txt' -print0 2>/dev/null |
                LC_ALL=C sort -z | xargs -0 -r sha256sum
            echo "$reqs_hash"
        } | sha256sum | cut -d' ' -f1
    )"
    TOOLS_STAMP="$VENV/.graspguide-tools.sha256"
    if [[ ! -f $TOOLS_STAMP || $(cat "$TOOLS_STAMP") != "$src_hash" ]]; then
        say "installing ./tools into .venv (pip --no-build-isolation)"
        rm -f "$TOOLS_STAMP"
        "$PY" -m pip install --quiet --disable-pip-version-check --no-build-isolation ./tools
        echo "$src_hash" >"$TOOLS_STAMP"
    else
        say "./tools package up to date"
    fi
fi

# --- 5. The simulated device ------------------------------------------------------
# `graspguide ... --port sim` and tools/tests/test_device_e2e.py run it. Offline, like
# the native tests; pio recompiles only what changed (about 1 s when nothing did). It
# builds into a folder of its own, where its launcher looks (graspguide.devices.builds):
# pio deletes its whole build folder when its project checksum changes, and another env's
# build must not take the simulated device with it.
if grep -q '^\[env:sim\]' "$ROOT/platformio.ini" 2>/dev/null; then
    sim_log="$(mktemp "${TMPDIR:-/tmp}/graspguide-sim-build.XXXXXX")"
    if PLATFORMIO_CORE_DIR="$ROOT/.pio-core" PLATFORMIO_DISABLE_UPGRADE_CHECK=true \
        PLATFORMIO_SETTING_ENABLE_TELEMETRY=No PLATFORMIO_BUILD_DIR="$ROOT/.pio/build-sim" \
        "$ROOT/.venv/bin/pio" run -e sim >"$sim_log" 2>&1; then
        say "simulated device ready (.pio/build-sim/sim/program)"
        rm -f "$sim_log"
    else
        tail -n 40 "$sim_log" >&2
        die "building the simulated device failed (\`pio run -e sim\`; full log: $sim_log)"
    fi
else
    say "platformio.ini has no [env:sim]: not building the simulated device"
fi

# --- 6. arduino-cli, offline, for the Pro Mini sketch ------------------------------------
# `go install` of arduino-cli is refused (its go.mod has replace directives), so it is
# built inside a throw-away module, with its version stamped in (`arduino-cli version`).
# The binary lives under .tools/arduino-cli/<version>/ so a version bump rebuilds it and
# nothing else does (measured: 78 s the first time, 2 cores, empty Go module cache). Debian's
# AVR core is linked in as the user's hardware folder: compiling then downloads nothing
# (arduino-cli still tries for its indexes and says so; harmless offline).
ARDUINO_CLI_VERSION=1.0.4
ACLI_HOME="$ROOT/.tools/arduino-cli"
ACLI_BIN="$ACLI_HOME/$ARDUINO_CLI_VERSION/arduino-cli"
DEBIAN_AVR_CORE=/usr/share/arduino/hardware/arduino/avr
mkdir -p "$ACLI_HOME"
# .tools/ holds only machine-local builds and caches; it ignores itself.
[[ -f $ROOT/.tools/.gitignore ]] || echo '*' >"$ROOT/.tools/.gitignore"
if [[ ! -x $ACLI_BIN ]]; then
    command -v go >/dev/null 2>&1 || die "no \`go\` on PATH to build arduino-cli (apt-get install golang-go)"
    # arduino-cli 1.0.4's go.mod says go 1.22; Debian 12's golang-go is 1.19.
    go_minor="$(go env GOVERSION | sed -n 's/^go1\.\([0-9]*\).*/\1/p')"
    [[ -n $go_minor && $go_minor -ge 22 ]] ||
        die "arduino-cli $ARDUINO_CLI_VERSION needs Go >= 1.22, found $(go env GOVERSION) at $(command -v go): install a newer Go (/usr/local/go) first on PATH"
    say "building arduino-cli $ARDUINO_CLI_VERSION with $(go version) (once; about 80 s on 2 cores)"
    acli_src="$(mktemp -d "$ACLI_HOME/src.XXXXXX")"
    acli_log="$ACLI_HOME/build-$ARDUINO_CLI_VERSION.log"
    acli_start=$SECONDS
    if (cd "$acli_src" && go mod init graspguide.local/arduino-cli-build &&
        go get "github.com/arduino/arduino-cli@v$ARDUINO_CLI_VERSION" &&
        go build -ldflags "-X github.com/arduino/arduino-cli/version.versionString=$ARDUINO_CLI_VERSION" \
            -o "$acli_src/arduino-cli" github.com/arduino/arduino-cli) >"$acli_log" 2>&1; then
        mkdir -p "$(dirname "$ACLI_BIN")"
        mv "$acli_src/arduino-cli" "$ACLI_BIN"
        rm -rf "$acli_src"
        say "arduino-cli $ARDUINO_CLI_VERSION built in $((SECONDS - acli_start)) s"
    else
        rm -rf "$acli_src"
        tail -n 30 "$acli_log" >&2
        die "building arduino-cli $ARDUINO_CLI_VERSION failed (full log: $acli_log)"
    fi
else
    say "arduino-cli $ARDUINO_CLI_VERSION present ($ACLI_BIN)"
fi
[[ -d $DEBIAN_AVR_CORE ]] || die "$DEBIAN_AVR_CORE missing; apt-get install arduino-core-avr"
mkdir -p "$ACLI_HOME/user/hardware/arduino" "$ACLI_HOME/data" "$ACLI_HOME/downloads"
ln -sfn "$DEBIAN_AVR_CORE" "$ACLI_HOME/user/hardware/arduino/avr"
ln -sfn "$ARDUINO_CLI_VERSION/arduino-cli" "$ACLI_HOME/arduino-cli"
cat >"$ACLI_HOME/arduino-cli.yaml.new" <<YAML
# Written by tools/bootstrap.sh: offline, Debian's AVR core as a user hardware folder.
directories:
  user: $ACLI_HOME/user
  data: $ACLI_HOME/data
  downloads: $ACLI_HOME/downloads
build_cache:
  path: $ACLI_HOME/build-cache
updater:
  enable_notification: false
metrics:
  enabled: false
YAML
mv "$ACLI_HOME/arduino-cli.yaml.new" "$ACLI_HOME/arduino-cli.yaml"

say "done"
