"""Each simulated device kind keeps its build: PlatformIO deletes its whole build folder when
its project checksum changes (another core_dir, a source file added), so a build of one
env must not take another kind's program with it; a missing one is built on first use
(graspguide.devices.builds). On scratch copies of the repository (symlinks to its
sources, their own .pio), with the real pio and the real simulated device."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys

import pytest
from conftest import REPO_ROOT, subprocess_env

from graspguide.devices import qemu_firmware as gq
from graspguide.devices import sim as gsim
from graspguide.link import client as dv
from graspguide.link.transport import SimNotBuilt

VENV_BIN = os.path.join(REPO_ROOT, ".venv", "bin")
# What pio reads of a project; the scratch repository links to them.
LINKED = (
    "platformio.ini",
    "src",
    "lib",
    "tools",
    "test",
    "promini",
    ".venv",
    ".pio-core",
    ".tools",
)


def scratch_repo(tmp_path) -> str:
    root = tmp_path / "repo"
    root.mkdir()
    for name in LINKED:
        if os.path.exists(os.path.join(REPO_ROOT, name)):
            os.symlink(os.path.join(REPO_ROOT, name), root / name)
    return str(root)


def pio_env(tmp_path, **extra) -> dict:
    env = subprocess_env()
    for key in ("PLATFORMIO_CORE_DIR", "PLATFORMIO_BUILD_DIR"):
        env.pop(key, None)
    env["PATH"] = VENV_BIN + os.pathsep + env.get("PATH", "")
    env["HOME"] = str(tmp_path / "home")  # a pio without PLATFORMIO_CORE_DIR uses ~/.platformio
    env["PLATFORMIO_DISABLE_UPGRADE_CHECK"] = "true"
    env["PLATFORMIO_SETTING_ENABLE_TELEMETRY"] = "No"
    env.update(extra)
    return env


def project_checksum(root: str, env: dict) -> str:
    """The checksum pio writes into a build folder it builds into, for the project at
    ``root`` under ``env``."""
    code = (
        "from platformio.project.config import ProjectConfig\n"
        "from platformio.project.helpers import compute_project_checksum\n"
        "print(compute_project_checksum(ProjectConfig.get_instance('platformio.ini')))"
    )
    done = subprocess.run(
        [os.path.join(VENV_BIN, "python"), "-c", code],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.strip()


def install_built_sim(root: str, tmp_path) -> str:
    """The repository's simulated device, placed in ``root`` where its launcher looks,
    with the checksum file the set-up's `pio run -e sim` leaves beside it."""
    real = gsim.find_sim_binary(None)
    target = os.path.join(root, gsim.SIM_RELATIVE_PATH)
    os.makedirs(os.path.dirname(target))
    shutil.copy2(real, target)
    build_dir = os.path.dirname(os.path.dirname(target))
    with open(os.path.join(build_dir, "project.checksum"), "w") as f:
        f.write(project_checksum(root, pio_env(tmp_path, PLATFORMIO_CORE_DIR=".pio-core")))
    return target


def command_in(text: str, what: str) -> str:
    """The shell command in an error message: the line that holds ``what`` (inside
    backticks when it is quoted so)."""
    for line in text.splitlines():
        if what in line:
            quoted = re.search(r"`([^`]*" + re.escape(what) + r"[^`]*)`", line)
            return (quoted[1] if quoted else line).strip()
    raise AssertionError(f"no command with {what!r} in: {text}")


def launches(root: str, monkeypatch) -> str:
    monkeypatch.setattr(gsim, "find_repo_root", lambda: root)
    with gsim.SimulatedDevice(start=True) as dev:
        return str(dv.DeviceClient(dev).hello().board)


