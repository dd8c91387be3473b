"""Where the exact (1D) wrinkling onset of a compressed bilayer equals a given crease strain, over the
modulus ratio (docs/creases.md, "Nucleation or least energy").

A crease smaller than the film sees a homogeneous body: its onset is the film's own, the homogeneous
block's (the modulus-ratio study's ratio-1 row, 0.3548 for this model's compressibility). Wrinkles come
first in a flawless film where their onset lies below it. This finds the ratio at which the two are
equal by bisection on the 1D reduction (about 10 s a ratio), for configs/bilayer-creases.toml and any
``--set`` changes (a longer strip, a thicker substrate).

    python scripts/crease_nucleation.py STRAIN [--set KEY=VALUE ...] [--range LO HI]
"""

from __future__ import annotations

import sys
from pathlib import Path

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "bilayer-creases.toml"


class NoOnset(RuntimeError):
    pass


def wrinkling_strain(sets: list[str], ratio: float) -> tuple[float, str]:
    """The exact wrinkling onset's applied strain and the wrinkle count at ``ratio`` (``surface``: the
    short-wave limit, Biot's surface instability, comes first)."""
    from app import config, factory
    from app.workflows import reduction

    cfg = config.load(str(CONFIG), [*sets, f"material.film.modulus_ratio={ratio!r}",
                                    "reduced.horizon=0"])
    block = reduction.compute(cfg)
    if block["time"] is None:
        raise NoOnset(f"ratio {ratio}: no wrinkling onset up to time.end ({cfg['time']['end']} s)")
    n = block["wrinkle_count"]
    return factory.section(cfg).loading.applied_strain(block["time"]), "surface" if n is None else f"{n:g}"


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        print(__doc__, file=sys.stderr)
        return 2
    rest = argv[1:]
    lo, hi = 1.0, 5.0
    try:
        target = float(argv[0])
        if "--range" in rest:
            i = rest.index("--range")
            lo, hi = float(rest[i + 1]), float(rest[i + 2])
            rest = rest[:i] + rest[i + 3:]
    except (ValueError, IndexError):
        print("crease_nucleation: STRAIN and --range LO HI must be numbers", file=sys.stderr)
        return 2
    if not (0 < target < 1 and 0 < lo < hi):
        print(f"crease_nucleation: STRAIN must lie in (0, 1) and 0 < LO < HI (got {target}, {lo}, {hi})",
              file=sys.stderr)
        return 2
    sets = [s for j, s in enumerate(rest) if j % 2 == 1 and rest[j - 1] == "--set"]
    from app.reduced.transient import TransientFailed
    from app.schema import ConfigError

    try:
        return bisect(target, lo, hi, sets)
    except ConfigError as err:
        print(f"crease_nucleation: {err}", file=sys.stderr)
        return 2
    except (NoOnset, TransientFailed) as err:
        print(f"crease_nucleation: {err}", file=sys.stderr)
        return 1


def bisect(target: float, lo: float, hi: float, sets: list[str]) -> int:
    f_lo, n_lo = wrinkling_strain(sets, lo)
    f_hi, n_hi = wrinkling_strain(sets, hi)
    print(f"ratio {lo:.4f}: wrinkles at {f_lo:.5f} (N = {n_lo}); ratio {hi:.4f}: {f_hi:.5f} (N = {n_hi})",
          flush=True)
    if not (f_lo > target > f_hi):
        print(f"the wrinkling onset does not cross {target} between ratios {lo} and {hi}", file=sys.stderr)
        return 1
    while hi - lo > 0.005:
        mid = 0.5 * (lo + hi)
        f, n = wrinkling_strain(sets, mid)
        print(f"ratio {mid:.4f}: wrinkles at {f:.5f} (N = {n})", flush=True)
        lo, hi = (mid, hi) if f > target else (lo, mid)
    print(f"the wrinkling onset equals {target} at a modulus ratio of {0.5 * (lo + hi):.3f} +- {0.5 * (hi - lo):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
