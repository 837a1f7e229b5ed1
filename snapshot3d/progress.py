"""Progress of long work (DESIGN section 2), on stderr: a tqdm bar with an ETA when stderr is a terminal;
when it is not (a log file, a job runner), a plain line every 5% of the work, at most one per 10 s and none
in the first 10 s, so that a long fit shows in its log and a short command prints nothing. Set
SNAPSHOT3D_PROGRESS=1 to force the bar, 0 to hide both."""
from __future__ import annotations

import os
import sys
import time

__all__ = ["progress", "LogLines"]


def _enabled() -> bool | None:
    flag = os.environ.get("SNAPSHOT3D_PROGRESS")
    if flag is not None:
        return flag not in ("", "0")
    return None  # a bar for a terminal, log lines otherwise


def _clock(seconds: float) -> str:
    m, s = divmod(int(seconds), 60)
    return f"{m // 60}h{m % 60:02d}m" if m >= 60 else f"{m}m{s:02d}s"


class LogLines:
    """tqdm's `.update(n)`, `.set_postfix_str(s)`, `.close()` and context manager, written as one line per
    `step` of the work ("fit: 35% (525/1500 step), 2m10s, about 4m03s left"), none before `quiet_s` seconds and
    at most one per `every_s` (and always the last, once past `quiet_s`)."""

    def __init__(self, total: int, desc: str, unit: str = "step", stream=None, step: float = 0.05,
                 quiet_s: float = 10.0, every_s: float = 10.0, clock=time.monotonic):
        self.total, self.desc, self.unit, self.stream = max(int(total), 1), desc, unit, stream or sys.stderr
        self.step, self.quiet_s, self.every_s, self.clock = step, quiet_s, every_s, clock
        self.n, self.postfix, self.t0 = 0, "", clock()
        self.next_share, self.last = step, -every_s

    def update(self, n: int = 1) -> None:
        self.n += n
        self.refresh()

    def refresh(self) -> None:
        """Write a line if the work has reached the next `step` (also after `n` was set directly, as tqdm allows)."""
        now, share = self.clock(), min(self.n / self.total, 1.0)
        if share < self.next_share or now - self.t0 < self.quiet_s or (now - self.last < self.every_s and share < 1):
            return
        self.next_share = (int(share / self.step) + 1) * self.step
        self.last, spent = now, now - self.t0
        left = f", about {_clock(spent / share - spent)} left" if share < 1 else ""
        extra = f", {self.postfix}" if self.postfix else ""
        print(f"{self.desc}: {share:.0%} ({self.n}/{self.total} {self.unit}), {_clock(spent)}{left}{extra}",
              file=self.stream, flush=True)

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        self.postfix = s

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress(total: int, desc: str, unit: str = "step"):
    """A bar over `total` units: `.update(n)`, `.set_postfix_str(s)`, `.close()` (also a context manager)."""
    on = _enabled()
    if on is None and not (hasattr(sys.stderr, "isatty") and sys.stderr.isatty()):
        return LogLines(total, desc, unit)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=False,
                disable=not on if on is not None else False, mininterval=0.5)
