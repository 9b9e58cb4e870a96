#!/usr/bin/env bash
# Installs the bare-metal ARM toolchain for `pio run -e cortex_m4f` (Debian 12): GCC,
# newlib (incl. newlib-nano) and libstdc++ for arm-none-eabi, plus qemu-system-arm for
# running the images on QEMU's mps2-an386 / mps2-an500. tools/run-tests.sh runs it before
# the firmware builds; tools/bootstrap.sh does not (tools/run-main.sh needs none of its
# ~400 MB). Idempotent: installs only missing packages (apt-get update only then), and
# takes well under a second when everything is there.
set -euo pipefail

PACKAGES=(gcc-arm-none-eabi libnewlib-arm-none-eabi libstdc++-arm-none-eabi-newlib qemu-system-arm)

say() { printf 'install-arm: %s\n' "$*"; }
die() { printf 'install-arm: ERROR: %s\n' "$*" >&2; exit 1; }

# shellcheck source=tools/apt-ensure.sh
. "$(dirname "${BASH_SOURCE[0]}")/apt-ensure.sh"
apt_ensure "${PACKAGES[@]}"
command -v arm-none-eabi-g++ >/dev/null 2>&1 || die "arm-none-eabi-g++ still not on PATH"
command -v qemu-system-arm >/dev/null 2>&1 || die "qemu-system-arm still not on PATH"
say "$(arm-none-eabi-g++ --version | head -n1); $(qemu-system-arm --version | head -n1)"
