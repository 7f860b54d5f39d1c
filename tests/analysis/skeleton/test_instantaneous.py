"""Instantaneous amplitude/phase/frequency: closed forms, pywt cross-check, ridge DP, chunking, errors."""

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.skeleton.instantaneous import analytic_ratios, instantaneous
from hilbench.analysis.skeleton.wavelet_ridge import morlet_spectrum, ridge_path

FS = 1000.0
T = np.arange(60000) / FS
INNER = (T > 6.0) & (T < 54.0)


def test_multitone_filtered_analytic_signal_matches_closed_form():
    # Sum of cosines: the band-passed analytic signal at any scale s is exactly
    # Y_s = sum a_k*Psi(s*f_k)*exp(j*(2*pi*f_k*t + phi_k)); Y', Y'' multiply each term by (j*2*pi*f_k)^n.
    # Tolerance 1e-4: record-edge leakage through the Gaussian tails, far below any use of p, q.
    fk = np.array([1.7, 2.0, 2.3])
    ak = np.array([0.2, 1.0, 0.3])
    ph = np.array([0.1, 0.5, -1.0])
    x = (ak[:, None] * np.cos(2 * np.pi * fk[:, None] * T + ph[:, None])).sum(0)
    res, rat = analytic_ratios(x, FS, (), "cwt", freq_range=(1.0, 4.0))
    terms = ak[:, None] * morlet_spectrum(res.scale[None, :] * fk[:, None], 0.5, 0.8) * np.exp(
        1j * (2 * np.pi * fk[:, None] * T + ph[:, None]))
    y = terms.sum(0)
    yd = (terms * 2j * np.pi * fk[:, None]).sum(0)
    ydd = (terms * (2j * np.pi * fk[:, None]) ** 2).sum(0)
    v = INNER
    assert np.max(np.abs(rat.y[v] - y[v])) / np.max(np.abs(y)) < 1e-4
    assert np.max(np.abs(rat.p[v] - yd[v] / y[v])) / (2 * np.pi * 2.0) < 1e-4
    assert np.max(np.abs(rat.q[v] - ydd[v] / y[v])) / (2 * np.pi * 2.0) ** 2 < 1e-4


@pytest.mark.parametrize("method, kw, tol_a, tol_da, tol_dda", [
    ("cwt", {}, 2e-3, 1e-2, 5e-2),
    ("cwt", {"fb": 1.5, "fc": 1.8}, 3e-2, 5e-2, 5e-2),
    ("hilbert", {}, 2e-3, 1e-1, None),
])
def test_amplitude_modulated_tone(method, kw, tol_a, tol_da, tol_dda):
    # x = A(t)*cos(2*pi*2*t), A = 0.5*(1 + 0.3*sin(2*pi*0.05*t)): closed-form A, A', A'', omega = 4*pi.
    # Tolerances (relative to max|A|, max|A'|, max|A''|) are the wavelet's smoothing of a 0.05 Hz modulation
    # over its time envelope (sigma_t = 0.2 s for 0.5/0.8, 0.78 s for 1.5/1.8); A'' is a tiny difference of
    # Re(Y''/Y) and omega^2, so Hilbert's unfiltered A'' is not checked.
    w_m = 2 * np.pi * 0.05
    a = 0.5 * (1 + 0.3 * np.sin(w_m * T))
    da = 0.5 * 0.3 * w_m * np.cos(w_m * T)
    dda = -0.5 * 0.3 * w_m**2 * np.sin(w_m * T)
    r = instantaneous(a * np.cos(2 * np.pi * 2.0 * T + 0.3), FS, method, **kw)
    v = r.valid & INNER
    assert v.sum() == INNER.sum()
    assert np.max(np.abs(r.amplitude[v] / a[v] - 1)) < tol_a
    assert np.max(np.abs(r.dA[v] - da[v])) / np.max(np.abs(da)) < tol_da
    assert np.max(np.abs(r.omega[v] / (4 * np.pi) - 1)) < 1e-3
    if tol_dda is not None:
        assert np.max(np.abs(r.ddA[v] - dda[v])) / np.max(np.abs(dda)) < tol_dda


def test_frequency_modulated_tone():
    # f(t) = 2 + 0.4*sin(2*pi*0.03*t) Hz, constant amplitude 0.5: closed-form omega and omega'.
    # Tolerances: 1e-3 on omega, 2e-2 of max|omega'| (measured 3e-4 and 6e-3 with cmor0.5-0.8).
    w_m = 2 * np.pi * 0.03
    omega = 2 * np.pi * (2 + 0.4 * np.sin(w_m * T))
    domega = 2 * np.pi * 0.4 * w_m * np.cos(w_m * T)
    psi = 2 * np.pi * (2 * T - 0.4 / w_m * np.cos(w_m * T))
    r = instantaneous(0.5 * np.cos(psi), FS, "cwt")
    v = r.valid & INNER
    assert v.sum() == INNER.sum()
    assert np.max(np.abs(r.omega[v] / omega[v] - 1)) < 1e-3
    assert np.max(np.abs(r.domega[v] - domega[v])) / np.max(np.abs(domega)) < 2e-2
    assert np.max(np.abs(r.amplitude[v] / 0.5 - 1)) < 1e-3
    # phase is psi up to a constant; 0.05 rad covers the filter's uneven weighting of the FM sidebands
    dphi = r.phase[v] - psi[v]
    assert np.ptp(dphi) < 0.05


