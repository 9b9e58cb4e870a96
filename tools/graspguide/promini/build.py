"""Builds the Pro Mini sketch (promini/GraspGuideProMini) with arduino-cli, offline, against
Debian's AVR core, and reads its flash and static RAM from arduino-cli's size report.

tools/bootstrap.sh builds arduino-cli into .tools/arduino-cli/ and writes the config that
links Debian's core in; ``python -m graspguide.promini.build`` runs this module.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

SKETCH_NAME = "GraspGuideProMini"
#: Pro Mini, ATmega328P at 3.3 V / 8 MHz.
FQBN = "arduino:avr:pro:cpu=8MHzatmega328"
#: Debian's core ships no tool manifests, so arduino-cli is told where avr-gcc and ctags
#: are. GCC 5.4 defines DECIMAL_DIG only for C99, which the core's WString.cpp needs in
#: C++. The core compiles C++ as gnu++11; the per-frame layer is C++14 (a later -std wins).
BUILD_PROPERTIES = (
    "runtime.tools.avr-gcc.path=/usr",
    "runtime.tools.ctags.path=/usr/bin",
    "compiler.cpp.extra_flags=-DDECIMAL_DIG=__DECIMAL_DIG__ -std=gnu++14",
)
#: The macro that stamps the sketch with its build id (HELLO_REPLY.build_id), as
#: tools/pio/scripts/build_id.py stamps the other boards.
BUILD_ID_MACRO = "GRASPGUIDE_BUILD_ID"
#: The project's Arduino libraries the sketch uses, relative to the repository.
LIBRARIES = ("lib/graspguide_cue", "lib/graspguide_hal", "lib/graspguide_cue_device")
#: The Pro Mini's budget: flash (the 32 KB less the 2 KB bootloader is 30 KB), and static RAM
#: plus the measured stack within 1.5 KB of the 2 KB.
FLASH_BUDGET_BYTES = 30 * 1024
RAM_BUDGET_BYTES = 1536
BUILD_TIMEOUT_S = 600.0

FIX = "run tools/bootstrap.sh (it builds arduino-cli into .tools/arduino-cli/)"


class ArduinoCliMissing(RuntimeError):
    """arduino-cli or its offline config is not where tools/bootstrap.sh puts them."""


class SketchBuildFailed(RuntimeError):
    """arduino-cli ran and failed, or its output lacked the size report."""


@dataclass(frozen=True)
class SketchBuild:
    elf: Path
    hex: Path
    flash_bytes: int
    flash_max_bytes: int
    static_ram_bytes: int
    ram_max_bytes: int
    seconds: float
    command: tuple[str, ...]
    #: arduino-cli's whole output (the libraries and platform it used are listed last).
    output: str


def repo_root() -> Path:
    from graspguide.repo_root import find_repo_root

    root = find_repo_root()
    if root is None:
        raise SketchBuildFailed(
            "the GraspGuide repository was not found (run from inside /path/to/repo)"
        )
    return Path(root)


def arduino_cli_paths(root: Path) -> tuple[Path, Path]:
    """arduino-cli and its config under ``root``/.tools/arduino-cli; raises
    :class:`ArduinoCliMissing` naming the fix when either is absent."""
    home = root / ".tools" / "arduino-cli"
    exe = home / "arduino-cli"
    config = home / "arduino-cli.yaml"
    for path, what in ((exe, "arduino-cli"), (config, "its config")):
        if not path.is_file() or (path is exe and not os.access(path, os.X_OK)):
            raise ArduinoCliMissing(f"{what} is missing ({path}): {FIX}")
    return exe, config


_FLASH_RE = re.compile(r"Sketch uses (\d+) bytes .*?Maximum is (\d+) bytes")
_RAM_RE = re.compile(r"Global variables use (\d+) bytes .*?Maximum is (\d+) bytes")


def parse_sizes(output: str) -> tuple[int, int, int, int]:
    """(flash, flash maximum, static RAM, RAM maximum) in bytes from arduino-cli's report."""
    flash = _FLASH_RE.search(output)
    ram = _RAM_RE.search(output)
    if flash is None or ram is None:
        raise SketchBuildFailed(
            "arduino-cli's output has no 'Sketch uses N bytes ... Global variables use N "
            "bytes' report:\n" + output[-2000:]
        )
    return int(flash[1]), int(flash[2]), int(ram[1]), int(ram[2])


