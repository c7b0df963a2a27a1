"""Progress on stderr (tqdm): bars for loops, an elapsed-time spinner for long single calls.

Nothing is shown for steps shorter than one second, nor at all when ``quiet``. Standard output
is never touched (it carries ``--json``). tqdm itself is imported only once a bar is due,
i.e. after its first second, so quick commands never import it.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Iterable, Iterator

DELAY_S = 1.0


def tqdm(*args, **kwargs):
    """``tqdm.tqdm``, imported on first use (the CLI imports this module for every command)."""
    from tqdm import tqdm as bar

    return bar(*args, **kwargs)


class Progress:
    """Progress reporting for one command run."""

    def __init__(self, quiet: bool = False):
        self.quiet = quiet

    def note(self, message: str) -> None:
        """A one-line remark on stderr (e.g. which profiles are used), unless quiet."""
        if not self.quiet:
            _write(f"popdispatch: {message}")

    def _bar_options(self) -> dict:
        """tqdm settings shared by every bar: stderr, shown after a second, gone when done."""
        return {
            "disable": self.quiet,
            "delay": DELAY_S,
            "leave": False,
            "file": sys.stderr,
            "dynamic_ncols": True,
            "mininterval": 0.1 if sys.stderr.isatty() else 10.0,
        }

    def iterate(self, items: Iterable, description: str, total: int | None = None) -> Iterator:
        """Iterate over ``items`` with a progress bar."""
        if self.quiet:
            yield from items
            return
        with self.counter(description, total) as advance:
            for item in items:
                yield item
                advance()

    @contextlib.contextmanager
    def counter(self, description: str, total: int | None) -> Iterator:
        """A progress bar over ``total`` units; yields ``advance(_)`` to call once per unit."""
        if self.quiet:
            yield lambda *_: None
            return
        bar = _DelayedBar(description, total, self._bar_options())
        try:
            yield bar.advance
        finally:
            bar.close()

    @contextlib.contextmanager
    def step(self, description: str) -> Iterator[None]:
        """An elapsed-time spinner while a single long call runs (no total known).

        On a terminal the line updates twice a second after the first second; elsewhere (logs)
        one line with the elapsed time is written when a step took more than a second.
        """
        if self.quiet:
            yield
            return
        if not sys.stderr.isatty():
            start = time.perf_counter()
            yield
            elapsed = time.perf_counter() - start
            if elapsed > DELAY_S:
                _write(f"{description}: {elapsed:.1f} s")
            return
        with self._spinner(description):
            yield

    @contextlib.contextmanager
    def _spinner(self, description: str) -> Iterator[None]:
        bar = tqdm(
            desc=description,
            total=None,
            delay=DELAY_S,
            leave=False,
            file=sys.stderr,
            bar_format="{desc}: {elapsed}",
        )
        stop = threading.Event()
        shown = threading.Event()

        def tick() -> None:
            if stop.wait(DELAY_S):
                return
            shown.set()
            while not stop.is_set():
                bar.refresh()
                stop.wait(0.5)

        thread = threading.Thread(target=tick, daemon=True)
        thread.start()
        try:
            yield
        finally:
            stop.set()
            thread.join()
            if shown.is_set():  # keep the final elapsed time on its own line
                bar.refresh()
                sys.stderr.write("\n")
            bar.close()


class _DelayedBar:
    """A tqdm bar made only once ``DELAY_S`` has passed since the bar was asked for (tqdm's own
    ``delay`` needs tqdm imported first); it then starts from the count and the time so far,
    its rate and remaining time counted from the first unit. Where stderr is not a terminal
    (a log) no bar is drawn: one line with the count and the time is written at the end of a
    loop that took over ``DELAY_S``."""

    def __init__(self, description: str, total: int | None, options: dict) -> None:
        self.description, self.total, self.options = description, total, options
        self.start = time.time()  # tqdm's clock
        self.count = 0
        self.bar = None
        self.terminal = sys.stderr.isatty()

    def advance(self, *_) -> None:
        """One unit done."""
        self.count += 1
        if self.bar is not None:
            self.bar.update(1)
        elif self.terminal and time.time() - self.start > DELAY_S:
            # delay > 0: tqdm draws nothing before its start time and count are set
            options = {**self.options, "delay": 1e-9}
            self.bar = tqdm(desc=self.description, total=self.total, initial=self.count, **options)
            self.bar.start_t = self.start  # elapsed time from the first unit
            self.bar.initial = 0  # and the rate over every unit
            self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elapsed = time.time() - self.start
        if not self.terminal and elapsed > DELAY_S:
            of = "" if self.total is None else f"/{self.total}"
            _write(f"{self.description}: {self.count}{of} in {elapsed:.1f} s")


def _write(line: str) -> None:
    """A line on stderr that does not break a progress bar being drawn (``tqdm.write``)."""
    from tqdm import tqdm as bar

    bar.write(line, file=sys.stderr)
