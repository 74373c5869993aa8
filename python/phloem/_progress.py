"""Progress reporting: API functions take ``progress(done, total)``; the CLI draws a bar.

The Rust engines queue their reports and the calling thread hands them to the callback, in
order, while it waits for the work (``rust/py/src/call.rs``), so a callback runs on the thread
that made the call. An exception it raises, like a Ctrl-C, stops the run within a fraction of
a second and propagates from the call.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

Progress = Callable[[int, int], None] | None


class Bar:
    """A small text progress bar on stderr, redrawn at most ten times a second.

    Draws only on a terminal, so logs and CI output stay clean; ``close()`` ends the line.
    """

    def __init__(self, label: str, stream: TextIO | None = None, enabled: bool = True) -> None:
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = enabled and self.stream.isatty()
        self.start = time.monotonic()
        self.last = 0.0

    def __call__(self, done: int, total: int) -> None:
        now = time.monotonic()
        if not self.enabled or (now - self.last < 0.1 and done < total):
            return
        self.last = now
        frac = done / total if total else 1.0
        filled = int(30 * frac)
        self.stream.write(
            f"\r{self.label} [{'#' * filled}{'.' * (30 - filled)}] {100 * frac:5.1f}% {now - self.start:6.1f}s"
        )
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
