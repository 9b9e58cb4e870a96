"""Building a measurement image with PlatformIO, for the target benchmarks (targets.py:
Cortex-M under QEMU; avr_target.py: the ATmega328P under simavr). Each caller passes its
own typed errors, so a missing tool or a failed build is reported in its target's terms."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


def pio_executable(root: Path, missing: type[Exception], hint: str = "") -> str:
    """The project's pio (.venv, then this interpreter's, then PATH)."""
    for candidate in (root / ".venv" / "bin" / "pio", Path(sys.executable).parent / "pio"):
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    found = shutil.which("pio")
    if found is None:
        raise missing(
            f"PlatformIO (pio) is not in {root / '.venv' / 'bin'} or on PATH: run "
            f"tools/bootstrap.sh{hint}"
        )
    return found


def pio_env(root: Path) -> dict[str, str]:
    """The environment the test command gives pio: the project's own core directory, no
    upgrade check (there is no registry to ask)."""
    env = dict(os.environ)
    env.setdefault("PLATFORMIO_CORE_DIR", str(root / ".pio-core"))
    env.setdefault("PLATFORMIO_DISABLE_UPGRADE_CHECK", "true")
    return env


def run_build(
    cmd: list[str],
    root: Path,
    what: str,
    timeout_s: float,
    failed: type[Exception],
    env: dict[str, str] | None = None,
) -> None:
    """Runs a build command; on a timeout or a non-zero exit raises ``failed`` with the
    command and the last 20 lines of its output."""
    try:
        p = subprocess.run(
            cmd,
            cwd=root,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        raise failed(f"`{what}` took over {timeout_s:.0f} s") from None
    if p.returncode != 0:
        tail = "\n".join(p.stdout.splitlines()[-20:])
        raise failed(f"`{what}` exited {p.returncode}:\n{tail}")
