"""Wrinkle counting on synthetic profiles with a known number of half-waves."""

import numpy as np
import pytest

from app.wrinkles import circumferential_wavenumber, wrinkle_count

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
    from app.wrinkles import band_vertex

    counts = [16.5, 17, 17.5, 18, 18.5, 19, 19.5, 18, 0.5]
    lam = [0.02 * (n - 17.8) ** 2 - 1e-3 for n in counts]
    lam[-2] += 0.5  # a second mode with the same count but higher eigenvalue is ignored
    lam[-1] = 0.01  # a global mode far from the band does not enter the fit
    assert band_vertex(counts, lam) == 18.0
    # first crossing 9.5, neighbours asymmetric: the vertex stays within half a step
    assert band_vertex([9.5, 10, 9, 10.5, 8.5], [-2.5e-6, 3.7e-6, 1.5e-5, 4e-5, 4.9e-5]) in (9.5, 10.0)
    assert band_vertex([10, 11], [0.1, 0.2]) is None  # too few counts
    assert band_vertex([10, 10.5, 11], [0.3, 0.2, 0.1]) is None  # minimum at the edge of the band
