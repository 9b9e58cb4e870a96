# GraspGuide local "arm-none-eabi" dev-platform builder: bare-metal ARM with Debian's
# arm-none-eabi-gcc/g++ from PATH (no PlatformIO toolchain package, works offline).
#
# The environment in platformio.ini chooses the CPU and the C library in build_flags
# (-mcpu/-mthumb/-mfpu/-mfloat-abi, --specs=...). They are mirrored to the link and
# assembler lines, because they select the multilib (e.g. thumb/v7e-m+fp/hard). Options:
#   custom_ldscript = path/to/link.ld   (relative to the project; relinks when it changes)
# The build writes $BUILD_DIR/firmware.elf and firmware.map, and prints flash/RAM from
# arm-none-eabi-size after every build (flash = text + data, RAM = data + bss).
import os
import shutil
import subprocess
import sys

from platformio.builder.tools.piobuild import ProcessFlags as process_flags
from SCons.Script import AlwaysBuild, Default, DefaultEnvironment

env = DefaultEnvironment()

PREFIX = "arm-none-eabi-"
if not shutil.which(PREFIX + "g++", path=env["ENV"].get("PATH")):
    sys.stderr.write(
        "Error: %sg++ is not on PATH. Install the ARM toolchain with "
        "tools/install-arm.sh (Debian gcc-arm-none-eabi, newlib, libstdc++).\n" % PREFIX
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

# Bare metal: every function and object in its own section so --gc-sections drops what
# main() does not reach; our own start-up code instead of crt0.
env.Append(
    ASFLAGS=["-x", "assembler-with-cpp"],
    CCFLAGS=["-ffunction-sections", "-fdata-sections"],
    LINKFLAGS=[
        "-nostartfiles",
        "-Wl,--gc-sections",
        "-Wl,-Map,${BUILD_DIR}/${PROGNAME}.map",
        "-Wl,--print-memory-usage",
    ],
)

# build_flags all land in CCFLAGS, which C files get too: move the C++-only ones to
# CXXFLAGS (else cc1 warns "valid for C++ but not for C" on start-up code in C).
CXX_ONLY_FLAGS = (
    "-fno-rtti",
    "-frtti",
    "-fno-threadsafe-statics",
    "-fthreadsafe-statics",
    "-fno-use-cxa-atexit",
    "-fuse-cxa-atexit",
    "-fvisibility-inlines-hidden",
    "-fno-enforce-eh-specs",
)


def _process_flags_cxx_aware(env, flags):
    process_flags(env, flags)
    moved = [f for f in env.get("CCFLAGS", []) if f in CXX_ONLY_FLAGS]
    if moved:
        env.Replace(CCFLAGS=[f for f in env["CCFLAGS"] if f not in CXX_ONLY_FLAGS])
        env.Append(CXXFLAGS=moved)


env.AddMethod(_process_flags_cxx_aware, "ProcessFlags")

ldscript = env.GetProjectOption("custom_ldscript", "")
if ldscript:
    env.Replace(LDSCRIPT_PATH=os.path.join(env.subst("$PROJECT_DIR"), ldscript))

target_elf = env.BuildProgram()

if env.get("LDSCRIPT_PATH"):
    env.Depends(target_elf, env["LDSCRIPT_PATH"])

# build_flags were parsed inside BuildProgram into CCFLAGS; command lines are expanded
# only when the link runs, so appending now still reaches the linker.
MACHINE_PREFIXES = (
    "-mcpu=",
    "-march=",
    "-mthumb",
    "-marm",
    "-mfpu=",
    "-mfloat-abi=",
    "--specs=",
    "-specs=",
)
machine = [
    f for f in env.get("CCFLAGS", []) if isinstance(f, str) and f.startswith(MACHINE_PREFIXES)
]
env.Append(LINKFLAGS=[f for f in machine if f not in env["LINKFLAGS"]])
env.Append(ASFLAGS=[f for f in machine if not f.startswith(("--specs=", "-specs="))])


def print_memory(target, source, env):  # pylint: disable=unused-argument
    elf = str(source[0])
    out = subprocess.run(
        [env.subst("$SIZETOOL"), "-B", "-d", elf], check=True, capture_output=True, text=True
    ).stdout
    print(out.rstrip())
    text, data, bss = (int(v) for v in out.splitlines()[1].split()[:3])
    print("Flash: %d bytes (text %d + data %d)" % (text + data, text, data))
    print("RAM:   %d bytes (data %d + bss %d), stack not included" % (data + bss, data, bss))


target_size = env.Alias(
    "size", target_elf, env.VerboseAction(print_memory, "Memory use of $SOURCE")
)
AlwaysBuild(target_size)
# PlatformIO drops a default target named "size" when SIZETOOL is set; keep ours.
memreport = env.Alias(
    "memreport", target_elf, env.VerboseAction(print_memory, "Memory use of $SOURCE")
)
AlwaysBuild(memreport)

Default([target_elf, memreport])
