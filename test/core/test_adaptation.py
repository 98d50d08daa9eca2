"""Tests of stability bounds, adaptation coefficients and tone-response identification."""

import numpy as np
import pytest
from linear_plants import frequency_response, resonance_bank, simulate, simulate_with_gaps

from hexapod_vibration.core.control import adaptation as ad
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

FS = 1000.0
TONES = np.array([40.0, 80.0, 120.0])


# ----------------------------------------------------------------------------- test plants
def resonant_plant(f_res_hz, zeta=0.2, gain=0.1, coupling=0.0, seed=0):
    """(A, B, C) at FS: coupling K, then a ZOH resonance per channel.

    K has |off-diagonal| in [0.5, 1] x coupling; each channel is
    g w^2/(s^2 + 2 zeta w s + w^2), strictly proper (one-sample command hold).
    """
    f_res_hz = np.atleast_1d(f_res_hz)
    n = f_res_hz.size
    rng = np.random.default_rng(seed)
    off = rng.uniform(0.5, 1.0, (n, n)) * rng.choice([-1.0, 1.0], (n, n))
    k = np.eye(n) + coupling * off * (1 - np.eye(n))
    a, b, c = resonance_bank(f_res_hz, zeta, gain)
    return a, b @ k, c


def coupled_plant():
    return resonant_plant(np.linspace(55.0, 75.0, 6), coupling=0.3, seed=3)


def delay_plant(gain_matrix, delay):
    """y_n = K u_{n - delay} (delay >= 1) as a state space."""
    c = gain_matrix.shape[0]
    n = delay * c
    a = np.zeros((n, n))
    a[c:, :-c] = np.eye(n - c)
    b = np.zeros((n, c))
    b[:c] = np.eye(c)
    cm = np.zeros((c, n))
    cm[:, -c:] = gain_matrix
    return a, b, cm


def shaker_disturbance(n_samples, tones, n_channels, amp=0.3, noise=0.0, seed=0):
    """Tones with a random per-channel amplitude/phase mixing (an off-centre shaker)."""
    rng = np.random.default_rng(seed)
    n = np.arange(n_samples)
    phases = 2 * np.pi * np.outer(n, tones) / FS
    mix_c = rng.standard_normal((len(tones), n_channels))
    mix_s = rng.standard_normal((len(tones), n_channels))
    d = amp * (np.cos(phases) @ mix_c + np.sin(phases) @ mix_s) / 2
    return d + noise * rng.standard_normal((n_samples, n_channels))


def tone_amplitudes(x, tones, n0):
    """Least-squares amplitude |X| of each tone in each channel of x (time n0 + k)."""
    n = n0 + np.arange(x.shape[0])
    ph = 2 * np.pi * np.outer(n, tones) / FS
    reg = np.hstack([np.cos(ph), np.sin(ph), np.ones((n.size, 1))])
    coef, *_ = np.linalg.lstsq(reg, x, rcond=None)
    t = len(tones)
    return np.abs(coef[:t] - 1j * coef[t:2 * t])


def log_slope(values, sel):
    return np.polyfit(np.flatnonzero(sel), np.log(values[sel]), 1)[0]


# ----------------------------------------------------------------------------- eq. (18)
def test_paper_mu_bound_is_the_averaged_recursion_limit():
    for beta in np.radians([95.0, 120.0, 165.6, -100.0, 180.0]):
        alpha = 0.37
        bound = ad.paper_mu_bound(alpha, beta)
        assert bound == pytest.approx(-4 * np.cos(beta) / alpha)
        assert abs(1 + bound / 2 * alpha * np.exp(1j * beta)) == pytest.approx(1.0)
        assert abs(1 + 0.99 * bound / 2 * alpha * np.exp(1j * beta)) < 1.0
    assert ad.paper_mu_bound(1.0, np.radians(60.0)) == 0.0
    assert ad.paper_mu_bound(1.0, np.pi / 2) == 0.0
    with pytest.raises(ValueError):
        ad.paper_mu_bound(0.0, np.pi)


def _raw_pure_gain_loop(gain, f, mu, n=4000):
    """e_n = g u_{n-1} + d_n with the raw paper canceller (P = 1); returns |e|."""
    anc = AdaptiveNotchCanceller(1, [f], FS, mu)
    u_prev, err = 0.0, np.empty(n)
    for k in range(n):
        e = gain * u_prev + np.cos(2 * np.pi * f * k / FS + 0.4)
        err[k] = abs(e)
        if err[k] > 1e6:              # diverged: stop before overflow
            err[k:] = np.inf
            break
        u_prev = anc.step(np.array([e]))[0]
    return err


