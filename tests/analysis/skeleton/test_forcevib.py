"""ForceVib against independent oracles: linear SDOF and Duffing (scipy DOP853, rtol 1e-10) under a chirp
F = G*sin(pi*a*t^2) sampled at 1 kHz; and the paper's Maxwell-slip system (C plant) against closed forms."""

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.skeleton.forcevib import _binned, compose, forcevib
from tests.analysis.chirp_oracle import chirp_response

FS = 1000.0
M, C, K = 1.0, 0.5, 50.0


def _linear(c=C, G=1.0, a=0.1, T=20.0):
    return chirp_response(M, c, K, 0.0, G, a, T, FS)


@pytest.mark.parametrize("method, kw", [("cwt", {}), ("cwt", {"fb": 1.5, "fc": 1.8}), ("hilbert", {})])
def test_linear_sdof_k_and_c_recovered(method, kw):
    # ForceVib is exact for a linear system whatever the band-pass, so k and c (median over valid samples)
    # must come back within 0.5 % (measured: cwt 1e-7 / 1e-5, hilbert 7e-5 / 3e-3).
    _, x, F = _linear()
    r = forcevib(x, F, FS, M, method, **kw)
    v = r.valid
    assert v.mean() > 0.3
    assert np.median(r.stiffness[v]) == pytest.approx(K, rel=5e-3)
    assert np.median(r.damping[v]) == pytest.approx(C, rel=5e-3)
    if method == "cwt":
        # pointwise: 90 % of valid samples within 0.5 % (1.5/1.8: every sample, measured 5e-5)
        q = 100 if kw else 90
        assert np.percentile(np.abs(r.stiffness[v] / K - 1), q) < 5e-3
        assert np.percentile(np.abs(r.damping[v] / C - 1), q) < 5e-3


def test_cone_of_influence_is_where_the_chirp_end_departs():
    # The record is cut mid-vibration at its end. Samples the COI mask (4 sigma_t) drops but a 1 sigma_t mask
    # would keep carry errors well above 0.5 %; the kept ones stay below it.
    _, x, F = _linear()
    strict = forcevib(x, F, FS, M, fb=1.5, fc=1.8)
    loose = forcevib(x, F, FS, M, fb=1.5, fc=1.8, coi=1.0)
    dropped = loose.valid & ~strict.valid & (loose.t > 10.0)
    assert dropped.sum() > 1000
    assert np.max(np.abs(loose.damping[dropped] / C - 1)) > 0.05
    assert np.max(np.abs(strict.damping[strict.valid] / C - 1)) < 5e-3


@pytest.mark.parametrize("method, tol", [("cwt", 1e-2), ("hilbert", None)])
def test_duffing_backbone(method, tol):
    # m x'' + c x' + k x + k3 x^3 = F: backbone omega(A) = omega0*sqrt(1 + 3*k3*A^2/(4*k)), an 8.8 % shift at
    # the largest amplitude. Wavelet: every valid sample within 1 % (measured 0.6 %). Hilbert (unfiltered
    # harmonics ripple its envelope): the median error within 1 % (measured 0.06 %).
    k3 = 500.0
    _, x, F = chirp_response(M, C, K, k3, 1.0, 0.1, 20.0, FS)
    r = forcevib(x, F, FS, M, method)
    v = r.valid
    a = r.amplitude[v]
    backbone = np.sqrt(K / M) * np.sqrt(1 + 3 * k3 * a**2 / (4 * K))
    err = np.sqrt(np.abs(r.omega0_sq[v])) / backbone - 1
    assert a.max() > 0.15 and a.min() < 0.03          # the excited range spans the nonlinearity
    if tol is None:
        assert abs(np.median(err)) < 1e-2
    else:
        assert np.max(np.abs(err)) < tol
        assert np.median(r.damping[v]) == pytest.approx(C, rel=1e-2)


def test_compose_two_linear_runs():
    # Two excitation levels cover different amplitude ranges; the composed curve spans both and every bin
    # gives k within 0.5 % (linear: the skeleton is flat).
    runs = [forcevib(x, F, FS, M) for _, x, F in (_linear(G=0.5), _linear(G=4.0))]
    sk = compose(runs, n_bins=20)
    lo = min(np.min(r.amplitude[r.valid]) for r in runs)
    hi = max(np.max(r.amplitude[r.valid]) for r in runs)
    assert sk.amplitude[0] < 2 * lo and sk.amplitude[-1] > hi / 2
    np.testing.assert_allclose(sk.stiffness, K, rtol=5e-3)
    np.testing.assert_allclose(sk.damping, C, rtol=5e-3)
    # bin medians of k*A vs k*(median A): equal up to the bin width (20 bins over ~2 decades: 5 %)
    np.testing.assert_allclose(sk.restoring_force, K * sk.amplitude, rtol=5e-2)
    assert set(np.unique(sk.points_run)) == {0, 1}


def test_bad_inputs():
    _, x, F = _linear()
    with pytest.raises(AnalysisError, match="force.*missing"):
        forcevib(x, None, FS, M)
    with pytest.raises(AnalysisError, match="mass"):
        forcevib(x, F, FS, 0.0)
    with pytest.raises(AnalysisError, match="shape"):
        forcevib(x, F[:-1], FS, M)
    with pytest.raises(AnalysisError, match="never crosses"):
        forcevib(x, F, FS, M, freq_range=(20.0, 40.0))
    with pytest.raises(AnalysisError):
        compose([])


# --- paper's Maxwell-slip system (needs the C plant) -------------------------------------------------------

H, D = 1.64, 0.656          # virgin curve (science.md §2)


