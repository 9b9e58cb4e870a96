"""PlatformIO extra script (``extra_scripts = pre:tools/graspguide/promini/pio_arduino_core.py``)
for ``pio run -e promini``: builds the Pro Mini sketch on the local avr-gcc dev-platform with
Debian's Arduino AVR core, offline, as arduino-cli does (graspguide.promini.build).

The board's MCU, clock, variant and board macro are read from the core's boards.txt, so
this build and arduino-cli's cannot disagree on them. The core is compiled with its own
warning level into a static library; the sketch and the project's libraries with the
environment's flags (-Werror included)."""

# ruff: noqa: F821 -- SCons injects Import and the environment.
from __future__ import annotations

import os
import sys
from pathlib import Path

Import("env")  # type: ignore[name-defined]

CORE_ROOT = "/usr/share/arduino/hardware/arduino/avr"
BOARD = "pro"
CPU = "8MHzatmega328"

project_dir = env.subst("$PROJECT_DIR")  # type: ignore[name-defined]
sys.path.insert(0, os.path.join(project_dir, "tools"))
from graspguide.promini.build import BUILD_ID_MACRO, LIBRARIES, SKETCH_NAME, build_id  # noqa: E402


def board_facts() -> dict[str, str]:
    boards_txt = os.path.join(CORE_ROOT, "boards.txt")
    if not os.path.isfile(boards_txt):
        sys.stderr.write(
            f"Error: {boards_txt} is missing: apt-get install arduino-core-avr "
            "(tools/bootstrap.sh does)\n"
        )
        env.Exit(1)  # type: ignore[name-defined]
    facts: dict[str, str] = {}
    prefixes = (f"{BOARD}.menu.cpu.{CPU}.", f"{BOARD}.")
    with open(boards_txt) as f:
        for line in f:
            key, sep, value = line.strip().partition("=")
            for prefix in prefixes:
                if sep and key.startswith(prefix):
                    # The cpu menu's value overrides the board's.
                    facts.setdefault(key[len(prefix) :], value)
    return facts


facts = board_facts()
mcu_flag = "-mmcu=" + facts["build.mcu"]
core_dir = os.path.join(CORE_ROOT, "cores", facts["build.core"])
variant_dir = os.path.join(CORE_ROOT, "variants", facts["build.variant"])
sketch_dir = os.path.join(project_dir, "promini", SKETCH_NAME)

# -flto as the core's platform.txt: arduino-cli's flash figure and this one then agree.
env.Append(  # type: ignore[name-defined]
    CCFLAGS=[mcu_flag, "-Os", "-ffunction-sections", "-fdata-sections", "-flto"],
    ASPPFLAGS=[mcu_flag],
    CFLAGS=["-std=gnu11"],
    # The core compiles C++ as gnu++11; the per-frame layer needs C++14.
    CXXFLAGS=["-std=gnu++14", "-fno-exceptions", "-fno-threadsafe-statics"],
    CPPDEFINES=[
        ("F_CPU", facts["build.f_cpu"]),
        ("ARDUINO", "10807"),
        "ARDUINO_" + facts["build.board"],
        "ARDUINO_ARCH_AVR",
        # GCC 5.4 defines DECIMAL_DIG for C99 only; the core's WString.cpp needs it in C++.
        ("DECIMAL_DIG", "__DECIMAL_DIG__"),
    ],
    CPPPATH=[core_dir, variant_dir, sketch_dir]
    + [os.path.join(project_dir, lib, "src") for lib in LIBRARIES],
    LINKFLAGS=[mcu_flag, "-Os", "-flto", "-fuse-linker-plugin"],
)

core_env = env.Clone()  # type: ignore[name-defined]
core_env.Replace(
    CCFLAGS=[f for f in core_env["CCFLAGS"] if not f.startswith(("-W", "-pedantic"))] + ["-w"],
    # A pre: script runs before the dev-platform names its tools; the clone keeps what it
    # copied, so it is given the same avr- tools (the main environment gets them later).
    AR="avr-gcc-ar",
    AS="avr-as",
    CC="avr-gcc",
    CXX="avr-g++",
    RANLIB="avr-gcc-ranlib",
)
# wiring_pulse.S and wiring_pulse.c would both be wiring_pulse.o: the assembly gets a
# folder of its own.
core_libs = [
    core_env.BuildLibrary(os.path.join("$BUILD_DIR", "arduino_core"), core_dir, "+<*> -<*.S>"),
    core_env.BuildLibrary(os.path.join("$BUILD_DIR", "arduino_core_S"), core_dir, "-<*> +<*.S>"),
]
env.Prepend(LIBS=core_libs)  # type: ignore[name-defined]
# The build id (HELLO_REPLY.build_id) as arduino-cli's build gives it; only the sketch and
# the libraries get it, so a new commit does not recompile the core.
env.Append(  # type: ignore[name-defined]
    CPPDEFINES=[(BUILD_ID_MACRO, "0x%08xu" % build_id(Path(project_dir)))]
)
env.BuildSources(os.path.join("$BUILD_DIR", "sketch"), sketch_dir)  # type: ignore[name-defined]
