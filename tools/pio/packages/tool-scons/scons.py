# GraspGuide local stand-in for PlatformIO's tool-scons launcher.
# PlatformIO runs this file with the interpreter it itself runs under (the
# project venv), where `scons==4.11.1` is pip-installed; so just start SCons.
import sys

try:
    import SCons
    import SCons.Script
except ImportError as exc:  # pragma: no cover - environment problem
    sys.stderr.write(
        "tool-scons: cannot import SCons (%s); run tools/bootstrap.sh to create "
        "the .venv with scons installed\n" % exc
    )
    sys.exit(2)

if __name__ == "__main__":
    SCons.Script.main()