@pytest.mark.parametrize("f, gain", [(40.0, -1.0), (300.0, 1.0)])
def test_raw_mu_real_signal_boundary_is_exact_lti_not_averaged(f, gain):
    """For real signals the loop is exactly LTI; its bound differs from eq. (18).

    Plant g z^-1 (pure gain, one-sample hold, d = 0): the characteristic polynomial
    z^2 - (2 cos w + mu g) z + 1 + mu g cos w gives mu < 2/|g| for any cos(beta) < 0.
    paper_mu_bound (-4 cos(beta)/alpha, averaged to first order) is 1.94x too high at
    beta = 166 deg and 0.62x (conservative) at beta = -108 deg.
    """
    plant = delay_plant(np.array([[gain]]), 1)
    g = frequency_response(plant, f)[0, 0, 0]
    alpha, beta = abs(g), np.angle(g)
    exact = ad.exact_mu_bound(plant, [f], FS, np.ones((1, 1, 1)))
    assert exact == pytest.approx(2.0 / alpha, rel=1e-3)
    assert _raw_pure_gain_loop(gain, f, 0.95 * exact)[-500:].max() < 1e-6
    assert _raw_pure_gain_loop(gain, f, 1.05 * exact)[-500:].max() > 1e3
    paper = ad.paper_mu_bound(alpha, beta)
    ratio = {40.0: 1.937, 300.0: 0.618}[f]
    assert paper / exact == pytest.approx(ratio, rel=1e-3)
    if paper > exact:   # inside the paper bound yet unstable
        assert _raw_pure_gain_loop(gain, f, 0.9 * paper)[-500:].max() > 1e3


def test_raw_mu_small_rate_matches_averaged_model():
    """Raw P = 1 at a small mu: the averaged rate |1 + (mu/2) G| is right (within 10 %).

    This resonant plant's exact bound is 1.04, 1/63 of paper_mu_bound (65.3): mu = 0.02 x
    paper_mu_bound diverges. 0.003 x paper_mu_bound = 0.19 x the exact bound is used.
    """
    f = 40.0
    plant = resonant_plant([25.0])
    g = frequency_response(plant, f)[0]
    paper = ad.paper_mu_bound(abs(g[0, 0]), np.angle(g[0, 0]))
    exact = ad.exact_mu_bound(plant, [f], FS, np.ones((1, 1, 1)))
    assert exact / paper == pytest.approx(0.016, abs=0.001)
    mu = 0.003 * paper
    anc = AdaptiveNotchCanceller(1, [f], FS, mu)
    n = np.arange(3000)
    dist = (0.3 * np.cos(2 * np.pi * f * n / FS + 0.7))[:, None]
    w_opt = -0.3 * np.exp(0.7j) / g[0, 0]
    dev = np.empty(n.size)

    def record(k):
        dev[k] = abs(anc.weights[0, 0] - w_opt)

    simulate(plant, anc, dist, record)
    observed = log_slope(dev, (n > 300) & (dev > 1e-9 * dev[0]))
    predicted = np.log(ad.convergence_factor(g, np.ones((1, 1)), mu))
    assert abs(observed - predicted) / abs(predicted) < 0.10


# ----------------------------------------------------------------------------- delayed modes
def test_mu_bound_closed_form_matches_numpy_roots():
    rng = np.random.default_rng(7)
    for _ in range(40):
        lam = rng.uniform(0.1, 2.0) * np.exp(1j * rng.uniform(-1.4, 1.4))
        d = int(rng.integers(0, 7))
        bound = ad.delayed_mode_mu_bound(lam, d)
        assert ad.delayed_mode_radius(lam, 0.999 * bound, d) < 1.0
        assert ad.delayed_mode_radius(lam, 1.001 * bound, d) > 1.0
    for d in range(6):
        assert ad.delayed_mode_mu_bound(0.5, d) == pytest.approx(
            2 * np.sin(np.pi / (2 * (2 * d + 1))) / 0.5)
    assert ad.delayed_mode_mu_bound(-0.1 + 1j, 0) == 0.0
    assert ad.mu_bound(np.eye(2), 2 * np.eye(2)) == 0.0           # M = -I: never stable
    assert ad.mu_bound(np.eye(2), -2 * np.eye(2), 2.5) == pytest.approx(2 * np.sin(np.pi / 14))


