"""Where each simulated device kind's PlatformIO build lives, and building one on demand.

PlatformIO keeps one build folder for all environments (``.pio/build``) and deletes all of
it whenever its project checksum changes: that checksum covers the whole configuration
(including ``core_dir``, so a `pio run` without ``PLATFORMIO_CORE_DIR`` differs from one
with it) and the list of source files under src/ and lib/ (so a file added anywhere
differs too). One `pio run -e m4f_firmware` then deleted the simulated device, and the
next `pio run -e sim` deleted the firmware. Each device kind therefore builds into a
folder of its own (``PLATFORMIO_BUILD_DIR=.pio/build-<env>``): a clean of one never
touches another. The launchers (``--port sim``, ``--port qemu``) build a missing one with
:func:`ensure_built`, showing pio's progress, or name the exact command when they
cannot.
"""

from __future__ import annotations

import fcntl
import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass

from graspguide.link.transport import SimNotBuilt


@dataclass(frozen=True)
class DeviceBuild:
    """One device kind's PlatformIO environment and what the launcher runs from it."""

    env: str
    #: what the build is, for messages ("the simulated device")
    what: str
    #: the launcher's file inside the env's folder of its build folder
    output: str
    #: programs the build needs on PATH besides pio (name, how to get it)
    needs: tuple[tuple[str, str], ...] = ()

    def build_dir(self, root: str) -> str:
        """The env's own PLATFORMIO_BUILD_DIR: ``<root>/.pio/build-<env>``."""
        return os.path.join(root, ".pio", f"build-{self.env}")

    def relative_build_dir(self) -> str:
        return os.path.join(".pio", f"build-{self.env}")

    def path(self, root: str) -> str:
        """The launcher's file: ``<root>/.pio/build-<env>/<env>/<output>``."""
        return os.path.join(self.build_dir(root), self.env, self.output)

    def relative_path(self) -> str:
        return os.path.join(self.relative_build_dir(), self.env, self.output)

    def command(self, root: str) -> str:
        """The exact shell command that builds it in the repository ``root``."""
        return (
            f"cd {shlex.quote(root)} && PLATFORMIO_CORE_DIR=.pio-core "
            f"PLATFORMIO_BUILD_DIR={self.relative_build_dir()} "
            f"PLATFORMIO_DISABLE_UPGRADE_CHECK=true .venv/bin/pio run -e {self.env}"
        )


SIM = DeviceBuild("sim", "the simulated device", "program")
M4F_FIRMWARE = DeviceBuild(
    "m4f_firmware",
    "the QEMU firmware",
    "firmware.elf",
    needs=(("arm-none-eabi-g++", "tools/install-arm.sh (as root) installs the ARM toolchain"),),
)
BUILDS = {b.env: b for b in (SIM, M4F_FIRMWARE)}


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def ensure_built(
    build: DeviceBuild,
    root: str,
    progress: Callable[[str], None] | None = None,
) -> str:
    """Path of ``build``'s output in the repository ``root``, building it first when it is
    missing (pio's output goes to ``progress``, default stderr, line by line). Concurrent
    callers (participants started at once) serialise on a lock file, so one builds and the
    others wait for it. Raises SimNotBuilt naming the exact command when it cannot build
    (no pio in ``root``/.venv, a tool missing) or the build fails."""
    out = build.path(root)
    if os.path.isfile(out):
        return out
    say = progress or _say
    command = build.command(root)
    pio = os.path.join(root, ".venv", "bin", "pio")
    if not os.access(pio, os.X_OK):
        raise SimNotBuilt(
            f"{build.what} is not built ({out} is missing); build it with:\n    {command}\n"
            "(tools/bootstrap.sh sets up .venv and builds the simulated device)"
        )
    for tool, how in build.needs:
        if shutil.which(tool) is None:
            raise SimNotBuilt(
                f"{build.what} is not built ({out} is missing) and {tool} is not on PATH "
                f"to build it: {how}; then:\n    {command}"
            )
    os.makedirs(os.path.dirname(build.build_dir(root)), exist_ok=True)
    with open(build.build_dir(root) + ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if os.path.isfile(out):  # another process built it while this one waited
            return out
        say(f"building {build.what} (once, a minute or two): {command}")
        env = dict(os.environ)
        env.update(
            PLATFORMIO_CORE_DIR=os.path.join(root, ".pio-core"),
            PLATFORMIO_BUILD_DIR=build.build_dir(root),
            PLATFORMIO_DISABLE_UPGRADE_CHECK="true",
            PLATFORMIO_SETTING_ENABLE_TELEMETRY="No",
        )
        tail: list[str] = []
        proc = subprocess.Popen(
            [pio, "run", "-e", build.env],
            cwd=root,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            errors="replace",
        )
        assert proc.stdout is not None
        for line in proc.stdout:
            line = line.rstrip()
            tail = (tail + [line])[-30:]
            say(f"  {line}")
        code = proc.wait()
        if code != 0 or not os.path.isfile(out):
            raise SimNotBuilt(
                f"building {build.what} failed (exit {code}):\n"
                + "\n".join(tail)
                + f"\nthe command was:\n    {command}"
            )
        say(f"built {build.what}: {out}")
    return out


__all__ = ["DeviceBuild", "SIM", "M4F_FIRMWARE", "BUILDS", "ensure_built"]