def _paper_runs(levels, a=0.05, T=40.0, n_elements=16):
    plant = pytest.importorskip("hilbench.firmware_sim.engine.plant")
    models = pytest.importorskip("hilbench.firmware_sim.engine.friction_models")
    params = models.paper_system(n_elements)
    dt = 1.0 / FS
    t = np.arange(int(T * FS) + 1) * dt
    runs = []
    for G in levels:
        # the plant holds u[k] over [t_k, t_k+1): sample the chirp mid-interval so that the held force is
        # centred on the analysed F(t_k) (no half-sample delay, which would bias the damping by ~5 %)
        out = plant.simulate(params, G * np.sin(np.pi * a * (t + dt / 2) ** 2), dt, substeps=4)
        force = G * np.sin(np.pi * a * t**2)
        runs.append(forcevib(out.theta, force, FS, params.inertia, spring=params.spring))
    return params, runs


@pytest.fixture(scope="module")
def paper_skeleton():
    params, runs = _paper_runs([0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0])
    return params, compose(runs, n_bins=30)


def test_maxwell_slip_equivalent_stiffness(paper_skeleton):
    # k_eq(A) = 2h*sqrt(d)/(d+A)^(3/2) (science.md §3), spring subtracted: every composed bin within 5 % over
    # the whole excited range (measured worst 2.4 %; 16-element discretisation alone accounts for -2.3 %).
    _, sk = paper_skeleton
    a = sk.amplitude
    k_ref = 2 * H * np.sqrt(D) / (D + a) ** 1.5
    assert a.min() < 0.01 and a.max() > 3.0
    np.testing.assert_array_less(np.abs(sk.stiffness / k_ref - 1), 0.05)
    # restoring force of the friction alone peaks near A = 2d (d/dA [k_eq*A] = 0)
    assert 0.5 * D < a[np.argmax(sk.restoring_force)] < 5 * D


def test_rate_fit_recovers_the_steady_value_of_a_biased_power_law():
    # Oracle: y = 2*A^3*(1 - 3*rate) with every sample growing (rate 0.01..0.04, as below resonance) and 5 %
    # gross outliers. The median is biased by -3*median(rate) ~ -7.5 %; the rate fit returns 2*A_bin^3 (the
    # steady value at the bin's median amplitude) within 0.5 %.
    rng = np.random.default_rng(4)
    n = 40_000
    a = np.exp(rng.uniform(np.log(0.01), np.log(1.0), n))
    rate = rng.uniform(0.01, 0.04, n)
    y = 2 * a**3 * (1 - 3 * rate) * (1 + 1e-3 * rng.normal(size=n))
    bad = rng.random(n) < 0.05
    y[bad] *= rng.uniform(0, 3, bad.sum())
    centre, (fit,), count = _binned(a, (y,), rate, 10, 20, "rate")
    np.testing.assert_allclose(fit, 2 * centre**3, rtol=5e-3)
    _, (med,), _ = _binned(a, (y,), rate, 10, 20, "median")
    assert np.all(med / (2 * centre**3) - 1 < -0.04)
    with pytest.raises(AnalysisError, match="method"):
        compose([forcevib(*_linear()[1:], FS, M)], method="mean")


@pytest.fixture(scope="module")
def fine_paper_runs():
    # 64 elements: the discretisation is within 0.6 % of the continuous closed forms, so what is left is the
    # method's own error. The 13 chirp levels of ``hilbench paper``.
    return _paper_runs([0.2, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0, 5.0, 7.0, 10.0, 14.0, 20.0], n_elements=64)[1]


def test_maxwell_slip_energy_per_cycle(fine_paper_runs):
    # E(A) = 4hA^3/(d+A)^2 from the equivalent damping, E = pi*c_eq*omega*A^2, every 30-bin value within 5 %
    # for A >= 0.01 m = 0.015 d (measured worst 4.1 %; below, only quasi-static samples of the two smallest
    # chirps and the dead-zone). The up/down medians (previous default) miss by up to 7 %: below resonance a
    # chirp only grows the amplitude, and a growing hysteretic loop dissipates less than its steady loop.
    def worst(method):
        sk = compose(fine_paper_runs, n_bins=30, method=method)
        a = sk.amplitude
        e_ref = 4 * H * a**3 / (D + a) ** 2
        err = np.abs(sk.energy / e_ref - 1)[a >= 0.01]
        assert err.size >= 18
        return float(np.max(err))

    assert worst("rate") < 0.05
    assert worst("updown") > 0.06


def test_maxwell_slip_dead_zone():
    # Below the smallest slip displacement Delta_min every element sticks: the system is linear with
    # stiffness spring + sum(k_i) and NO damping, so E departs from 4hA^3/(d+A)^2 (-> 0 here). This is the
    # paper's dead-zone (an artefact of the finite discretisation), not an analysis error.
    params, runs = _paper_runs([0.005], a=0.1, T=20.0)
    r = runs[0]
    v = r.valid
    delta_min = np.min(np.asarray(params.ms_slip) / np.asarray(params.ms_stiffness))
    assert np.max(r.amplitude[v]) < delta_min
    np.testing.assert_allclose(np.median(r.stiffness[v]), params.spring + sum(params.ms_stiffness), rtol=1e-3)
    # c_eq ~ 0 (measured 5e-5 N*s/m, the level a friction-free linear plant also returns), while the
    # continuous virgin curve would give c_eq = E/(pi*omega*A^2) = 4hA/(pi*omega*(d+A)^2) ~ 1e-3 at these
    # amplitudes: the departure from E(A) = 4hA^3/(d+A)^2 is total in the dead-zone.
    a = r.amplitude[v]
    c_cont = 4 * H * a / (np.pi * r.omega[v] * (D + a) ** 2)
    assert abs(np.median(r.damping[v])) < 0.25 * np.median(c_cont)
