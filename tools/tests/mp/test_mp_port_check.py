"""`graspguide mp deploy|run|log --port`: a port that does not exist is refused first,
before anything is built or claimed."""

from __future__ import annotations

import os
import pty
from pathlib import Path

import pytest

from graspguide.cli import main
from graspguide.mp.deploy import MpToolError, check_port

ROOT = Path(__file__).resolve().parents[3]
PROTOCOL = str(ROOT / "protocols" / "paper.toml")
MISSING = "/dev/ttyUSB-graspguide-missing"


@pytest.mark.parametrize(
    "argv",
    [
        ["deploy", "--plan-protocol", PROTOCOL, "--participant", "U3", "--levels", "--new-store"],
        ["deploy"],
        ["run"],
        ["log", "--out", "OUT"],
    ],
    ids=["deploy-plan", "deploy", "run", "log"],
)
def test_a_missing_port_fails_before_any_build_or_claim(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    staging = tmp_path / "staging"
    extra = ["--staging", str(staging)] if argv[0] == "deploy" else []
    argv = [a.replace("OUT", str(tmp_path / "out")) for a in argv]
    assert main(["mp", *argv[:1], "--port", MISSING, *argv[1:], *extra]) == 1
    out, err = capsys.readouterr()
    assert out == "", out  # no "16 files ... in a NEW results store"
    assert f"--port {MISSING}: no such serial port" in err, err
    assert "graspguide ports" in err  # how to find the right one
    assert not staging.exists() and not (tmp_path / "out").exists()


def test_existing_ports_and_the_names_mpremote_resolves_pass() -> None:
    master, slave = pty.openpty()
    try:
        check_port(os.ttyname(slave))
        check_port("port:" + os.ttyname(slave))
    finally:
        os.close(master)
        os.close(slave)
    for name in ("auto", "id:0123ABCD", "socket://127.0.0.1:2217", "rfc2217://host:4000"):
        check_port(name)


def test_a_file_or_folder_is_not_a_port(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("")
    for path, word in ((tmp_path / "f", "file"), (tmp_path, "folder")):
        with pytest.raises(MpToolError, match=f"that is a {word}, not a serial port"):
            check_port(str(path))
