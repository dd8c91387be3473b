"""Drained / undrained surface (Biot-type) instability of a laterally constrained hydrogel layer.

Standalone (numpy + scipy only), independent of the hydrobuckle FE code. See drained-onset.md (same folder).

Model (per unit preswollen reference volume, plane strain, F = 2x2 in-plane, out-of-plane stretch 1):

    psi(F, s) = g/(2 J0) [J0^(2/3) (F:F + 1) - 3 - 2 ln(J J0)]
              + a/J0 [s ln(s/(1+s)) + chi s/(1+s)] + e/(2 J0) (J J0 - 1 - s)^2

Both the undrained energy psi(F, s_frozen) and the drained energy W(F, mu) = min_s [psi - mu s] have the
form   mu_n/2 F:F + G(J)   with the network shear modulus mu_n = g J0^(-1/3); all that matters for the
surface stability of a homogeneously strained half-space F = diag(l1, l2) with a traction-free surface
(normal along 2) is the dimensionless volumetric stiffness  kappa = G''(J)/mu_n. The zero-speed surface-wave
(Biot) condition reduces to (drained-onset.md, eq. (S))

    stable  <=>  kappa * l1^2 > Phi(x),   x = l1/l2,
    Phi(x) = (1 - x^2)(1 + 6 x^2 + x^4) / [(1 + 3x - x^2 + x^3)(x^3 + x^2 + 3x - 1)]   (x_B < x < 1),

unstable for every kappa when x <= x_B = 0.29559 (root of x^3 + x^2 + 3x - 1: Biot's incompressible limit).

Drained:    G''_d(J) = g/(J0 J^2) + J0 a f''(s) e / (a f''(s) + e)      (-> g/(J0 J^2) + J0 a f'' for e -> inf)
Undrained:  G''_u(J) = g/(J0 J^2) + J0 e                                (-> inf: incompressible, Biot)
with f''(s) = 1/(s (1+s)^2) - 2 chi/(1+s)^3.

Stretches: ``lam`` is the thickness stretch relative to the preswollen reference (lateral stretch 1). Relative to
the dry state the thickness stretch is lam J0^(1/3) (and the lateral one J0^(1/3)); Kang & Huang's linear
swelling ratio (dry, laterally unstretched layer) corresponds to J0 = 1.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

DEFAULT = dict(gamma=0.1, alpha=24.2, eps=10.0, J0=1.01, chi=0.1)

# --- Biot's incompressible neo-Hookean limit -------------------------------------------------------------

X_BIOT = float(brentq(lambda x: x**3 + x**2 + 3 * x - 1, 0.1, 0.5, xtol=1e-15))  # l1/l2 = 0.295598...
STRETCH_BIOT = math.sqrt(X_BIOT)  # plane-strain compression l1 = sqrt(x) (l2 = 1/l1): 0.543689...
RATIO_BIOT = 1.0 / X_BIOT  # l2/l1 = 3.38298...


# --- mixing function and the homogeneous constrained layer -----------------------------------------------


def f1(s, chi):
    """f'(s) of f(s) = s ln(s/(1+s)) + chi s/(1+s)."""
    return math.log(s / (1 + s)) + 1 / (1 + s) + chi / (1 + s) ** 2


def f2(s, chi):
    """f''(s) = 1/(s (1+s)^2) - 2 chi/(1+s)^3."""
    return 1 / (s * (1 + s) ** 2) - 2 * chi / (1 + s) ** 3


def layer_fluid(lam, gamma, eps, J0):
    """Fluid content of the constrained layer F = diag(1, lam) with P_yy = 0 (eps = inf: s = lam J0 - 1)."""
    if math.isinf(eps):
        return lam * J0 - 1
    return lam * J0 - 1 + gamma / (eps * J0) * (J0 ** (2 / 3) * lam - 1 / lam)


def layer_mu(lam, gamma, alpha, eps, J0, chi):
    """Chemical potential dpsi/ds of that state. With eps = inf the constraint pressure is fixed by P_yy = 0:
    mu = a/J0 f'(s) + g/J0^2 (J0^(2/3) lam - 1/lam), the e -> inf limit of the finite-penalty expression."""
    s = layer_fluid(lam, gamma, eps, J0)
    return alpha / J0 * f1(s, chi) + gamma / J0**2 * (J0 ** (2 / 3) * lam - 1 / lam)