def test_normalized_coefficients_modes():
    g = frequency_response(coupled_plant(), TONES)
    lam = ad.weight_loop_eigenvalues(g, ad.normalized_coefficients(g, "centralized"))
    assert lam.shape == (3, 6) and np.allclose(lam, 1.0)
    p_dec = ad.normalized_coefficients(g, "decentralized")
    assert np.allclose(p_dec, np.stack([np.diag(-2 / np.diag(m)) for m in g]))
    lam_dec = ad.weight_loop_eigenvalues(g, p_dec)
    assert np.allclose(lam_dec.sum(axis=1), 6.0) and np.all(lam_dec.real > 0.5)
    assert np.array_equal(ad.normalized_coefficients(g, "raw"), np.broadcast_to(np.eye(6),
                                                                                (3, 6, 6)))
    bad = g.copy()
    bad[1] = np.outer(np.arange(1, 7), np.ones(6))        # rank one
    with pytest.raises(ValueError, match="ill-conditioned"):
        ad.normalized_coefficients(bad, "centralized")
    with pytest.raises(ValueError):
        ad.normalized_coefficients(g, "optimal")
    zero_diag = g.copy()
    zero_diag[0, 2, 2] = 0.0
    with pytest.raises(ValueError):
        ad.normalized_coefficients(zero_diag, "decentralized")


# ----------------------------------------------------------------------------- coupled 6x6
@pytest.mark.parametrize("mode", ["centralized", "decentralized"])
def test_normalized_p_reduces_tones_by_60db_on_coupled_plant(mode):
    plant = coupled_plant()
    g = frequency_response(plant, TONES)
    p = ad.normalized_coefficients(g, mode)
    dist = shaker_disturbance(3000, TONES, 6, noise=1e-5, seed=1)
    anc = AdaptiveNotchCanceller(6, TONES, FS, 0.01, p)
    err = simulate(plant, anc, dist)
    before = tone_amplitudes(dist[-1000:], TONES, 2000)
    after = tone_amplitudes(err[-1000:], TONES, 2000)
    reduction_db = 20 * np.log10(before / after)
    assert reduction_db.min() > 60.0
    assert ad.closed_loop_spectral_radius(plant, TONES, FS, p, 0.01) < 1.0


def test_convergence_rate_matches_convergence_factor():
    plant = coupled_plant()
    g = frequency_response(plant, TONES)
    p = ad.normalized_coefficients(g, "decentralized")
    mu = 0.01
    dist = shaker_disturbance(3000, TONES, 6, seed=2)
    n = np.arange(dist.shape[0])
    d_ph = np.stack([tone_amplitudes_phasor(dist, f) for f in TONES])     # (T, C)
    w_opt = -np.linalg.solve(g, d_ph[:, :, None])[:, :, 0]
    anc = AdaptiveNotchCanceller(6, TONES, FS, mu, p)
    dev = np.empty(n.size)

    def record(k):
        dev[k] = np.linalg.norm(anc.weights - w_opt)

    simulate(plant, anc, dist, record)
    observed = log_slope(dev, (n > 800) & (n < 2500))
    predicted = np.log(ad.convergence_factor(g, p, mu))
    exact = np.log(ad.closed_loop_spectral_radius(plant, TONES, FS, p, mu))
    assert abs(observed - predicted) / abs(predicted) < 0.10
    assert abs(observed - exact) / abs(exact) < 0.05
    assert ad.predicted_time_constant_s(g, p, mu, FS) == pytest.approx(-1 / (FS * predicted))


def tone_amplitudes_phasor(x, f):
    n = np.arange(x.shape[0])
    reg = np.column_stack([np.cos(2 * np.pi * f * n / FS), np.sin(2 * np.pi * f * n / FS)])
    coef, *_ = np.linalg.lstsq(reg, x, rcond=None)
    return coef[0] - 1j * coef[1]


def _growth(plant, tones, p, mu, n=4000):
    dist = shaker_disturbance(n, tones, plant[2].shape[0], seed=4)
    anc = AdaptiveNotchCanceller(plant[2].shape[0], tones, FS, mu, p)
    err = np.abs(simulate(plant, anc, dist)).max(axis=1)
    return err[-500:].max() / err[:500].max()


