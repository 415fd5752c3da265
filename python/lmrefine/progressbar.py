"""Progress callbacks: what their answer means, and a terminal progress bar
usable as any lmrefine ``progress`` callback."""

import sys
import time


def cancels(answer):
    """True when a ``progress(fraction, stage)`` callback's return value asks
    to cancel: any false value but None (a plain print callback returns None
    and must not stop the work). The native calls read it the same way
    (native/bindings/progress_binding.cpp); Python code that reads an answer
    itself asks here."""
    return answer is not None and not answer


class ProgressBar:
    """Call it as ``progress(fraction, stage)``; it redraws at most 10 times a
    second on a terminal, and prints one line per stage otherwise (logs of
    batch jobs stay readable). Never cancels (returns None)."""

    def __init__(self, stream=None, width=30):
        self.stream = stream or sys.stderr
        self.width = width
        self.stage = None
        self.last_draw = 0.0
        self.interactive = hasattr(self.stream, "isatty") and self.stream.isatty()

    def __call__(self, fraction, stage):
        now = time.monotonic()
        if stage != self.stage:
            if self.stage is not None and self.interactive:
                self.stream.write("\n")
            self.stage = stage
            if not self.interactive:
                self.stream.write(f"{stage}...\n")
                self.stream.flush()
        if not self.interactive or (now - self.last_draw < 0.1 and fraction < 1.0):
            return None
        self.last_draw = now
        filled = int(round(self.width * max(0.0, min(1.0, fraction))))
        self.stream.write(f"\r{stage:<24} [{'#' * filled}{'.' * (self.width - filled)}] {fraction * 100:5.1f}%")
        self.stream.flush()
        return None

    def close(self):
        if self.stage is not None and self.interactive:
            self.stream.write("\n")
            self.stream.flush()
        self.stage = None