def equilibrium_stretch(gamma=DEFAULT["gamma"], alpha=DEFAULT["alpha"], eps=DEFAULT["eps"],
                        J0=DEFAULT["J0"], chi=DEFAULT["chi"], mu_bar=0.0):
    """Thickness stretch (relative to the preswollen reference) of the constrained layer at mu = mu_bar."""
    lo = 1.0 + 1e-12
    while layer_fluid(lo, gamma, eps, J0) <= 0:  # J0 < 1 guard; not needed for J0 >= 1
        lo *= 1.001
    return brentq(lambda l: layer_mu(l, gamma, alpha, eps, J0, chi) - mu_bar, lo, 1e3, xtol=1e-14, rtol=1e-14)


# --- incremental moduli -------------------------------------------------------------------------------------


def network_shear(gamma, J0):
    return gamma * J0 ** (-1 / 3)


def drained_G2(lam, gamma, alpha, eps, J0, chi):
    """G''(J) of the drained energy W(F, mu) at the constrained-layer state of stretch lam (J = lam)."""
    s = layer_fluid(lam, gamma, eps, J0)
    af = alpha * f2(s, chi)
    mix = J0 * af if math.isinf(eps) else J0 * af * eps / (af + eps)
    return gamma / (J0 * lam**2) + mix


def undrained_G2(lam, gamma, alpha, eps, J0, chi):
    """G''(J) of psi(F, s frozen); infinite for eps = inf (incompressible)."""
    return math.inf if math.isinf(eps) else gamma / (J0 * lam**2) + J0 * eps


def tangent_moduli(l1, l2, mu_n, G1, G2):
    """Nonzero components A_iJkL = d2W/dF_iJ dF_kL of W = mu_n/2 F:F + G(J) at F = diag(l1, l2)."""
    J = l1 * l2
    return {"1111": mu_n + G2 * l2**2, "2222": mu_n + G2 * l1**2, "1122": G2 * J + G1,
            "1212": mu_n, "2121": mu_n, "1221": -G1}


def strongly_elliptic(A):
    a = A["1212"] * A["2222"]
    c = A["1111"] * A["2121"]
    B = A["1122"] + A["1221"]
    b = -(A["1212"] * A["2121"] + A["1111"] * A["2222"]) + B**2
    return min(A["1111"], A["2222"], A["1212"], A["2121"]) > 0 and b < 2 * math.sqrt(a * c)


def surface_determinant(A):
    """Real zero-speed Rayleigh (Biot) function of a half-space X2 < 0, surface X2 = 0 traction-free, for the
    orthotropic tangent A (general form, eq. (R) of drained-onset.md). Positive = surface-stable (checked at
    the unstrained state), zero = critical."""
    a = A["1212"] * A["2222"]
    c = A["1111"] * A["2121"]
    B = A["1122"] + A["1221"]
    b = -(A["1212"] * A["2121"] + A["1111"] * A["2222"]) + B**2
    m = A["1212"] * A["1122"]
    n = A["1221"] * A["1111"]
    r = A["1122"] * B - A["2222"] * A["1111"]
    P = math.sqrt(c / a)
    return m * c + P * (n * a - m * r) + n * (r - b)


def surface_determinant_complex(A):
    """The same condition evaluated without the closed-form algebra: decay exponents p (Re p > 0) from the
    biquadratic, eigenvectors, 2x2 traction determinant divided by (p1 - p2) (numerical cross-check)."""
    a = A["1212"] * A["2222"]
    c = A["1111"] * A["2121"]
    B = A["1122"] + A["1221"]
    b = -(A["1212"] * A["2121"] + A["1111"] * A["2222"]) + B**2
    q = np.roots([a, b, c]).astype(complex)  # p^2
    p = np.sqrt(q)
    p = np.where(p.real < 0, -p, p)
    cols = []
    for pk in p:
        U1, U2 = -1j * pk * B, A["1212"] * pk**2 - A["1111"]
        t1 = A["1212"] * pk * U1 + A["1221"] * 1j * U2
        t2 = A["1122"] * 1j * U1 + A["2222"] * pk * U2
        cols.append((t1, t2))
    D = cols[0][0] * cols[1][1] - cols[1][0] * cols[0][1]
    return D / (p[0] - p[1]) / 1j


