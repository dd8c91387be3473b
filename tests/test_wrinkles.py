"""Wrinkle counting on synthetic profiles with a known number of half-waves."""

import numpy as np
import pytest

from app.model.shapes import circumferential_wavenumber, wrinkle_count

L = 2.0
X = np.linspace(0, L, 201)


@pytest.mark.parametrize("k", [1, 2, 3, 7, 13, 27, 33])
@pytest.mark.parametrize("shape", ["cos", "sin", "shifted"])
def test_pure_profiles(k, shape):
    phase = {"cos": 0.0, "sin": np.pi / 2, "shifted": 0.7}[shape]
    y = np.cos(k * np.pi * X / L - phase)
    assert wrinkle_count(X, y, L) == k / 2


@pytest.mark.parametrize("k", [5, 12, 27])
def test_end_effects_and_noise(k):
    rng = np.random.default_rng(k)
    envelope = np.tanh(X / 0.15) * np.tanh((L - X) / 0.15)  # wrinkles fade at the clamped ends
    y = envelope * np.cos(k * np.pi * X / L) + 0.15 * rng.standard_normal(X.size) + 0.3 * X
    assert wrinkle_count(X, y, L) == k / 2


def test_localized_packet_counts_its_wavelength():
    k = 20
    y = np.exp(-((X - 1.0) / 0.5) ** 2) * np.sin(k * np.pi * X / L)
    assert abs(wrinkle_count(X, y, L) - k / 2) <= 0.5


def test_unsorted_input_and_circumferential():
    perm = np.random.default_rng(0).permutation(X.size)
    y = np.sin(9 * np.pi * X / L)
    assert wrinkle_count(X[perm], y[perm], L) == 4.5
    th = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    assert circumferential_wavenumber(th, 1 + 0.01 * np.cos(17 * th + 0.3)) == 17


def test_band_vertex_finds_the_dispersion_minimum():
    from app.onset.bisection import band_vertex

    counts = [16.5, 17, 17.5, 18, 18.5, 19, 19.5, 18, 0.5]
    lam = [0.02 * (n - 17.8) ** 2 - 1e-3 for n in counts]
    lam[-2] += 0.5  # a second mode with the same count but higher eigenvalue is ignored
    lam[-1] = 0.01  # a global mode far from the band does not enter the fit
    assert band_vertex(counts, lam) == 18.0
    # first crossing 9.5, neighbours asymmetric: the fitted vertex (9.56) is nearest to 9.5
    assert band_vertex([9.5, 10, 9, 10.5, 8.5], [-2.5e-6, 3.7e-6, 1.5e-5, 4e-5, 4.9e-5]) == 9.5
    assert band_vertex([10, 11], [0.1, 0.2]) is None  # too few counts
    assert band_vertex([10, 10.5, 11], [0.3, 0.2, 0.1]) is None  # minimum at the edge of the band


def _mirrored(centre, step, offsets, values):
    """Counts centre +- offsets (in steps) with the same eigenvalue on both sides."""
    counts = [centre + o * step for o in offsets] + [centre - o * step for o in offsets]
    return counts, list(values) + list(values)


@pytest.mark.parametrize("step", [0.5, 1.0])
@pytest.mark.parametrize("parity", [0, 1])
def test_band_vertex_rounding_is_the_same_for_both_parities(step, parity):
    """The count nearest the fitted vertex; a vertex exactly halfway between two counts goes to the
    one with the lower sampled eigenvalue (equal: the smaller count), whatever the parity of the
    count / step (half-to-even rounding used to send 9.75 up to 10 and 10.25 down to 10)."""
    from app.onset.bisection import band_vertex

    n = 10.0 + parity * step  # an even and an odd multiple of the step
    rng = np.random.default_rng(int(4 * n))
    # data mirrored about a count: the vertex is that count
    counts, lam = _mirrored(n, step, [0, 1, 2, 3], [-1e-5, 2e-6, 9e-6, 3e-5])
    for perm in (np.arange(len(counts)), rng.permutation(len(counts))):
        assert band_vertex([counts[i] for i in perm], [lam[i] for i in perm], step=step) == n
    # a parabola mirrored about the midpoint of n and n + step: a tie between them, always n
    mid = n + step / 2
    counts, lam = _mirrored(mid, step, [0.5, 1.5, 2.5], [4e-6 * (o * o - 1) for o in (0.5, 1.5, 2.5)])
    for perm in (np.arange(len(counts)), rng.permutation(len(counts))):
        assert band_vertex([counts[i] for i in perm], [lam[i] for i in perm], step=step) == n
    # lowest sample n, but the band leans to one side so far that its fitted minimum lies nearer a
    # neighbour (vertex n +- 0.57 step): that neighbour, on either side, for either parity
    offsets, values = [-2, -1, 0, 1, 2], [5e-5, 4e-6, -1e-5, -9.9e-6, 3e-6]
    right = band_vertex([n + o * step for o in offsets], values, step=step)
    left = band_vertex([n - o * step for o in offsets], values, step=step)
    assert (left, right) == (n - step, n + step)
    # and the vertex is kept within one step of n: a far-off fitted minimum gives the neighbour
    values = [5e-5, 3e-5, -1e-5, -9.99e-6, -9.98e-6]
    assert band_vertex([n + o * step for o in offsets], values, step=step) == n + step
    assert band_vertex([n - o * step for o in offsets], values, step=step) == n - step
