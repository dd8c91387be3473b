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


SETTLING = 3  # steps after a switch that still leave the saddle (reported apart)


def main() -> int:
    last, pre, post, settled, since = None, [], [], [], None
    for line in sys.stdin:
        now = time.perf_counter()
        if "branch switch" in line:
            since, last = 0, None
        if line.startswith("step"):
            if last is not None:
                (post if since is not None else pre).append(now - last)
                if since is not None and since >= SETTLING:
                    settled.append(now - last)
            if since is not None:
                since += 1
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
    if settled:
        print(f"branch steps {SETTLING}+ steps after a switch ({len(settled)}): mean {statistics.mean(settled):.3f} s, "
              f"ratio of means {statistics.mean(settled) / statistics.mean(pre):.2f}; the slowest branch steps: "
              + ", ".join(f"{t:.2f}" for t in sorted(post)[-5:]) + " s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