def Phi(x):
    """Critical value of kappa l1^2 = G'' l1^2/mu_n as a function of x = l1/l2 (inf at and below X_BIOT)."""
    if x <= X_BIOT:
        return math.inf
    return (1 - x**2) * (1 + 6 * x**2 + x**4) / ((1 + 3 * x - x**2 + x**3) * (x**3 + x**2 + 3 * x - 1))


def surface_margin(l1, l2, kappa):
    """Reduced surface function (positive = stable) for W = mu_n/2 F:F + G(J), traction-free (P22 = 0),
    kappa = G''/mu_n:  [k l1^2 (l1^2 + 3 l2^2) + l1^2 - l2^2]/sqrt(1 + k l1^2) - (l2^2 - l1^2) sqrt(1 + k l2^2).
    kappa = inf: the incompressible limit, l2^2 (l1^3 + l1^2 l2 + 3 l1 l2^2 - l2^3)/l1 (up to a positive factor)."""
    if math.isinf(kappa):
        return (l1**3 + l1**2 * l2 + 3 * l1 * l2**2 - l2**3) / l2**3
    k = kappa
    if 1 + k * l1**2 <= 0 or 1 + k * l2**2 <= 0:
        return -1.0  # A1111 or A2222 <= 0: strong ellipticity already lost (bulk instability)
    return (k * l1**2 * (l1**2 + 3 * l2**2) + l1**2 - l2**2) / math.sqrt(1 + k * l1**2) \
        - (l2**2 - l1**2) * math.sqrt(1 + k * l2**2)


# --- critical stretches of the swelling constrained layer -------------------------------------------------


def _first_root(fun, lo, hi, n=4000):
    grid = np.linspace(lo, hi, n)
    vals = [fun(x) for x in grid]
    for i in range(1, n):
        if vals[i - 1] > 0 >= vals[i]:
            return brentq(fun, grid[i - 1], grid[i], xtol=1e-14, rtol=1e-14)
    return None


def _critical(G2fun, gamma, alpha, eps, J0, chi, lam_max):
    mu_n = network_shear(gamma, J0)

    def margin(lam):
        return surface_margin(1.0, lam, G2fun(lam, gamma, alpha, eps, J0, chi) / mu_n)

    hi = min(lam_max, RATIO_BIOT + 1e-9)  # beyond Biot's ratio every kappa > 0 is unstable
    return _first_root(margin, 1.0 + 1e-9, hi)


def drained_critical_stretch(gamma=DEFAULT["gamma"], alpha=DEFAULT["alpha"], eps=DEFAULT["eps"],
                             J0=DEFAULT["J0"], chi=DEFAULT["chi"], lam_max=RATIO_BIOT + 1e-9, mu_bar=None):
    """Thickness stretch (relative to the preswollen reference) at which the drained half-space tangent of the
    homogeneously swollen constrained layer first admits a zero-speed surface wave (short-wave onset).
    Multiply by J0^(1/3) for the stretch relative to the dry state. None if no root below lam_max.
    With mu_bar given, None also when the root lies beyond the equilibrium stretch at mu_bar (the layer
    equilibrates before it gets there)."""
    if mu_bar is not None:
        lam_max = min(lam_max, equilibrium_stretch(gamma, alpha, eps, J0, chi, mu_bar))
    return _critical(drained_G2, gamma, alpha, eps, J0, chi, lam_max)


def undrained_critical_stretch(gamma=DEFAULT["gamma"], alpha=DEFAULT["alpha"], eps=DEFAULT["eps"],
                               J0=DEFAULT["J0"], chi=DEFAULT["chi"], lam_max=RATIO_BIOT + 1e-9, mu_bar=None):
    """Same with the fluid content frozen at the homogeneous state's s (undrained tangent psi_FF).
    eps = inf: exactly Biot's ratio 3.38298. None if no root below lam_max, or (mu_bar given) if the layer
    equilibrates at mu_bar before reaching it ("never goes undrained-unstable while swelling")."""
    if mu_bar is not None:
        lam_max = min(lam_max, equilibrium_stretch(gamma, alpha, eps, J0, chi, mu_bar))
    if math.isinf(eps):
        return RATIO_BIOT if lam_max >= RATIO_BIOT else None
    return _critical(undrained_G2, gamma, alpha, eps, J0, chi, lam_max)


def reached_on_swelling_path(lam_c, gamma, alpha, eps, J0, chi, mu_bar=0.0):
    """True if a critical stretch is reached before the constrained layer equilibrates at mu_bar."""
    return lam_c is not None and lam_c < equilibrium_stretch(gamma, alpha, eps, J0, chi, mu_bar)


