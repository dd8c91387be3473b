"""What a user waiting on a study, sweep or converge sees while it works.

- After every case: the cases done out of the total, and an estimate of the time left (the mean wall time
  of the cases this invocation ran, times the cases left, divided among the groups running them).
  "Done" is counted on disk (every case directory with a complete summary), so with several groups
  each group's line counts the others' cases too, and cases finished by an earlier invocation count.
- During a case: its simulated time against ``time.end``, as a bar on a terminal (tqdm), and as a
  plain line at most every ``PLAIN_EVERY`` seconds when the output is a file or a pipe.

Only the rank that logs (rank 0 of a group) shows anything; the other ranks get objects that do nothing.
"""

from __future__ import annotations

import math
import sys
import time
from contextlib import nullcontext

PLAIN_EVERY = 30.0  # seconds of wall time between two plain progress lines of a running case


def on_terminal(stream=None) -> bool:
    """Whether ``stream`` (default stderr, where the bar goes) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def duration(seconds: float) -> str:
    """A wall time as a person reads it: 45 s, 12 min, 2.3 h."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


class Cases:
    """The cases of one command (``what``: "study", "converge"; ``unit``: "cases", "levels"): ``total``
    cases over ``groups`` groups of ranks; ``done()`` counts the complete ones (on disk). ``show``: this
    rank logs (rank 0 of its group). A case may weigh more than another (a finer converge level):
    the estimate is the wall time per unit of weight of the cases run here times the weight left."""

    def __init__(self, what: str, total: int, groups: int, done, log, show: bool, bar: bool | None = None,
                 unit: str = "cases"):
        self.what, self.total, self.groups, self.done = what, total, max(1, groups), done
        self.log, self.show, self.unit = log, show, unit
        self.bar = on_terminal() if bar is None else bar
        self.runs: list[tuple[float, float]] = []  # (wall time, weight) of each case run here

    def estimate(self, done: int, left_weight: float | None = None) -> str:
        """The time left after ``done`` of the cases (``left_weight``: the weight of the cases left,
        default one a case), from the cases run here (none yet: unknown)."""
        left = self.total - done
        if left <= 0:
            return "none left"
        if not self.runs:
            return "time left unknown until one has run"
        rate = sum(s for s, _ in self.runs) / sum(w for _, w in self.runs)
        if left_weight is None:
            return (f"about {duration(rate * math.ceil(left / self.groups))} left "
                    f"({duration(rate)} a {self.unit[:-1]})")
        return f"about {duration(rate * left_weight / self.groups)} left"

    def line(self, seconds: float | None = None, weight: float = 1.0, left_weight: float | None = None) -> str:
        """The line after a case (``seconds``: its wall time, None when it did not run here)."""
        if seconds is not None:
            self.runs.append((seconds, weight))
        done = self.done()
        return f"{self.what}: {done}/{self.total} {self.unit} done; {self.estimate(done, left_weight)}"

    def finished(self, seconds: float | None = None, weight: float = 1.0, left_weight: float | None = None) -> None:
        if self.show:
            self.log.info(self.line(seconds, weight, left_weight))

    def case(self, label: str, t_end: float):
        """The running case's progress: a callable told each accepted step (a ``StepRecord``); a context
        manager that ends its bar. Ranks that do not log get one that does nothing."""
        if not self.show:
            return NoProgress()
        return Running(label, t_end, self.log, self.bar)


class NoProgress:
    """A case's progress where nothing is shown (a rank that does not log, or progress off)."""

    def __call__(self, rec) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass


class Running(NoProgress):
    """One case's simulated time ``t`` of ``t_end``: a tqdm bar (``bar``) or a plain line every PLAIN_EVERY s."""

    def __init__(self, label: str, t_end: float, log, bar: bool, clock=time.monotonic):
        self.label, self.t_end, self.log, self.clock = label, t_end, log, clock
        self.t0 = self.last = clock()
        self.tqdm = None
        self.redirect = nullcontext()
        if bar:
            from tqdm import tqdm
            from tqdm.contrib.logging import logging_redirect_tqdm

            self.tqdm = tqdm(total=t_end, desc=label, unit="s", unit_scale=False, leave=False, dynamic_ncols=True,
                             bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.4g}/{total:.4g} s "
                                        "[{elapsed}<{remaining}]{postfix}")
            self.redirect = logging_redirect_tqdm([log])  # log lines above the bar, not through it

    def __enter__(self):
        self.redirect.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        if self.tqdm is not None:
            self.tqdm.close()
        self.redirect.__exit__(*exc)

    def __call__(self, rec) -> None:
        t = min(rec.time, self.t_end)
        if self.tqdm is not None:
            self.tqdm.n = t
            self.tqdm.set_postfix_str(f"step {rec.step}, growth {1e3 * rec.growth_mm:.4g} um", refresh=False)
            self.tqdm.refresh()
            return
        now = self.clock()
        if now - self.last >= PLAIN_EVERY:
            self.last = now
            self.log.info(self.plain(rec, now))

    def plain(self, rec, now: float) -> str:
        frac = rec.time / self.t_end if self.t_end > 0 else 0.0
        return (f"  {self.label}: t = {rec.time:.5g} of {self.t_end:g} s ({100 * frac:.0f}%), step {rec.step}, "
                f"growth {1e3 * rec.growth_mm:.4f} um, {duration(now - self.t0)} so far")
