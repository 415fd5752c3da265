"""Terminal progress of a batch: a bar per running level and one in total.

Progress events come from the workers (Dask's event log, on the client's
event-loop thread); the driver redraws from its own thread. On a terminal the
bars are redrawn in place; otherwise (a log file, CI) one line per level
start and end keeps the log readable.
"""

import sys
import threading
import time


def _bar(fraction, width):
    filled = int(round(width * max(0.0, min(1.0, fraction))))
    return "#" * filled + "." * (width - filled)


class BatchProgress:
    def __init__(self, total, stream=None, width=24):
        self.stream = stream or sys.stderr
        self.total = total
        self.width = width
        self.finished = 0
        self.running = {}  # name -> (fraction, stage)
        self.lock = threading.Lock()
        self.drawn_lines = 0
        self.interactive = hasattr(self.stream, "isatty") and self.stream.isatty()

    def event(self, name, state, fraction, stage):
        """A worker's report; thread-safe."""
        with self.lock:
            if state == "finished":
                self.running.pop(name, None)
                return
            if state == "started" and not self.interactive:
                self.stream.write(f"{name}: started\n")
                self.stream.flush()
            self.running[name] = (fraction, stage)

    def level_done(self, name, status, seconds, detail=""):
        """A level committed or given up: a permanent line above the bars."""
        with self.lock:
            self.running.pop(name, None)
            if status in ("done", "failed", "not run"):
                self.finished += 1
            self._clear()
            extra = f" ({detail})" if detail else ""
            self.stream.write(f"{name}: {status} in {seconds:.1f} s{extra}  [{self.finished}/{self.total}]\n")
            self.stream.flush()

    def message(self, text):
        with self.lock:
            self._clear()
            self.stream.write(text + "\n")
            self.stream.flush()

    def draw(self):
        if not self.interactive:
            return
        with self.lock:
            self._clear()
            lines = [f"{name[:20]:<20} [{_bar(f, self.width)}] {100 * f:3.0f}% {stage[:40]}"
                     for name, (f, stage) in sorted(self.running.items())]
            partial = sum(f for f, _ in self.running.values())
            done = (self.finished + partial) / max(1, self.total)
            lines.append(f"{'total':<20} [{_bar(done, self.width)}] {self.finished}/{self.total} levels")
            self.stream.write("\n".join(lines) + "\n")
            self.stream.flush()
            self.drawn_lines = len(lines)

    def _clear(self):
        if self.interactive and self.drawn_lines:
            self.stream.write(f"\x1b[{self.drawn_lines}F\x1b[J")
            self.drawn_lines = 0

    def close(self):
        with self.lock:
            self._clear()


class Ticker:
    """Calls `draw` every `interval` seconds until stopped (the driver waits on futures)."""

    def __init__(self, draw, interval=0.2):
        self.draw, self.interval = draw, interval
        self.next = time.monotonic()

    def tick(self):
        if time.monotonic() >= self.next:
            self.draw()
            self.next = time.monotonic() + self.interval