# --- validation helpers -------------------------------------------------------------------------------------


def compressible_biot_stretch(kappa_over_mu):
    """Plane-strain compression l1 of W = mu/2 (F:F + 1 - 3 - 2 ln J) + K/2 (J - 1)^2 (traction-free in 2):
    critical l1 of the surface instability; -> STRETCH_BIOT as K/mu -> inf."""
    K = kappa_over_mu  # mu = 1

    def l2_of(l1):  # P22 = (l2 - 1/l2) + K (l1 l2 - 1) l1 = 0
        return brentq(lambda l2: l2 - 1 / l2 + K * (l1 * l2 - 1) * l1, 1e-3, 1e3, xtol=1e-15)

    def margin(l1):
        l2 = l2_of(l1)
        J = l1 * l2
        return surface_margin(l1, l2, 1 / J**2 + K)

    return brentq(margin, 0.3, 0.999, xtol=1e-14)


def undrained_compression_stretch(gamma=DEFAULT["gamma"], eps=DEFAULT["eps"], J0=DEFAULT["J0"]):
    """Critical compression stretch l1 of the gel with diffusion off (s = s0, F = diag(l1, l2), P_yy = 0):
    the analytic counterpart of hydrobuckle's configs/biot.toml check."""
    s0 = gamma / eps * (J0 ** (-1 / 3) - 1 / J0) + J0 - 1
    mu_n = network_shear(gamma, J0)

    def l2_of(l1):  # P_yy = g/J0 (J0^(2/3) l2 - 1/l2) + e (J J0 - 1 - s0) l1 = 0
        return brentq(lambda l2: gamma / J0 * (J0 ** (2 / 3) * l2 - 1 / l2) + eps * (l1 * l2 * J0 - 1 - s0) * l1,
                      1e-3, 1e3, xtol=1e-15)

    def margin(l1):
        l2 = l2_of(l1)
        return surface_margin(l1, l2, (gamma / (J0 * (l1 * l2) ** 2) + J0 * eps) / mu_n)

    return brentq(margin, 0.3, 0.999, xtol=1e-14)


def drained_energy_fd_check(lam=3.0, h=1e-4, **par):
    """Finite-difference Hessian of W(F, mu) = min_s [psi(F, s) - mu s] (s found by Newton at each F) against
    the closed-form drained moduli; returns the max relative deviation."""
    p = {**DEFAULT, **par}
    g, a, e, J0, chi = p["gamma"], p["alpha"], p["eps"], p["J0"], p["chi"]
    s_star = layer_fluid(lam, g, e, J0)
    mu = layer_mu(lam, g, a, e, J0, chi)

    def psi(F, s):
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        FF = (F**2).sum() + 1
        return (g / (2 * J0) * (J0 ** (2 / 3) * FF - 3 - 2 * math.log(J * J0))
                + a / J0 * (s * math.log(s / (1 + s)) + chi * s / (1 + s)) + e / (2 * J0) * (J * J0 - 1 - s) ** 2)

    def W(F):
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        s = s_star
        for _ in range(60):  # Newton on dpsi/ds = mu
            r = a / J0 * f1(s, chi) - e / J0 * (J * J0 - 1 - s) - mu
            s -= r / (a / J0 * f2(s, chi) + e / J0)
        return psi(F, s) - mu * s

    F0 = np.diag([1.0, lam])
    idx = [(0, 0), (0, 1), (1, 0), (1, 1)]
    H = np.zeros((4, 4))
    for I, (i, j) in enumerate(idx):
        for K, (k, l) in enumerate(idx):
            def Wp(di, dk):
                F = F0.copy()
                F[i, j] += di
                F[k, l] += dk
                return W(F)
            H[I, K] = (Wp(h, h) - Wp(h, -h) - Wp(-h, h) + Wp(-h, -h)) / (4 * h * h)
    mu_n = network_shear(g, J0)
    G1 = -mu_n * lam  # P22 = 0
    A = tangent_moduli(1.0, lam, mu_n, G1, drained_G2(lam, g, a, e, J0, chi))
    ref = np.zeros((4, 4))
    ref[0, 0], ref[3, 3], ref[0, 3], ref[3, 0] = A["1111"], A["2222"], A["1122"], A["1122"]
    ref[1, 1], ref[2, 2], ref[1, 2], ref[2, 1] = A["1212"], A["2121"], A["1221"], A["1221"]
    return np.abs(H - ref).max() / np.abs(ref).max()


