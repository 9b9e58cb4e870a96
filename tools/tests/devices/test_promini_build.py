"""The Pro Mini sketch (promini/GraspGuideProMini) built with arduino-cli, offline, against
Debian's AVR core (graspguide.promini.build): it builds, fits the Pro Mini's flash and static
RAM budget, arduino-cli's size report agrees with avr-size and with the board's limits in
the core's boards.txt, it has no warning, and it uses the per-frame layer and the
per-frame-only device from lib/ as Arduino libraries. A missing arduino-cli is a failure
that names tools/bootstrap.sh, never a skip."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import REPO_ROOT

from graspguide.promini import build

ROOT = Path(REPO_ROOT)
BOARDS_TXT = Path("/usr/share/arduino/hardware/arduino/avr/boards.txt")


@pytest.fixture(scope="module")
def sketch(tmp_path_factory):
    try:
        result = build.build_sketch(ROOT, tmp_path_factory.mktemp("promini"))
    except build.ArduinoCliMissing as e:
        pytest.fail(str(e))
    # The stack is measured under simavr (`graspguide bench --target avr`); the figures
    # printed here are the static ones.
    print(
        f"\nPro Mini sketch: flash {result.flash_bytes} B of {result.flash_max_bytes} B, "
        f"static RAM {result.static_ram_bytes} B of {result.ram_max_bytes} B "
        f"(stack not yet measured), arduino-cli compile {result.seconds:.1f} s"
    )
    return result


def _boards_txt(key: str) -> int:
    for line in BOARDS_TXT.read_text().splitlines():
        if line.startswith(key + "="):
            return int(line.split("=", 1)[1])
    raise AssertionError(f"{key} not in {BOARDS_TXT}")


def test_the_sketch_fits_the_flash_and_static_ram_budget(sketch):
    assert 0 < sketch.flash_bytes <= build.FLASH_BUDGET_BYTES
    # Static RAM alone for now; static RAM + measured stack is checked under simavr.
    assert 0 < sketch.static_ram_bytes <= build.RAM_BUDGET_BYTES


def test_the_limits_are_the_pro_mini_3v3_8mhz_board_of_the_core(sketch):
    board = "pro.menu.cpu.8MHzatmega328"
    assert sketch.flash_max_bytes == _boards_txt(f"{board}.upload.maximum_size")
    assert sketch.ram_max_bytes == _boards_txt(f"{board}.upload.maximum_data_size")
    assert build.FLASH_BUDGET_BYTES <= sketch.flash_max_bytes


def test_the_size_report_agrees_with_avr_size(sketch):
    avr_size = shutil.which("avr-size")
    assert avr_size, "avr-size is missing: run tools/bootstrap.sh (Debian's binutils-avr)"
    out = subprocess.run(
        [avr_size, "-A", str(sketch.elf)], check=True, capture_output=True, text=True
    ).stdout
    sections = {m[1]: int(m[2]) for m in re.finditer(r"^(\.\w+)\s+(\d+)\s+\d+$", out, re.MULTILINE)}
    assert sketch.flash_bytes == sections[".text"] + sections[".data"]
    assert sketch.static_ram_bytes == sections[".data"] + sections.get(".bss", 0) + sections.get(
        ".noinit", 0
    )
    assert sketch.hex.stat().st_size > 0


@pytest.mark.parametrize("lib", build.LIBRARIES)
def test_it_uses_the_repositorys_libraries_as_arduino_libraries(sketch, lib):
    props = (ROOT / lib / "library.properties").read_text()
    name = re.search(r"^name=(.*)$", props, re.MULTILINE)
    assert name, f"{lib}/library.properties has no name="
    # arduino-cli's closing table: "<name> <version> <path>", one line per library used.
    used = [
        line
        for line in sketch.output.splitlines()
        if line.startswith(name[1] + " ") and line.rstrip().endswith(str(ROOT / lib))
    ]
    assert used, f"{name[1]} from {ROOT / lib} not used:\n{sketch.output[-800:]}"
    arches = re.search(r"^architectures=(.*)$", props, re.MULTILINE)
    assert arches and "avr" in arches[1].split(","), "the sketch compiles it for avr"


def test_the_build_has_no_warnings(sketch):
    # Ours: the sketch and lib/. Debian's Arduino core warns about its own files (new.cpp's
    # unused parameters) on a cold build cache; those are not ours to fix.
    ours = [
        line
        for line in sketch.output.splitlines()
        if "warning:" in line and "/hardware/arduino/avr/" not in line
    ]
    assert not ours, "\n".join(ours[:20])
    assert "error:" not in sketch.output


def test_the_ino_holds_no_code():
    # Debian's universal-ctags makes no prototypes: a function in the .ino fails to build.
    ino = ROOT / "promini" / build.SKETCH_NAME / f"{build.SKETCH_NAME}.ino"
    lines = [line.strip() for line in ino.read_text().splitlines() if line.strip()]
    assert lines and all(line.startswith("//") for line in lines)


def test_a_missing_arduino_cli_names_the_fix(tmp_path):
    with pytest.raises(build.ArduinoCliMissing, match=r"tools/bootstrap\.sh"):
        build.arduino_cli_paths(tmp_path)


def test_output_without_the_size_report_is_a_clear_error():
    with pytest.raises(build.SketchBuildFailed, match="Sketch uses N bytes"):
        build.parse_sizes("Compilation finished.\n")


def test_pio_run_e_promini_builds_the_same_sketch(sketch):
    """PlatformIO's offline local AVR dev-platform builds the very files arduino-cli does:
    the same flash and static RAM, with -Werror."""
    from graspguide.bench.pio_build import pio_env, pio_executable

    class PioMissing(Exception):
        pass

    pio = pio_executable(ROOT, PioMissing, " (run tools/bootstrap.sh)")
    res = subprocess.run(
        [pio, "run", "-e", "promini"],
        cwd=ROOT,
        env=pio_env(ROOT),
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    flash = re.search(r"^Flash: (\d+) bytes", res.stdout, re.MULTILINE)
    ram = re.search(r"^RAM:\s+(\d+) bytes", res.stdout, re.MULTILINE)
    assert flash and ram, res.stdout[-2000:]
    assert (int(flash[1]), int(ram[1])) == (sketch.flash_bytes, sketch.static_ram_bytes)
