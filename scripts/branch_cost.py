"""Cost of a step on a followed branch against a step before the onset (docs/performance.md).

Reads a run's progress lines on stdin and times them as they arrive: the wall time between consecutive
accepted steps, without the bisection and crossing work, before and after the first branch switch.

    hydrobuckle run configs/bilayer.toml --set stability.after_onset=branch --set stability.error_estimate=false \\
        --set time.end=1.2 --set mesh.element_size=0.008 --set mesh.film_layers=4 -o /tmp/branch 2>&1 \\
        | python scripts/branch_cost.py
"""

import statistics
import sys
import time


def main() -> int:
    last, pre, post, switched = None, [], [], False
    for line in sys.stdin:
        now = time.perf_counter()
        if "branch switch" in line:
            switched, last = True, None
        if line.startswith("step"):
            if last is not None:
                (post if switched else pre).append(now - last)
            last = now
        elif any(k in line for k in ("bisection", "crossing", "lost positive")):
            last = None
    if not pre or not post:
        print("branch_cost: no steps before or after a branch switch in the input", file=sys.stderr)
        return 2
    mp, mq = statistics.median(pre), statistics.median(post)
    print(f"pre-onset steps {len(pre)}: median {mp:.3f} s, mean {statistics.mean(pre):.3f} s; "
          f"branch steps {len(post)}: median {mq:.3f} s, mean {statistics.mean(post):.3f} s; "
          f"ratio of medians {mq / mp:.2f}, of means {statistics.mean(post) / statistics.mean(pre):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