def test_building_the_qemu_firmware_as_its_error_says_keeps_the_simulated_device(
    tmp_path, monkeypatch
):
    """`--port qemu` without the firmware names a command; running it (and a bare `pio run
    -e m4f_firmware` without PLATFORMIO_CORE_DIR, whose project checksum differs) leaves
    the simulated device where `--port sim` finds it. Each pio run gets `-t clean` in place
    of the compile: pio's clean of a build folder whose checksum differs, which deleted the
    other builds, runs before any target."""
    root = scratch_repo(tmp_path)
    sim = install_built_sim(root, tmp_path)
    monkeypatch.delenv(gq.QEMU_FIRMWARE_ENV, raising=False)
    monkeypatch.delenv(gsim.SIM_ENV, raising=False)
    monkeypatch.setattr(gq, "find_repo_root", lambda: root)
    with pytest.raises(SimNotBuilt) as missing:
        gq.find_firmware_elf()
    printed = command_in(str(missing.value), "pio run -e m4f_firmware")
    for command in (printed, "pio run -e m4f_firmware"):
        done = subprocess.run(
            ["bash", "-c", f"{command} -t clean"],
            cwd=root,
            env=pio_env(tmp_path),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, f"{command}: {done.stdout}{done.stderr}"
        assert os.path.isfile(sim), f"`{command}` deleted the simulated device {sim}"
    assert launches(root, monkeypatch) == "sim-posix"


def test_a_missing_simulated_device_is_built_on_first_use_showing_progress(
    tmp_path, monkeypatch, capfd
):
    """A fresh checkout (no build at all): `--port sim` builds the simulated device into its
    own folder, showing pio's output, then runs it. The real build: about a minute of two
    cores."""
    root = scratch_repo(tmp_path)
    monkeypatch.delenv(gsim.SIM_ENV, raising=False)
    assert launches(root, monkeypatch) == "sim-posix"
    err = capfd.readouterr().err
    assert "building the simulated device" in err and "PLATFORMIO_BUILD_DIR=" in err
    assert "Linking" in err  # pio's own progress, passed on
    assert os.path.isfile(os.path.join(root, ".pio", "build-sim", "sim", "program"))
    assert not os.path.exists(os.path.join(root, ".pio", "build"))  # nobody else's folder


def test_without_pio_the_error_names_the_exact_command(tmp_path, monkeypatch):
    from graspguide.devices import builds as db

    root = tmp_path / "bare"
    (root / "lib" / "graspguide_link").mkdir(parents=True)
    (root / "platformio.ini").write_text("[env:sim]\n")
    monkeypatch.delenv(gsim.SIM_ENV, raising=False)
    monkeypatch.setattr(gsim, "find_repo_root", lambda: str(root))
    with pytest.raises(SimNotBuilt) as info:
        gsim.SimulatedDevice()
    text = str(info.value)
    assert db.SIM.command(str(root)) in text
    assert "PLATFORMIO_BUILD_DIR=.pio/build-sim " in text and "pio run -e sim" in text
    assert not (root / ".pio").exists()  # nothing was built


def test_every_device_kind_builds_into_a_folder_no_other_kind_cleans():
    from graspguide.devices import builds as db

    dirs = {env: b.relative_build_dir() for env, b in db.BUILDS.items()}
    assert len(set(dirs.values())) == len(dirs)
    for env, b in db.BUILDS.items():
        assert b.relative_path().startswith(dirs[env] + os.sep)
        assert not b.relative_path().startswith(os.path.join(".pio", "build") + os.sep)
    assert gsim.SIM_RELATIVE_PATH == db.SIM.relative_path()
    assert gq.FIRMWARE_RELATIVE_PATH == db.M4F_FIRMWARE.relative_path()
    # the test command builds each kind where its launcher looks
    with open(os.path.join(REPO_ROOT, "tools", "run-tests.sh")) as f:
        run_tests = f.read()
    listed = re.search(r'^DEVICE_ENVS=" (.*) "$', run_tests, re.M)
    assert listed is not None and set(listed[1].split()) == set(db.BUILDS) - {"sim"}
    assert 'PLATFORMIO_BUILD_DIR="$ROOT/.pio/build-$env"' in run_tests
    with open(os.path.join(REPO_ROOT, "tools", "bootstrap.sh")) as f:
        assert 'PLATFORMIO_BUILD_DIR="$ROOT/.pio/build-sim"' in f.read()


def test_the_readmes_promini_sim_latency_works_on_a_fresh_checkout(tmp_path):
    """`graspguide latency --port promini-sim` (the README's example) in a checkout where the
    sketch was never built: the command builds it (arduino-cli, saying so), then measures.
    SIMULATED (the sketch under simavr)."""
    root = scratch_repo(tmp_path)
    assert not os.path.exists(os.path.join(root, "build"))
    out = tmp_path / "promini.json"
    env = subprocess_env()
    env.pop("GRASPGUIDE_PROMINI_ELF", None)
    done = subprocess.run(
        [sys.executable, "-m", "graspguide", "latency", "--port", "promini-sim"]
        + ["--count", "20", "--json", str(out)],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "building the Pro Mini sketch" in done.stderr
    assert os.path.isfile(os.path.join(root, "build", "promini", "GraspGuideProMini.ino.elf"))
    result = json.loads(out.read_text())
    assert result["count"] == 20 and result["board"] == "promini"