def test_magnitude_agrees_with_pywt_cwt():
    # Independent implementation: pywt.cwt (time-domain integrated wavelet). Away from the band's low end the
    # zero-mean correction is negligible, so |W_pywt| / |W_ours| must be one constant per scale
    # (pywt's sqrt(scale) normalisation); 1 % covers pywt's first-order differencing.
    pywt = pytest.importorskip("pywt")
    t = T[:20000]
    x = np.cos(2 * np.pi * (1.0 * t + 0.05 * t**2)) * (1 + 0.3 * np.sin(2 * np.pi * 0.07 * t))
    fb, fc = 1.5, 1.8
    scales = fc / np.array([1.5, 2.0, 2.5])
    cw, _ = pywt.cwt(x, scales * FS, f"cmor{fb}-{fc}", sampling_period=1 / FS, method="fft")
    from hilbench.analysis.skeleton.wavelet_ridge import analytic_spectrum
    nfft = 2 * x.size
    spec = analytic_spectrum(x, nfft)
    f = np.arange(spec.size) * FS / nfft
    sl = slice(5000, 15000)
    for i, s in enumerate(scales):
        full = np.zeros(nfft, complex)
        full[: spec.size] = spec * morlet_spectrum(s * f, fb, fc)
        ours = np.fft.ifft(full)[: x.size]
        strong = np.abs(ours[sl]) > 0.05 * np.abs(ours[sl]).max()
        ratio = np.abs(cw[i, sl])[strong] / np.abs(ours[sl])[strong]
        assert strong.sum() > 2000
        assert np.std(ratio) / np.mean(ratio) < 1e-2
        # pywt normalises by sqrt(scale in samples) and keeps half the analytic amplitude
        assert np.mean(ratio) == pytest.approx(np.sqrt(s * FS) / 2, rel=1e-2)