def build_id(root: Path) -> int:
    """The first 8 hex digits of the commit ``root`` is at, as the other boards' builds
    stamp theirs (tools/pio/scripts/build_id.py); 0 outside a git checkout."""
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short=8", "HEAD"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return int(out[:8], 16)
    except (OSError, subprocess.CalledProcessError, ValueError):
        return 0


def build_properties(root: Path) -> list[str]:
    """BUILD_PROPERTIES with the build id: arduino-cli has one property for extra C++
    flags, so the id joins the flags there."""
    props = []
    for prop in BUILD_PROPERTIES:
        if prop.startswith("compiler.cpp.extra_flags="):
            prop += f" -D{BUILD_ID_MACRO}=0x{build_id(root):08x}u"
        props.append(prop)
    return props


def compile_command(root: Path, out_dir: Path) -> list[str]:
    exe, config = arduino_cli_paths(root)
    cmd = [str(exe), "--config-file", str(config), "--no-color", "compile", "--fqbn", FQBN]
    cmd += ["--warnings", "all"]
    for prop in build_properties(root):
        cmd += ["--build-property", prop]
    for lib in LIBRARIES:
        cmd += ["--library", str(root / lib)]
    cmd += [
        "--build-path",
        str(out_dir / "work"),
        "--output-dir",
        str(out_dir),
        str(root / "promini" / SKETCH_NAME),
    ]
    return cmd


def build_sketch(root: Path | None = None, out_dir: Path | None = None) -> SketchBuild:
    """Compiles the sketch into ``out_dir`` (default build/promini/) and returns where the
    ELF and HEX are and the sizes arduino-cli reports."""
    root = repo_root() if root is None else root
    out_dir = root / "build" / "promini" if out_dir is None else out_dir
    cmd = compile_command(root, out_dir)
    start = time.monotonic()
    try:
        p = subprocess.run(
            cmd,
            cwd=root,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=BUILD_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired:
        raise SketchBuildFailed(f"arduino-cli compile took over {BUILD_TIMEOUT_S:.0f} s") from None
    seconds = time.monotonic() - start
    if p.returncode != 0:
        tail = "\n".join(p.stdout.splitlines()[-30:])
        raise SketchBuildFailed(
            f"arduino-cli compile failed (exit {p.returncode}):\n{' '.join(cmd)}\n{tail}"
        )
    flash, flash_max, ram, ram_max = parse_sizes(p.stdout)
    elf = out_dir / f"{SKETCH_NAME}.ino.elf"
    hex_file = out_dir / f"{SKETCH_NAME}.ino.hex"
    for path in (elf, hex_file):
        if not path.is_file():
            raise SketchBuildFailed(f"arduino-cli reported success but wrote no {path}")
    return SketchBuild(elf, hex_file, flash, flash_max, ram, ram_max, seconds, tuple(cmd), p.stdout)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m graspguide.promini.build",
        description=f"Build promini/{SKETCH_NAME} with arduino-cli ({FQBN}), offline, "
        "and print its flash and static RAM.",
    )
    parser.add_argument("--out", type=Path, help="output folder (default build/promini/)")
    args = parser.parse_args(argv)
    try:
        result = build_sketch(out_dir=args.out)
    except (ArduinoCliMissing, SketchBuildFailed) as e:
        print(f"promini build: {e}", file=sys.stderr)
        return 1
    print(f"elf: {result.elf}")
    print(f"hex: {result.hex}")
    print(f"flash: {result.flash_bytes} of {result.flash_max_bytes} bytes")
    print(f"static RAM: {result.static_ram_bytes} of {result.ram_max_bytes} bytes")
    print(f"build time: {result.seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
