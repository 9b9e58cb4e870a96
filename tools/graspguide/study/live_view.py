"""The live status of `graspguide stream`: a rich panel on a terminal, plain periodic lines
otherwise."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class StatusView:
    """Live status: a rich panel on a terminal, plain periodic lines otherwise."""

    def __init__(self, k: int, out: TextIO | None = None, period_s: float = 1.0):
        self.out = out or sys.stdout
        self.k = k
        self.period_s = period_s
        self.next_t = 0.0
        self.live = None
        self.last_draw = 0.0
        if self.out.isatty():
            try:
                from rich.live import Live

                self.live = Live(self._render({}), refresh_per_second=10, transient=False)
                self.live.start()
            except ImportError:  # pragma: no cover - rich is a dependency
                self.live = None

    def _render(self, s):
        from rich.table import Table

        table = Table(title="graspguide stream", show_header=False, expand=False)
        table.add_row("time", f"{s.get('t_s', 0.0):7.2f} s")
        table.add_row("error", f"{s.get('error_deg', float('nan')):7.2f} deg")
        for i, pwm in enumerate(s.get("pwm", [0] * self.k)[: self.k]):
            bar = "#" * (pwm * 30 // 255)
            table.add_row(f"motor {i + 1}", f"{pwm:3d} [green]{bar:<30}[/green]")
        table.add_row("rate", f"{s.get('rate_hz', 0.0):7.1f} poses/s")
        table.add_row("sent / telemetry", f"{s.get('sent', 0)} / {s.get('received', 0)}")
        table.add_row("dropped", str(s.get("dropped", 0)))
        return table

    def update(self, s, force: bool = False) -> None:
        if self.live is not None:
            now = time.monotonic()
            if force or now - self.last_draw >= 0.1:
                self.live.update(self._render(s))
                self.last_draw = now
            return
        if force or s["t_s"] >= self.next_t:
            self.next_t = s["t_s"] + self.period_s
            pwm = " ".join(f"{p:3d}" for p in s["pwm"][: self.k])
            print(
                f"t={s['t_s']:7.2f}s error={s['error_deg']:7.2f}deg pwm=[{pwm}] "
                f"rate={s['rate_hz']:.1f}/s sent={s['sent']} dropped={s['dropped']}",
                file=self.out,
                flush=True,
            )

    def close(self) -> None:
        if self.live is not None:
            self.live.stop()
            self.live = None


__all__ = ["StatusView"]
