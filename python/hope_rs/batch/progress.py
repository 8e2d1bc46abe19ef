"""The progress line of a batch, and the one-line warnings of the command line and workers."""

from __future__ import annotations

import sys
import time

__all__ = ["BatchProgress", "one_line_warning"]


def one_line_warning(message, category, filename, lineno, line=None) -> str:
    """``warnings.formatwarning`` for the command line and its workers: one line, no source."""
    return f"hope-rs: warning: {message}\n"


class BatchProgress:
    """A progress bar with rate and ETA on one line of stderr (or a line per pair when the stream
    is not a terminal)."""

    def __init__(self, total: int, *, stream=None, enabled: bool = True):
        self.total, self.stream, self.enabled = total, stream or sys.stderr, enabled
        self.done = self.failed = self.skipped = self.doubtful = 0
        self.t0 = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def __call__(self, r) -> None:
        """Count the finished :class:`~hope_rs.batch.driver.PairResult` ``r`` and redraw."""
        self.done += 1
        self.failed += not r.ok
        self.skipped += r.skipped
        self.doubtful += r.likely_failed
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.t0
        computed = self.done - self.skipped
        rate = computed / elapsed if computed and elapsed > 0 else 0.0
        left = self.total - self.done
        eta = f"{int(left / rate) // 60}m{int(left / rate) % 60:02d}s" if rate else "?"
        width = 24
        fill = int(width * self.done / max(self.total, 1))
        line = (
            f"[{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} pairs"
            f" ({self.failed} failed, {self.skipped} skipped"
            + (f", {self.doubtful} likely failed" if self.doubtful else "")
            + f") {60 * rate:.1f}/min ETA {eta}"
        )
        if self.tty:
            self.stream.write("\r" + line + ("\n" if self.done == self.total else ""))
        else:
            status = "skipped" if r.skipped else ("ok" if r.ok else f"FAILED: {r.error}")
            if r.likely_failed:
                status += ", likely failed"
            self.stream.write(f"{line} | {r.a} -> {r.b}: {status}\n")
        self.stream.flush()
