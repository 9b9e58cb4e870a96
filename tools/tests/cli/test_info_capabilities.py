"""`graspguide info` shows what a device can do (HELLO_REPLY.capabilities, by name) and
which build it runs (build_id: the commit it was built from, on every board the tools
build, the Pro Mini's sketch included). On the real simulated device and the real sketch
under simavr."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

from conftest import REPO_ROOT, subprocess_env

from graspguide.link import messages


def info(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "graspguide", "info", *args],
        capture_output=True,
        text=True,
        env=env or subprocess_env(),
        cwd=REPO_ROOT,
        timeout=120,
    )


def names_a_commit(build_id: str) -> bool:
    done = subprocess.run(
        ["git", "-C", REPO_ROOT, "rev-parse", "--verify", "--quiet", f"{build_id}^{{commit}}"],
        capture_output=True,
        text=True,
    )
    return done.returncode == 0


def test_capability_bits_are_named_after_the_protocol():
    from graspguide.cli.info import capability_names

    assert capability_names(0) == []
    assert capability_names(messages.CAPABILITY_PER_FRAME) == ["per_frame"]
    every = (
        messages.CAPABILITY_FULL_SOLVE
        | messages.CAPABILITY_HOSTLESS
        | messages.CAPABILITY_SIM_MESSAGES
        | messages.CAPABILITY_PER_FRAME
    )
    assert capability_names(every) == ["full_solve", "hostless", "sim_messages", "per_frame"]
    assert capability_names(0x80 | messages.CAPABILITY_FULL_SOLVE) == ["full_solve", "bit0x80"]


def test_info_on_the_simulated_device_shows_its_capabilities_and_build():
    text = info("--port", "sim")
    assert text.returncode == 0, text.stderr
    assert re.search(r"^capabilities: +full_solve \(0x01\)$", text.stdout, re.M), text.stdout
    as_json = info("--port", "sim", "--json")
    assert as_json.returncode == 0, as_json.stderr
    data = json.loads(as_json.stdout)
    assert data["capabilities"] == ["full_solve"] and data["capabilities_bits"] == 1
    assert data["build_id"] != "00000000" and names_a_commit(data["build_id"])


def test_info_on_the_pro_mini_shows_per_frame_and_the_build_it_was_stamped_with(sketch_build):
    env = subprocess_env()
    env["GRASPGUIDE_PROMINI_ELF"] = str(sketch_build.elf)
    text = info("--port", "promini-sim", env=env)
    assert text.returncode == 0, text.stderr
    assert re.search(r"^capabilities: +per_frame \(0x08\)$", text.stdout, re.M), text.stdout
    as_json = info("--port", "promini-sim", "--json", env=env)
    assert as_json.returncode == 0, as_json.stderr
    data = json.loads(as_json.stdout)
    assert data["board"] == "promini" and data["capabilities"] == ["per_frame"]
    stamped = re.search(r"-DGRASPGUIDE_BUILD_ID=0x([0-9a-f]{8})u", " ".join(sketch_build.command))
    assert stamped is not None, sketch_build.command
    assert data["build_id"] == stamped[1] != "00000000"
    assert names_a_commit(data["build_id"])
    assert os.path.isfile(sketch_build.elf)
