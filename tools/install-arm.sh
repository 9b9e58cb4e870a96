#!/usr/bin/env bash
# Installs the bare-metal ARM toolchain for `pio run -e cortex_m4f` (Debian 12): GCC,
# newlib (incl. newlib-nano) and libstdc++ for arm-none-eabi, plus qemu-system-arm for
# running the image on QEMU's mps2-an386. About 400 MB, so tools/bootstrap.sh does not
# install it; tools/run-tests.sh builds the firmware only when the compiler is present.
# Idempotent: installs only missing packages (apt-get update only then).
set -euo pipefail

PACKAGES=(gcc-arm-none-eabi libnewlib-arm-none-eabi libstdc++-arm-none-eabi-newlib qemu-system-arm)

say() { printf 'install-arm: %s\n' "$*"; }
die() { printf 'install-arm: ERROR: %s\n' "$*" >&2; exit 1; }

# shellcheck source=tools/apt-ensure.sh
. "$(dirname "${BASH_SOURCE[0]}")/apt-ensure.sh"
apt_ensure "${PACKAGES[@]}"
command -v arm-none-eabi-g++ >/dev/null 2>&1 || die "arm-none-eabi-g++ still not on PATH"
say "$(arm-none-eabi-g++ --version | head -n1)"
