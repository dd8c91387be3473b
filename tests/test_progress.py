"""What a user waiting on a study or converge sees: cases done of the total, the time left estimated
from the cases run so far, and a running case's progress (plain lines in a log, a bar on a terminal)."""

import io
import logging
from types import SimpleNamespace

from conftest import LogLines

from app.workflows import progress


def _log():
    log = logging.getLogger("hydrobuckle.test_progress")
    log.handlers, log.propagate = [LogLines()], False
    log.setLevel(logging.INFO)
    return log, log.handlers[0].lines


def test_the_estimate_is_the_mean_case_time_times_the_rounds_left():
    """Cases of 60 s and 100 s, 2 groups, 3 cases of 8 done (on disk): 5 left = 3 rounds of 80 s."""
    log, lines = _log()
    done = [0]
    cases = progress.Cases("study", 8, 2, lambda: done[0], log, show=True, bar=False)
    assert cases.estimate(0) == "time left unknown until one has run"
    done[0] = 2
    cases.finished(60.0)
    done[0] = 3
    cases.finished(100.0)
    assert lines == ["study: 2/8 cases done; about 3 min left (60 s a case)",  # 6 left: 3 rounds of 60 s
                     "study: 3/8 cases done; about 4 min left (80 s a case)"]  # 5 left: 3 rounds of 80 s
    done[0] = 8
    cases.finished(None)  # a case that did not run here (another group's) does not time the estimate
    assert lines[-1] == "study: 8/8 cases done; none left"


def test_weighted_levels_scale_the_estimate_with_their_cost():
    """converge: a base of 50 s (weight 1) and a level of weight 2 in 100 s give 50 s per unit; the
    levels left weigh 4 + 16: 1000 s."""
    log, lines = _log()
    ran = []
    levels = progress.Cases("converge", 4, 1, lambda: len(ran), log, show=True, bar=False, unit="levels")
    ran.append(0)
    levels.finished(50.0, 1.0, 2 + 4 + 16)
    ran.append(1)
    levels.finished(100.0, 2.0, 4 + 16)
    assert lines == ["converge: 1/4 levels done; about 18 min left", "converge: 2/4 levels done; about 17 min left"]


def test_a_rank_that_does_not_log_shows_nothing():
    log, lines = _log()
    cases = progress.Cases("study", 2, 1, lambda: 1, log, show=False, bar=False)
    with cases.case("a", 10.0) as monitor:
        monitor(SimpleNamespace(time=5.0, step=3, growth_mm=0.001))
    cases.finished(10.0)
    assert lines == []


def test_plain_lines_come_at_most_every_plain_every_seconds():
    log, lines = _log()
    now = [0.0]
    run = progress.Running("case w=0.01", 10.0, log, bar=False, clock=lambda: now[0])
    step = iter(range(1, 100))
    for clock, t in [(10.0, 1.0), (progress.PLAIN_EVERY + 1, 2.5), (progress.PLAIN_EVERY + 5, 3.0),
                     (2 * progress.PLAIN_EVERY + 2, 5.0)]:
        now[0] = clock
        run(SimpleNamespace(time=t, step=next(step), growth_mm=0.002 * t))
    assert lines == ["  case w=0.01: t = 2.5 of 10 s (25%), step 2, growth 5.0000 um, 31 s so far",
                     "  case w=0.01: t = 5 of 10 s (50%), step 4, growth 10.0000 um, 62 s so far"]


def test_the_bar_follows_the_simulated_time_and_log_lines_pass_above_it(monkeypatch):
    """On a terminal: a tqdm bar over time.end on stderr; while it is up, a log line (stdout) goes through
    tqdm, which clears the bar, writes the line and draws the bar again below it."""
    screen, out = io.StringIO(), io.StringIO()
    monkeypatch.setattr(progress.sys, "stderr", screen)
    monkeypatch.setattr(progress.sys, "stdout", out)
    log = logging.getLogger("hydrobuckle.test_progress_bar")
    log.handlers, log.propagate = [logging.StreamHandler(out)], False
    log.setLevel(logging.INFO)
    with progress.Running("case", 10.0, log, bar=True) as run:
        run(SimpleNamespace(time=4.0, step=7, growth_mm=0.003))
        assert run.tqdm.n == 4.0 and run.tqdm.total == 10.0
        assert "t = 4/10 s" in screen.getvalue() and "step 7, growth 3 um" in screen.getvalue()
        before = screen.getvalue()
        log.info("a line of the run")
        assert out.getvalue() == "a line of the run\n"
        redrawn = screen.getvalue()[len(before):]
        assert redrawn.count("t = 4/10 s") == 1 and redrawn.index("\r ") < redrawn.index("t = 4/10 s")
    log.info("after the case")
    assert out.getvalue() == "a line of the run\nafter the case\n"