# --- layer of finite thickness (Rayleigh-Ritz in the thickness direction) ---------------------------------


def layer_min_eigenvalue(A, kH, n_el=400, grading=1.03):
    """Smallest eigenvalue of the second variation of a layer 0 < Y < H bonded at Y = 0 (u = 0), traction-free
    at Y = H, for the mode u1 = U1(Y) cos kX, u2 = U2(Y) sin kX, tangent A (P2 elements, L2 mass, k = 1).
    Negative = unstable at this wavenumber. Independent of the closed-form surface function."""
    from scipy.linalg import eigh

    H = kH
    # graded mesh: element sizes grow geometrically from the surface Y = H down to the substrate Y = 0
    w = grading ** np.arange(n_el)
    y = H - np.concatenate([[0.0], np.cumsum(w)]) / w.sum() * H
    y = np.clip(y[::-1], 0.0, H)
    ne = len(y) - 1
    nn = 2 * ne + 1  # P2 nodes per field
    gp, gw = np.polynomial.legendre.leggauss(4)
    K = np.zeros((2 * nn, 2 * nn))
    M = np.zeros((2 * nn, 2 * nn))
    for e_ in range(ne):
        y0, y1 = y[e_], y[e_ + 1]
        he = y1 - y0
        dofs = [2 * e_, 2 * e_ + 1, 2 * e_ + 2]
        for xi, wi in zip(gp, gw):
            t = (xi + 1) / 2
            N = np.array([2 * (t - 0.5) * (t - 1), -4 * t * (t - 1), 2 * t * (t - 0.5)])
            dN = np.array([4 * t - 3, -8 * t + 4, 4 * t - 1]) / he
            wq = wi * he / 2
            # quadratic form (X-averaged): A1111 U1^2 + A2222 U2'^2 - 2 A1122 U1 U2'
            #                              + A1212 U1'^2 + A2121 U2^2 + 2 A1221 U1' U2    (k = 1)
            i1 = [d for d in dofs]
            i2 = [nn + d for d in dofs]
            K[np.ix_(i1, i1)] += wq * (A["1111"] * np.outer(N, N) + A["1212"] * np.outer(dN, dN))
            K[np.ix_(i2, i2)] += wq * (A["2222"] * np.outer(dN, dN) + A["2121"] * np.outer(N, N))
            C = -A["1122"] * np.outer(N, dN) + A["1221"] * np.outer(dN, N)
            K[np.ix_(i1, i2)] += wq * C
            K[np.ix_(i2, i1)] += wq * C.T
            M[np.ix_(i1, i1)] += wq * np.outer(N, N)
            M[np.ix_(i2, i2)] += wq * np.outer(N, N)
    free = [i for i in range(2 * nn) if i not in (0, nn)]  # u = 0 at Y = 0
    return eigh(K[np.ix_(free, free)], M[np.ix_(free, free)], eigvals_only=True, subset_by_index=[0, 0])[0]


# --- finite tau: poroelastic growth rates of a Fourier mode and the inertia of K_tau ---------------------


