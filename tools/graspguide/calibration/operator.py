"""The operator's keyboard: the participant says what they felt, the operator types it.
One line per answer (y/n for detection, 1/2 for which of two felt stronger); anything
else is asked again; q (or the end of input) aborts the calibration."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import TextIO

from graspguide.calibration.session import CalibrationAborted

QUIT = "q"
DETECTION_KEYS = {"y": True, "yes": True, "n": False, "no": False}
COMPARE_KEYS = {"1": 1, "first": 1, "2": 2, "second": 2}


def _flush_typed_ahead(stream: TextIO) -> None:
    """Drop keys typed while the stimulus ran: an answer must come after the question."""
    try:
        import termios

        if stream.isatty():
            termios.tcflush(stream.fileno(), termios.TCIFLUSH)
    except (ImportError, OSError, ValueError):
        pass


class OperatorResponder:
    """Answers typed on ``inp`` (a terminal), questions on ``out``."""

    simulated = False

    def __init__(self, inp: TextIO | None = None, out: TextIO | None = None) -> None:
        self.inp = inp or sys.stdin
        self.out = out or sys.stdout

    def _ask(self, question: str, keys: Mapping[str, object], help_text: str) -> object:
        _flush_typed_ahead(self.inp)
        while True:
            self.out.write(question)
            self.out.flush()
            line = self.inp.readline()
            if not line:
                raise CalibrationAborted("the operator's input ended (end of file)")
            key = line.strip().lower()
            if key == QUIT:
                raise CalibrationAborted("the operator quit (q)")
            if key in keys:
                return keys[key]
            self.out.write(f"  {key!r}? type {help_text}{os.linesep}")

    def detect(self, finger: str, pwm: int, n: int) -> bool:
        shown = "catch trial, no stimulus" if pwm == 0 else f"PWM {pwm}"
        return bool(
            self._ask(
                f"{finger} detection #{n} ({shown}): did the participant feel it? [y/n, q quits] ",
                DETECTION_KEYS,
                "y (felt it), n (did not) or q (quit)",
            )
        )

    def compare(self, finger: str, first: tuple[str, int], second: tuple[str, int], n: int) -> int:
        which = self._ask(
            f"{finger} matching #{n} (1: {first[0]} PWM {first[1]}, 2: {second[0]} PWM "
            f"{second[1]}): which felt stronger? [1/2, q quits] ",
            COMPARE_KEYS,
            "1 (the first felt stronger), 2 (the second) or q (quit)",
        )
        return int(which)  # type: ignore[call-overload]


__all__ = ["OperatorResponder", "DETECTION_KEYS", "COMPARE_KEYS", "QUIT"]
