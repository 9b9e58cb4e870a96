"""The operator's keys while a study runs with a person: read from the terminal in cbreak
mode without blocking the pose loop, and typed lines (a reason, a note, a TLX answer)
read in the terminal's own line mode. The terminal is restored on every way out."""

from __future__ import annotations

import os
import select
import sys
import termios
import tty
from typing import Any, TextIO

# The keys (docs/study.md, "Running a study with people").
PAUSE, REDO, SKIP, NOTE = "p", "r", "s", "n"
KEYS_HELP = "keys: p pause, r redo, s skip, n note"

_ENTER = ("\r", "\n")
_BACKSPACE = ("\x7f", "\x08")
_ESCAPE = "\x1b"


class ConsoleClosed(Exception):
    """The terminal's input ended (EOF) while a line or a key was awaited."""


class OperatorConsole:
    """Keys from a terminal file descriptor (stdin by default).

    :meth:`poll` never blocks: it returns ``("key", k)`` for p, r, s and
    ``("note", text)`` once a note started with n has been typed and ended with Enter
    (the note is composed key by key while the trial runs; Escape drops it).
    :meth:`read_line` and :meth:`wait_key` block (between trials, or with the motors
    off). Use as a context manager: the terminal's settings are put back on exit."""

    def __init__(self, fd: int | None = None, out: TextIO | None = None):
        self.fd = sys.stdin.fileno() if fd is None else fd
        self.out = out or sys.stdout
        self._saved: list[Any] | None = None
        self._note: list[str] | None = None  # a note being typed, else None
        # Keys read after the one that stopped a poll (typed quickly, e.g. p then
        # Enter): the next wait_key or read_line gets them, none is lost.
        self._pending = ""

    @staticmethod
    def available(fd: int | None = None) -> bool:
        """Whether ``fd`` (stdin) is a terminal, where keys can be read one by one."""
        try:
            return os.isatty(sys.stdin.fileno() if fd is None else fd)
        except (OSError, ValueError):
            return False

    def __enter__(self) -> OperatorConsole:
        self._saved = termios.tcgetattr(self.fd)
        tty.setcbreak(self.fd, termios.TCSANOW)
        return self

    def __exit__(self, *exc: Any) -> None:
        self.restore()

    def restore(self) -> None:
        """The terminal as it was before (idempotent)."""
        if self._saved is not None:
            try:
                termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            except termios.error:
                pass  # the terminal is gone (closed window): nothing to restore
            self._saved = None

    # ---- keys, not blocking
    def _read_ready(self, timeout_s: float) -> str:
        ready, _, _ = select.select([self.fd], [], [], timeout_s)
        if not ready:
            return ""
        data = os.read(self.fd, 256)
        if not data:
            raise ConsoleClosed("the terminal's input ended")
        return data.decode("utf-8", "replace")

    def poll(self) -> list[tuple[str, str]]:
        """The operator's actions since the last call, at once (no wait). The keys after
        a p, r or s are kept for what the runner asks next (the pause's Enter, a reason)."""
        text, self._pending = self._pending + self._read_ready(0.0), ""
        actions: list[tuple[str, str]] = []
        for i, ch in enumerate(text):
            action = self._feed(ch)
            if action is not None:
                actions.append(action)
                if action[0] == "key":
                    self._pending = text[i + 1 :]
                    break
        return actions

    def _feed(self, ch: str) -> tuple[str, str] | None:
        if self._note is not None:
            if ch in _ENTER:
                text = "".join(self._note).strip()
                self._note = None
                self._echo("\n")
                return ("note", text) if text else None
            if ch == _ESCAPE:
                self._note = None
                self._echo(" (note dropped)\n")
            elif ch in _BACKSPACE:
                if self._note:
                    self._note.pop()
                    self._echo("\b \b")
            elif ch.isprintable():
                self._note.append(ch)
                self._echo(ch)
            return None
        key = ch.lower()
        if key == NOTE:
            self._note = []
            self._echo("\nnote (Enter to save, Esc to drop): ")
            return None
        if key in (PAUSE, REDO, SKIP):
            return ("key", key)
        return None

    @property
    def typing(self) -> bool:
        """A note is being typed (the progress line should not overwrite it)."""
        return self._note is not None

    def _echo(self, text: str) -> None:
        self.out.write(text)
        self.out.flush()

    # ---- blocking
    def wait_key(self, timeout_s: float | None = None) -> str | None:
        """One key (Enter is ``"\\n"``), or None after ``timeout_s``."""
        if self._pending:
            ch, self._pending = self._pending[0], self._pending[1:]
        else:
            ready, _, _ = select.select([self.fd], [], [], timeout_s)
            if not ready:
                return None
            data = os.read(self.fd, 1)
            if not data:
                raise ConsoleClosed("the terminal's input ended")
            ch = data.decode("utf-8", "replace")
        return "\n" if ch in _ENTER else ch

    def read_line(self, prompt: str) -> str:
        """A line typed in the terminal's line mode (echo, editing), then cbreak again.
        EOFError when the input ends (as input() does)."""
        head, sep, rest = self._pending.replace("\r", "\n").partition("\n")
        if sep:  # typed ahead, Enter included
            self._pending = rest
            self._echo(prompt + head + "\n")
            return head
        self._pending = ""
        saved = self._saved
        if saved is not None:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, saved)
        try:
            self._echo(prompt + head)
            chunks: list[bytes] = [head.encode("utf-8")]
            while True:
                data = os.read(self.fd, 1024)
                if not data:
                    raise EOFError
                chunks.append(data)
                if b"\n" in data or b"\r" in data:
                    break
            return b"".join(chunks).decode("utf-8", "replace").splitlines()[0]
        finally:
            if saved is not None:
                tty.setcbreak(self.fd, termios.TCSADRAIN)

    def read_reason(self, what: str) -> str:
        """A non-empty reason for ``what`` (asked again when empty)."""
        while True:
            text = self.read_line(f"reason for the {what}: ").strip()
            if text:
                return text
            self._echo(f"  a {what} needs a reason (a few words)\n")


__all__ = ["OperatorConsole", "ConsoleClosed", "KEYS_HELP", "PAUSE", "REDO", "SKIP", "NOTE"]