def coupled_mode_matrices(lam, kH, gamma=DEFAULT["gamma"], alpha=DEFAULT["alpha"], eps=DEFAULT["eps"],
                          J0=DEFAULT["J0"], chi=DEFAULT["chi"], n_el=160, grading=1.04):
    """Second variation of the incremental potential for one Fourier mode (wavenumber k = 1, lengths in 1/k)
    of the constrained layer at the homogeneous state lam, thickness kH, bonded and impermeable at Y = 0,
    traction-free and open (mu = mu_bar, no Hessian term) at Y = H:

        u1 = U1(Y) cos X,  u2 = U2(Y) sin X,  dQ1 = Q1(Y) cos X,  dQ2 = Q2(Y) sin X,  ds = -Div dQ = (Q1 - Q2') sin X

    Returns (E, D, n_u): E = energy Hessian in (U, Q) (psi'' of the model), D = dissipation matrix with the
    mobility M = 1 (C:(dQ x dQ)/(J0^(1/3) M s)), n_u = number of displacement dofs (first). K_tau = E + D/tau.
    Growth rates of the linearized gradient flow: omega = M k^2 * (eigenvalues of -E~ w.r.t. D), E~ = Schur
    complement of E on the flux dofs. Elements: P2 for U1, U2, Q2 (Q2 = 0 at Y = 0), discontinuous P1 for Q1."""
    mu_n = network_shear(gamma, J0)
    s = layer_fluid(lam, gamma, eps, J0)
    Au = tangent_moduli(1.0, lam, mu_n, -mu_n * lam, undrained_G2(lam, gamma, alpha, eps, J0, chi))
    c11, c22 = -eps * lam, -eps * 1.0  # d2psi/dF11 ds = -eps cof(F)_11, d2psi/dF22 ds = -eps cof(F)_22
    pss = (alpha * f2(s, chi) + eps) / J0
    dis1, dis2 = 1.0 / (J0 ** (1 / 3) * s), lam**2 / (J0 ** (1 / 3) * s)  # C = diag(1, lam^2), M = 1
    H = kH
    w = grading ** np.arange(n_el)
    y = np.clip((H - np.concatenate([[0.0], np.cumsum(w)]) / w.sum() * H)[::-1], 0.0, H)
    ne = len(y) - 1
    nn = 2 * ne + 1
    # dof layout: U1 [0, nn), U2 [nn, 2nn), Q2 [2nn, 3nn), Q1 [3nn, 3nn + 2 ne)
    ndof = 3 * nn + 2 * ne
    E = np.zeros((ndof, ndof))
    D = np.zeros((ndof, ndof))
    gp, gw = np.polynomial.legendre.leggauss(4)
    for e_ in range(ne):
        he = y[e_ + 1] - y[e_]
        loc = np.array([2 * e_, 2 * e_ + 1, 2 * e_ + 2])
        iU1, iU2, iQ2 = loc, nn + loc, 2 * nn + loc
        iQ1 = 3 * nn + np.array([2 * e_, 2 * e_ + 1])
        for xi, wi in zip(gp, gw):
            t = (xi + 1) / 2
            N = np.array([2 * (t - 0.5) * (t - 1), -4 * t * (t - 1), 2 * t * (t - 0.5)])
            dN = np.array([4 * t - 3, -8 * t + 4, 4 * t - 1]) / he
            L = np.array([1 - t, t])
            wq = wi * he / 2
            # strain-like vector  z = [F11, F22, F12, F21, ds] as linear maps of the local dofs
            z = {"F11": (iU1, -N), "F22": (iU2, dN), "F12": (iU1, dN), "F21": (iU2, N)}
            ds = [(iQ1, L), (iQ2, -dN)]

            def add(Mat, a, b, coef):
                (ia, va), (ib, vb) = a, b
                Mat[np.ix_(ia, ib)] += coef * wq * np.outer(va, vb)
                if not (ia is ib):
                    Mat[np.ix_(ib, ia)] += coef * wq * np.outer(vb, va)

            add(E, z["F11"], z["F11"], Au["1111"])
            add(E, z["F22"], z["F22"], Au["2222"])
            add(E, z["F11"], z["F22"], Au["1122"])
            add(E, z["F12"], z["F12"], Au["1212"])
            add(E, z["F21"], z["F21"], Au["2121"])
            add(E, z["F12"], z["F21"], Au["1221"])
            for d_ in ds:
                add(E, z["F11"], d_, c11)
                add(E, z["F22"], d_, c22)
            add(E, ds[0], ds[0], pss)
            add(E, ds[1], ds[1], pss)
            add(E, ds[0], ds[1], pss)
            add(D, (iQ1, L), (iQ1, L), dis1)
            add(D, (iQ2, N), (iQ2, N), dis2)
    free = np.array([i for i in range(ndof) if i not in (0, nn, 2 * nn)])  # u = 0, Q2 = 0 at Y = 0
    E, D = E[np.ix_(free, free)], D[np.ix_(free, free)]
    return E, D, 2 * nn - 2


def growth_rates(lam, kH=30.0, n_modes=3, **par):
    """Largest growth rates omega/(M k^2) [MPa] of the linearized gradient flow for one Fourier mode
    (undrained state must be stable: E_uu positive definite). Positive = growing."""
    from scipy.linalg import eigh

    E, D, nu = coupled_mode_matrices(lam, kH, **par)
    Euu, EuQ, EQQ = E[:nu, :nu], E[:nu, nu:], E[nu:, nu:]
    if np.linalg.eigvalsh(Euu)[0] <= 0:
        return None  # undrained-unstable: instantaneous (infinite-rate) instability
    S = EQQ - EuQ.T @ np.linalg.solve(Euu, EuQ)
    theta = eigh(S, D[nu:, nu:], eigvals_only=True, subset_by_index=[0, n_modes - 1])
    return -theta


