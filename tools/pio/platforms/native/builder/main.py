# GraspGuide local "native" dev-platform builder (offline replacement for
# PlatformIO's registry platform "native"): build with the host toolchain.
from SCons.Script import AlwaysBuild, Default, DefaultEnvironment

env = DefaultEnvironment()

# Drop the generic C/C++ tools and let SCons pick the host GCC/G++ instead,
# keeping the C/C++ flags that PlatformIO has already put in the environment.
for key in ("CC", "CXX"):
    if key in env:
        del env[key]
backup_cflags = env.get("CFLAGS", [])
backup_cxxflags = env.get("CXXFLAGS", [])
env.Tool("gcc")
env.Tool("g++")
env.Append(CFLAGS=backup_cflags, CXXFLAGS=backup_cxxflags)

target_bin = env.BuildProgram()

target_size = env.Alias(
    "size", target_bin, env.VerboseAction("$SIZEPRINTCMD", "Calculating size $SOURCE")
)
AlwaysBuild(target_size)

Default([target_bin])