@pytest.mark.parametrize("mode", ["centralized", "decentralized"])
def test_mu_bound_separates_stable_from_unstable_where_averaging_holds(mode):
    """Coupled 6x6 pure-delay plant (d = 10) and one tone at 250 Hz: averaging holds."""
    rng = np.random.default_rng(3)
    k = np.eye(6) + 0.3 * rng.uniform(-1, 1, (6, 6)) * (1 - np.eye(6))
    plant, d, tones = delay_plant(k, 11), 10, np.array([250.0])
    g = frequency_response(plant, tones)
    p = ad.normalized_coefficients(g, mode)
    bound = ad.mu_bound(g, p, d)
    exact = ad.exact_mu_bound(plant, tones, FS, p)
    assert 0.9 < exact / bound < 1.0
    assert _growth(plant, tones, p, 0.85 * bound) < 1e-3
    assert _growth(plant, tones, p, 1.1 * bound) > 1e3


@pytest.mark.parametrize("mode", ["centralized", "decentralized"])
def test_exact_bound_on_resonant_plant_and_averaged_overestimate(mode):
    """Resonant coupled plant, 3 tones: the canceller's skirt meets the 55-75 Hz modes.

    The exact LTI bound (about 0.022) is what the simulation shows; the averaged mu_bound
    (about 2) is a necessary condition only and is ~90x too high here.
    """
    plant = coupled_plant()
    g = frequency_response(plant, TONES)
    p = ad.normalized_coefficients(g, mode)
    exact = ad.exact_mu_bound(plant, TONES, FS, p)
    assert 0.015 < exact < 0.03
    assert ad.mu_bound(g, p, 0) > 50 * exact
    assert _growth(plant, TONES, p, 0.9 * exact) < 1e-2
    assert _growth(plant, TONES, p, 1.1 * exact) > 1e2


# ----------------------------------------------------------------------------- identification
def test_identifier_recovers_plant_response_under_disturbance():
    plant = coupled_plant()
    g_true = frequency_response(plant, TONES)
    ident = ad.ToneResponseIdentifier(6, TONES, FS)
    assert ident.duration_s == pytest.approx(3.2)
    n_total = int(round(ident.duration_s * FS))
    # shaker at 40 Hz (larger than the response to the 2 N excitation) plus sensor noise
    dist = shaker_disturbance(n_total + 10, TONES[:1], 6, amp=2.0, noise=1e-4, seed=5)
    with pytest.raises(RuntimeError):
        ident.result()
    progress = []
    simulate(plant, ident, dist[:n_total], lambda k: progress.append(ident.progress))
    assert ident.done and progress[-1] == 1.0 and np.all(np.diff(progress) > 0)
    assert np.all(ident.step(np.ones(6)) == 0.0)
    g_est = ident.result()
    assert g_est.shape == (3, 6, 6)
    mag_err = np.abs(np.abs(g_est) / np.abs(g_true) - 1)
    phase_err = np.degrees(np.abs(np.angle(g_est / g_true)))
    assert mag_err.max() < 0.01
    assert phase_err.max() < 1.0
    # without the baseline subtraction the 40 Hz disturbance would dominate
    shaker = tone_amplitudes(dist, TONES[:1], 0)[0]
    assert np.all(shaker > 2.0 * np.abs(g_true[0]).max(axis=1))


def test_identifier_validation():
    with pytest.raises(ValueError):
        ad.ToneResponseIdentifier(6, [], FS)
    with pytest.raises(ValueError):
        ad.ToneResponseIdentifier(6, [40.0, 40.0], FS)
    with pytest.raises(ValueError):
        ad.ToneResponseIdentifier(6, [40.0], FS, amplitude_n=-1.0)
    with pytest.raises(ValueError):
        ad.ToneResponseIdentifier(6, [40.0], FS, measure_s=0.001)


def test_the_tone_identification_leaves_missing_samples_out_of_its_fits():
    a, b, c = resonance_bank([30.0, 55.0, 90.0], 0.1, 1.0)
    plant = (a, b @ (np.eye(3) + 0.3 * np.random.default_rng(1).normal(size=(3, 3))), c)
    ident = ad.ToneResponseIdentifier(3, [40.0, 80.0], FS)
    n = int(round(ident.duration_s * FS))
    t = np.arange(n) / FS
    dist = (0.5 * np.sin(2 * np.pi * 40.0 * t)[:, None] * np.ones(3)
            + 1e-4 * np.random.default_rng(3).normal(size=(n, 3)))
    missing = np.random.default_rng(7).random(n) < 0.02
    simulate_with_gaps(plant, ident, dist, missing)
    assert ident.done and 0 < ident.missing <= np.count_nonzero(missing)
    assert ident.missing_refusal() == ""
    exact = frequency_response(plant, [40.0, 80.0])
    error = np.linalg.norm(ident.result() - exact, axis=(1, 2)) / np.linalg.norm(exact,
                                                                                  axis=(1, 2))
    assert np.all(error < 0.02), error