def K_tau_negative_count(lam, tau_Mk2, kH=30.0, **par):
    """Number of negative eigenvalues of K_tau = E + D/tau for one Fourier mode, with tau M k^2 = tau_Mk2."""
    E, D, _ = coupled_mode_matrices(lam, kH, **par)
    return int((np.linalg.eigvalsh(E + D / tau_Mk2) < 0).sum())


def tau_onset_stretch(tau_Mk2, kH=30.0, **par):
    """Stretch at which K_tau of one Fourier mode (tau M k^2 = tau_Mk2) first loses positive definiteness:
    growth_rates(lam)[0] = 1/tau_Mk2. Lies between the drained and the undrained critical stretch."""
    p = {**DEFAULT, **par}
    lo = drained_critical_stretch(**p) + 1e-9
    hi = undrained_critical_stretch(**p) - 1e-6
    target = 1.0 / tau_Mk2

    def fun(lam):
        r = growth_rates(lam, kH, n_modes=1, **p)
        return (math.inf if r is None else r[0]) - target

    if fun(hi) < 0:
        return hi
    return brentq(fun, lo, hi, xtol=1e-6)


# --- table ----------------------------------------------------------------------------------------------------


def summary_row(gamma, alpha, eps, J0, chi):
    lc_d = drained_critical_stretch(gamma, alpha, eps, J0, chi)
    lc_u = undrained_critical_stretch(gamma, alpha, eps, J0, chi)
    leq = equilibrium_stretch(gamma, alpha, eps, J0, chi)
    c = J0 ** (1 / 3)
    return dict(gamma=gamma, chi=chi, NOmega=gamma / alpha, eps=eps, J0=J0,
                lc_d=lc_d, lc_d_dry=None if lc_d is None else lc_d * c,
                lc_u=lc_u, lc_u_dry=None if lc_u is None else lc_u * c,
                leq=leq, leq_dry=leq * c,
                drained_unstable=lc_d is not None and lc_d < leq,
                undrained_unstable=lc_u is not None and lc_u < leq)


def _fmt(v, w=7, p=4):
    return f"{'-':>{w}}" if v is None else f"{v:{w}.{p}f}"


