"""How far long work is, said while it runs: a bar where someone watches (a terminal, a notebook), a
line every so often where nobody does (a log, a pipe), nothing when asked.

    with Ticker(total_steps + 1, "train", progress) as tick:     # progress: None (auto), True, False
        for step in range(total_steps + 1):
            ...
            tick.advance()

A sweep's bar is a ``Ticker`` too, with ``lines=False`` (its runs say their own lines, through
``Ticker.say``, above the bar). ``say_left`` and ``Heartbeat`` are the words and the pace of those lines (the
sweeps' too). The time left is taken at the rate of the recent past (``Rate``), not the average since the
start: a run that slows down (another job joins the box, a kind whose steps grow dearer) is said to at the
next line, not minutes later. Nothing here imports torch.
"""
from __future__ import annotations

import sys
import time
from collections import deque

# seconds between the lines that say how far a long run is where no bar is drawn: a sweep's runs
# (``hnn.sweeps.backends``), and a lone fit or evaluation (``Ticker``)
HEARTBEAT = 30.0
LINE_EVERY = 10.0
# a bar appears once the work has run this long (shorter work stays silent)
BAR_DELAY = 2.0
# the rate of the time left: the work done over about this many recent seconds (at least two samples)
WINDOW = 60.0


def watched() -> bool:
    """Whether someone watches this process's output as it comes: stderr is a terminal, or the code
    runs in a Jupyter kernel (whose stderr is no terminal, but whose cells show a bar)."""
    if sys.stderr.isatty():
        return True
    shell = sys.modules.get("IPython")
    ipython = getattr(shell, "get_ipython", lambda: None)() if shell is not None else None
    return ipython is not None and "IPKernelApp" in getattr(ipython, "config", {})


def say_left(seconds: float) -> str:
    """``'about 12 min left'`` (hours past two hours, seconds under 90)."""
    if seconds >= 2 * 3600:
        return f"about {seconds / 3600:.1f} h left"
    return f"about {seconds / 60:.0f} min left" if seconds >= 90 else f"about {seconds:.0f} s left"


class Rate:
    """Work per second over the recent past: ``add(done)`` as the work goes, ``left(total)`` the seconds
    still to go at the rate of the last ``WINDOW`` seconds (of at least two samples), None before a rate
    is known."""

    def __init__(self, done: float = 0.0, now: float | None = None, window: float = WINDOW):
        self.window = window
        self.samples = deque([(done, time.perf_counter() if now is None else now)])

    def add(self, done: float, now: float | None = None) -> None:
        now = time.perf_counter() if now is None else now
        self.samples.append((done, now))
        # keep one sample at least a window old (the start of the rate), and every one since
        while len(self.samples) > 2 and now - self.samples[1][1] >= self.window:
            self.samples.popleft()

    def left(self, total: float, now: float | None = None) -> float | None:
        (done0, t0), (done1, t1) = self.samples[0], self.samples[-1]
        now = t1 if now is None else now
        if done1 <= done0 or t1 <= t0:
            return None
        return (total - done1) * (t1 - t0) / (done1 - done0) + (t1 - now)


class Heartbeat:
    """How far one run is, every ``every`` seconds: ``due(step, total)`` gives ``'step s of total, about
    m min left'`` when a line is due (else None), at the rate of the recent past (``Rate``, from the first
    step it saw: a resumed run is not timed from its start)."""

    def __init__(self, every: float = HEARTBEAT):
        self.every, self.rate, self.said = every, None, time.perf_counter()

    def due(self, step: int, total: int) -> str | None:
        now = time.perf_counter()
        first = self.rate is None
        if first:
            self.rate = Rate(step, now)
        if now - self.said <= self.every:
            return None
        self.said = now
        if not first:
            self.rate.add(step, now)
        left = None if first else self.rate.left(total, now)
        return f"step {step} of {total}" + (f", {say_left(left)}" if left is not None else "")


class Ticker:
    """The progress of one loop of ``total`` units named ``desc``: ``progress`` True draws a bar, False
    nothing, None (auto) a bar where someone watches (``watched``: after ``BAR_DELAY`` s, so short work
    stays silent) and else, with ``lines``, a line on stderr every ``LINE_EVERY`` s (``'train: step 400 of
    2001, about 1 min left'``; ``lines=False``: none, where the caller says its own through ``say``). Use as a
    context manager; ``advance(n)`` after each unit."""

    def __init__(self, total: int, desc: str, progress: bool | None = None, start: int = 0, unit: str = "step",
                 lines: bool = True):
        self.total, self.desc, self.done, self.unit = total, desc, start, unit
        self.bar, self.beat = None, None
        if progress is None and not watched():
            if lines:
                self.beat = Heartbeat(LINE_EVERY)
                self.beat.due(start, total)
        elif progress is None or progress:
            from tqdm.auto import tqdm          # here: tqdm.auto looks for a notebook, which costs an import
            self.bar = tqdm(total=total, initial=start, desc=desc, unit=unit, leave=False, file=sys.stderr,
                            delay=BAR_DELAY if progress is None else 0.0, dynamic_ncols=True)

    def advance(self, n: int = 1) -> None:
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
        elif self.beat is not None and (line := self.beat.due(self.done, self.total)):
            print(f"{self.desc}: {line.replace('step', self.unit, 1)}", file=sys.stderr, flush=True)

    @property
    def drawn(self) -> bool:
        """Whether a bar is drawn (else a caller's own lines are the only word of how far the work is)."""
        return self.bar is not None

    def say(self, line: str) -> None:
        """Print ``line`` on stdout above the bar, flushed: tqdm's ``write`` does not flush, and a command's
        output piped to a file or a pager (no terminal: no bar either) would hold every line until it ends."""
        if self.bar is not None:
            self.bar.write(line)
        else:
            print(line)
        sys.stdout.flush()

    def note(self, text: str) -> None:
        """``text`` beside the bar (``'3/21 runs'``), shown at its next refresh; nothing without a bar."""
        if self.bar is not None:
            self.bar.set_postfix_str(text, refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> Ticker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
