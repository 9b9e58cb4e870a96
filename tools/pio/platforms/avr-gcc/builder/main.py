# GraspGuide local "avr-gcc" dev-platform builder: bare-metal AVR with Debian's avr-gcc/g++
# and avr-libc from PATH (no PlatformIO toolchain package, works offline). The environment's
# build_flags choose the MCU (-mmcu=...), which is mirrored to the link line because it
# selects avr-libc's start-up code and device library. The build writes
# $BUILD_DIR/firmware.elf and prints flash/RAM from avr-size (flash = text + data,
# static RAM = data + bss; the stack comes on top).
import shutil
import subprocess
import sys

from SCons.Script import AlwaysBuild, Default, DefaultEnvironment

env = DefaultEnvironment()

PREFIX = "avr-"
if not shutil.which(PREFIX + "g++", path=env["ENV"].get("PATH")):
    sys.stderr.write(
        "Error: %sg++ is not on PATH. Install Debian's gcc-avr and avr-libc "
        "(tools/bootstrap.sh does).\n" % PREFIX
    )
    env.Exit(1)

env.Replace(
    AR=PREFIX + "gcc-ar",
    AS=PREFIX + "as",
    CC=PREFIX + "gcc",
    CXX=PREFIX + "g++",
    LINK=PREFIX + "g++",
    RANLIB=PREFIX + "gcc-ranlib",
    OBJCOPY=PREFIX + "objcopy",
    SIZETOOL=PREFIX + "size",
    ARFLAGS=["rc"],
    PROGNAME="firmware",
    PROGSUFFIX=".elf",
    # Replaces PlatformIO's board-based size check (there is no board here).
    SIZECHECKCMD="",
    SIZEPRINTCMD="$SIZETOOL -B -d $SOURCES",
)

# Every function and object in its own section so --gc-sections drops what main() does not
# reach.
env.Append(
    CCFLAGS=["-ffunction-sections", "-fdata-sections"],
    LINKFLAGS=["-Wl,--gc-sections", "-Wl,-Map,${BUILD_DIR}/${PROGNAME}.map"],
)

target_elf = env.BuildProgram()

# build_flags were parsed inside BuildProgram into CCFLAGS; command lines are expanded only
# when the link runs, so appending now still reaches the linker.
mcu = [f for f in env.get("CCFLAGS", []) if isinstance(f, str) and f.startswith("-mmcu=")]
env.Append(LINKFLAGS=[f for f in mcu if f not in env["LINKFLAGS"]])


def print_memory(target, source, env):  # pylint: disable=unused-argument
    elf = str(source[0])
    out = subprocess.run(
        [env.subst("$SIZETOOL"), "-B", "-d", elf], check=True, capture_output=True, text=True
    ).stdout
    print(out.rstrip())
    text, data, bss = (int(v) for v in out.splitlines()[1].split()[:3])
    print("Flash: %d bytes (text %d + data %d)" % (text + data, text, data))
    print("RAM:   %d bytes (data %d + bss %d), stack not included" % (data + bss, data, bss))


# PlatformIO drops a default target named "size" when SIZETOOL is set; keep ours.
memreport = env.Alias(
    "memreport", target_elf, env.VerboseAction(print_memory, "Memory use of $SOURCE")
)
AlwaysBuild(memreport)

Default([target_elf, memreport])