def main():
    print("Validation")
    print(f"  Biot (incompressible neo-Hookean): x^3+x^2+3x-1=0 -> l1/l2 = {X_BIOT:.6f}, "
          f"l1 = {STRETCH_BIOT:.6f}, l2/l1 = {RATIO_BIOT:.5f}")
    for K in (1e2, 1e3, 1e4, 1e6, 1e8):
        print(f"  compressible neo-Hookean, K/mu = {K:8.0e}: critical compression stretch = "
              f"{compressible_biot_stretch(K):.6f}")
    print(f"  hydrogel, diffusion off (s = s0), defaults: critical compression stretch = "
          f"{undrained_compression_stretch():.6f}")
    print(f"  drained moduli vs finite differences of min_s(psi - mu s): max rel. dev. = "
          f"{drained_energy_fd_check():.2e}")
    A = tangent_moduli(1.0, 3.0, 1.0, -3.0, 7.0)
    print(f"  closed-form vs complex-root surface determinant (k = 7, lam = 3): "
          f"{surface_determinant(A):.6e} vs {surface_determinant_complex(A).real:.6e} "
          f"(imag {surface_determinant_complex(A).imag:.1e}); reduced form x (k l2/l1) sqrt(1 + k l2^2) = "
          f"{surface_margin(1.0, 3.0, 7.0) * 7 * 3 * 8:.6e}")
    mu_n = network_shear(DEFAULT["gamma"], DEFAULT["J0"])
    lc_half = drained_critical_stretch()
    print(f"  layer on a rigid substrate, drained (defaults), Rayleigh-Ritz in the thickness (P2) vs the "
          f"half-space root {lc_half:.6f}:")
    for kH in (2.0, 4.0, 8.0, 30.0):
        def ev(lam):
            A_ = tangent_moduli(1.0, lam, 1.0, -lam, drained_G2(lam, **DEFAULT) / mu_n)
            return layer_min_eigenvalue(A_, kH, n_el=160)
        print(f"    kH = {kH:4.0f}: critical lam = {brentq(ev, 2.5, 3.6, xtol=1e-8):.6f}")
    print()
    print("Constrained layer, thickness stretch lam relative to the preswollen reference (dry: x J0^(1/3))")
    hdr = (f"{'gamma':>6} {'chi':>5} {'N Omega':>8} {'eps':>6} {'J0':>5} | {'lc_drain':>8} {'(dry)':>7} | "
           f"{'lc_undr':>7} {'(dry)':>7} | {'lam_eq':>7} {'(dry)':>7} | drained / undrained unstable before eq.?")
    print(hdr)
    print("-" * len(hdr))
    cases = [(0.1, 24.2, 10.0, 1.01, 0.1), (0.1, 24.2, math.inf, 1.01, 0.1), (0.1, 24.2, 10.0, 1.0, 0.1),
             (0.1, 24.2, math.inf, 1.0, 0.1), (0.1, 24.2, 1e3, 1.01, 0.1)]
    for g in (0.01, 0.1, 0.3, 0.8, 1.0):
        for chi in (0.1, 0.3, 0.5):
            cases.append((g, 24.2, 10.0, 1.01, chi))
    for g, a, e, J0, chi in cases:
        r = summary_row(g, a, e, J0, chi)
        print(f"{g:6.3g} {chi:5.2f} {r['NOmega']:8.2e} {e:6.3g} {J0:5.3f} | {_fmt(r['lc_d'], 8)} "
              f"{_fmt(r['lc_d_dry'])} | {_fmt(r['lc_u'])} {_fmt(r['lc_u_dry'])} | {r['leq']:7.4f} "
              f"{r['leq_dry']:7.4f} | {'yes' if r['drained_unstable'] else 'no'} / "
              f"{'yes' if r['undrained_unstable'] else 'no'}")
    print()
    print("Kang & Huang limit (eps = inf, J0 = 1): drained critical linear swelling ratio lc and equilibrium lam_eq")
    print(f"{'N Omega':>8} " + " ".join(f"{'chi=' + str(c):>15}" for c in (0.0, 0.2, 0.4, 0.6)))
    for NO in (1e-4, 1e-3, 4.13e-3, 1e-2, 3e-2, 1e-1):
        cells = []
        for chi in (0.0, 0.2, 0.4, 0.6):
            lc = drained_critical_stretch(NO, 1.0, math.inf, 1.0, chi)
            leq = equilibrium_stretch(NO, 1.0, math.inf, 1.0, chi)
            cells.append(f"{_fmt(lc, 6, 3)}/{leq:6.3f}{'*' if lc is not None and lc < leq else ' '}")
        print(f"{NO:8.2e} " + " ".join(f"{c:>15}" for c in cells))
    print("  (* = lc < lam_eq: the layer becomes surface-unstable (drained) before it reaches equilibrium)")
    print()
    print("Finite tau (defaults, half-space mode kH = 30): growth rate omega = M k^2 Omega(lam) of the linearized")
    print("gradient flow, and the inertia of K_tau = E + D/tau (one Fourier mode)")
    for lam in (3.0, 3.141, 3.145, 3.15, 3.2, 3.25, 3.3, 3.35):
        r = growth_rates(lam, 30.0, n_modes=1)
        om = r[0] if r[0] > 1e-6 else 0.0
        cnt = [K_tau_negative_count(lam, t / om, 30.0) if om > 0 else K_tau_negative_count(lam, 1e6, 30.0)
               for t in (0.9, 1.1)]
        print(f"  lam = {lam:5.3f}: Omega = {om:10.4g} MPa;  negative eigenvalues of K_tau at "
              f"omega tau = 0.9 / 1.1: {cnt[0]} / {cnt[1]}")
    print("  K_tau onset stretch vs tau M k^2 (drained %.4f ... undrained %.4f):"
          % (drained_critical_stretch(), undrained_critical_stretch()))
    for t in (1e4, 1e2, 1.0, 1e-1, 1e-2, 1e-3, 1e-4):
        print(f"    tau M k^2 = {t:7.0e} MPa^-1: lam_tau = {tau_onset_stretch(t):.4f}")


if __name__ == "__main__":
    main()