def test_ridge_path_penalises_jumps():
    # A ridge on bin 10 with a brief, stronger blip on bin 30: with a jump penalty the path stays on the
    # ridge (a detour costs 2 jumps of 20 bins); without penalty and with free jumps it follows the maximum.
    log_mag = np.full((40, 200), -10.0)
    log_mag[10, :] = 0.0
    log_mag[30, 100:103] = 1.0
    assert np.all(ridge_path(log_mag, penalty=0.5, max_jump=40) == 10)
    free = ridge_path(log_mag, penalty=0.0, max_jump=40)
    assert np.all(free[100:103] == 30) and free[0] == 10
    # a slowly drifting ridge is followed exactly
    drift = np.full((40, 200), -10.0)
    idx = (5 + np.arange(200) // 10).astype(int)
    drift[idx, np.arange(200)] = 0.0
    assert np.array_equal(ridge_path(drift, penalty=0.5, max_jump=2), idx)


def test_ridge_path_is_the_cheapest_of_all_paths_by_enumeration():
    # Independent oracle: every path through a 4-scale, 6-column map (4^6 = 4096) scored by the stated cost
    # sum_t -log_mag[i_t, t] + penalty*(i_t - i_{t-1})^2 with |jump| <= max_jump; the DP must find the minimum
    # (random maps: the minimum is unique to 1e-9 in each case drawn)
    import itertools

    rng = np.random.default_rng(7)
    for max_jump in (1, 2, 5):
        for _ in range(5):
            log_mag = rng.normal(size=(4, 6))
            best, best_cost = None, np.inf
            for path in itertools.product(range(4), repeat=6):
                jumps = np.diff(path)
                if np.any(np.abs(jumps) > max_jump):
                    continue
                c = -log_mag[list(path), range(6)].sum() + 0.5 * float(np.sum(jumps**2))
                if c < best_cost:
                    best, best_cost = path, c
            assert tuple(ridge_path(log_mag, penalty=0.5, max_jump=max_jump)) == best


@pytest.mark.parametrize("method, tol", [("cwt", 1e-4), ("hilbert", 1e-2)])
def test_chunked_equals_single_pass(method, tol):
    # Chunks are padded by five wavelet widths (cwt: envelope weight 4e-6 left) or by the Hilbert edge; the
    # Hilbert kernel decays only as 1/t, hence its looser 1e-2.
    t = T[:40000]
    x = (1 + 0.3 * np.sin(0.3 * t)) * np.cos(2 * np.pi * (1.5 * t + 0.01 * t**2))
    one = instantaneous(x, FS, method, freq_range=(0.5, 5.0))
    many = instantaneous(x, FS, method, freq_range=(0.5, 5.0), max_core=4096)
    v = one.valid & many.valid
    assert v.sum() > 0.8 * one.valid.sum()
    assert np.max(np.abs(many.amplitude[v] / one.amplitude[v] - 1)) < tol
    assert np.max(np.abs(many.omega[v] / one.omega[v] - 1)) < tol


def test_cone_of_influence_marks_record_ends_invalid():
    x = np.cos(2 * np.pi * 2.0 * T[:20000])
    r = instantaneous(x, FS, "cwt")
    sigma_t = 0.8 / 2.0 * np.sqrt(0.5 / 2)     # s*sqrt(fb/2) at the 2 Hz ridge
    n_coi = int(4.0 * sigma_t * FS)
    assert not r.valid[: n_coi - 50].any() and not r.valid[-(n_coi - 50):].any()
    assert r.valid[n_coi + 200: -(n_coi + 200)].all()


def test_errors_are_analysis_errors():
    x = np.cos(2 * np.pi * 2.0 * T[:20000])
    with pytest.raises(AnalysisError, match="missing"):
        instantaneous(None, FS)
    with pytest.raises(AnalysisError, match="NaN"):
        instantaneous(np.r_[x, np.nan], FS)
    with pytest.raises(AnalysisError, match="too short"):
        instantaneous(x[:300], FS, freq_range=(1.0, 4.0))
    with pytest.raises(AnalysisError, match="too short"):
        instantaneous(x[:300], FS, fb=1.5, fc=1.8)
    with pytest.raises(AnalysisError, match="never crosses"):
        instantaneous(np.cos(2 * np.pi * 40.0 * T[:20000]), FS, freq_range=(0.5, 3.0))
    with pytest.raises(AnalysisError, match="unknown method"):
        instantaneous(x, FS, method="stft")
    with pytest.raises(AnalysisError, match="fb"):
        instantaneous(x, FS, fb=0.1, fc=0.5)
    with pytest.raises(AnalysisError, match="constant"):
        instantaneous(np.ones(20000), FS)


def test_the_ridge_streamed_block_by_block_is_the_whole_maps_ridge(monkeypatch):
    """The ridge without the map (wavelet_ridge.streamed_ridge: |W| block by block into RidgeTracker, 1 byte per
    cell) equals ridge_path of the whole map normalised by its maximum, bit for bit, on a chirp whose amplitude
    grows 100-fold (the running maximum used as the floor's reference changes from block to block); and the
    tracker fed any split of a map gives ridge_path's path."""
    from hilbench.analysis.skeleton.wavelet_ridge import (
        RidgeTracker,
        magnitude_blocks,
        magnitude_map,
        scale_grid,
        streamed_ridge,
    )

    fs, n = 200.0, 40_000
    t = np.arange(n) / fs
    x = np.geomspace(0.01, 1.0, n) * np.sin(np.pi * 0.05 * t**2 + 2 * np.pi * 0.5 * t)  # 0.5 to 10.5 Hz
    scales = scale_grid(0.3, 20.0, 0.8, 16)
    hop, core = 4, 4096  # about ten blocks
    assert len(list(magnitude_blocks(x, fs, scales, 0.5, 0.8, hop, core))) >= 9
    mag = magnitude_map(x, fs, scales, 0.5, 0.8, hop, core)
    whole = ridge_path(np.log(mag / float(mag.max()) + 1e-12), 0.5, 3)
    np.testing.assert_array_equal(streamed_ridge(x, fs, scales, 0.5, 0.8, hop, core, 0.5, 3), whole)
    import hilbench.analysis.skeleton.wavelet_ridge as wavelet_ridge

    monkeypatch.setattr(wavelet_ridge, "RIDGE_COLUMNS", 100)  # each block handed to the ridge in parts
    np.testing.assert_array_equal(streamed_ridge(x, fs, scales, 0.5, 0.8, hop, core, 0.5, 3), whole)
    f_ridge = 0.8 / scales[whole[500:-500]]  # the chirp's frequency, to a bin (16 voices: 4.4 %)
    f_true = 0.5 + 0.05 * t[::hop][500:-500]
    assert np.max(np.abs(f_ridge / f_true - 1)) < 0.05
    log_mag = np.log(mag + 1e-12)
    tracker = RidgeTracker(scales.size, mag.shape[1], 0.5, 3)
    for a, b in ((0, 1), (1, 7), (7, 5000), (5000, mag.shape[1])):
        tracker.push(log_mag[:, a:b])
    np.testing.assert_array_equal(tracker.path(), ridge_path(log_mag, 0.5, 3))
