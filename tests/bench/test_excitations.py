"""Excitations checked against closed forms: filter response, Fourier series, instantaneous frequency,
whole-period windows."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from hilbench.bench.acquisition import excitations as ex


def _zero_crossings(t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Times where u changes sign, by linear interpolation between samples."""
    s = np.signbit(u)
    idx = np.nonzero(s[1:] != s[:-1])[0]
    idx = idx[u[idx] != 0.0]
    return t[idx] - u[idx] * (t[idx + 1] - t[idx]) / (u[idx + 1] - u[idx])


# ---- random-enveloped -------------------------------------------------------------------------------------


def test_lowpass_cutoff_attenuates_as_butterworth_closed_form():
    """The spectrum of the generated signal follows |H|^4 of the forward-backward Butterworth.

    Oracle: the digital Butterworth (bilinear, pre-warped) has
    |H|^2 = 1/(1 + (tan(pi f/fs)/tan(pi fc/fs))^(2N));
    filtfilt squares it again, so the power ratio to the pass band is |H|^4. Welch PSD of 200 s at 1 kHz,
    averaged over 4 Hz bands: about 1500 independent estimates per band, i.e. ~0.1 dB of scatter; the envelope
    (period 4 s) smears the spectrum by ~1.25 Hz, which on a slope of ~1.2 dB/Hz biases the band mean by
    well under 1 dB. Tolerance 1.5 dB.
    """
    fs, fc, order = 1000.0, 40.0, 4
    exc = ex.random_enveloped(200.0, fs, amplitude=5.0, period=4.0, cutoff=fc, order=order, seed=7)
    f, p = signal.welch(exc.u, fs=fs, nperseg=8192)
    passband = p[(f > 2.0) & (f < 15.0)].mean()

    def h4(freq):
        return (1.0 / (1.0 + (np.tan(np.pi * freq / fs) / np.tan(np.pi * fc / fs)) ** (2 * order))) ** 2

    for centre in (40.0, 50.0, 60.0, 70.0):
        band = (f > centre - 2.0) & (f < centre + 2.0)
        measured_db = 10 * np.log10(p[band].mean() / passband)
        expected_db = 10 * np.log10(h4(f[band]).mean())
        assert measured_db == pytest.approx(expected_db, abs=1.5), centre
    # "really attenuates": everything above 2*fc is at least 45 dB below the pass band (closed form: -48 dB).
    assert 10 * np.log10(p[f > 2 * fc].max() / passband) < -45.0


def test_envelope_is_three_term_rectangular_series():
    """DFT over 5 whole periods: DC = offset, harmonics 1, 3, 5 have amplitude 4A/(pi k), nothing else.

    Exact up to float rounding: tolerance 1e-9 (absolute, amplitude 5).
    """
    amplitude, period, offset, fs = 5.0, 2.0, 0.3, 1000.0
    n_periods = 5
    t = np.arange(int(n_periods * period * fs)) / fs
    e = ex.rectangular_envelope(t, amplitude, period, offset)
    spectrum = np.fft.rfft(e) / t.size
    mag = 2 * np.abs(spectrum)
    mag[0] = spectrum[0].real
    expected = np.zeros_like(mag)
    expected[0] = offset
    for k in (1, 3, 5):
        expected[k * n_periods] = 4 * amplitude / (math.pi * k)
    np.testing.assert_allclose(mag, expected, atol=1e-9)
    # sine series: the harmonics are in quadrature with t=0 (imaginary DFT, negative sign for sin)
    for k in (1, 3, 5):
        assert spectrum[k * n_periods].imag == pytest.approx(-2 * amplitude / (math.pi * k), abs=1e-9)


def test_random_enveloped_is_noise_times_envelope_and_seeded():
    """u = normalised low-passed noise x envelope, bounded by the envelope; the same seed reproduces it."""
    kw = dict(amplitude=2.0, period=3.0, offset=0.5, cutoff=40.0, seed=3)
    a = ex.random_enveloped(10.0, 1000.0, **kw)
    b = ex.random_enveloped(10.0, 1000.0, **kw)
    c = ex.random_enveloped(10.0, 1000.0, **{**kw, "seed": 4})
    np.testing.assert_array_equal(a.u, b.u)
    assert not np.allclose(a.u, c.u)
    env = ex.rectangular_envelope(a.t, 2.0, 3.0, 0.5)
    noise = ex.lowpass_uniform_noise(a.u.size, 1000.0, 40.0, seed=3)
    np.testing.assert_allclose(a.u, noise * env, rtol=0, atol=1e-12)
    assert np.max(np.abs(noise)) == pytest.approx(1.0, abs=1e-15)
    assert np.all(np.abs(a.u) <= np.abs(env) + 1e-12)
    assert a.u.size == 10000 and a.unit == "A"
    proto = a.protocol()
    assert proto["mode"] == "current" and proto["params"]["seed"] == 3 and proto["params"]["cutoff"] == 40.0


# ---- chirps -----------------------------------------------------------------------------------------------


def test_quadratic_chirp_instantaneous_frequency_is_a_t():
    """Phase pi*a*t^2 crosses zero at t_k = sqrt(k/a); the mean frequency over a half cycle [t_k, t_k+1] is
    exactly a*(t_k + t_k+1)/2 = 1/(2*dt). Zero crossings by linear interpolation at 10 kHz are accurate to
    ~1e-9 s here, so the relative tolerance 1e-5 has ample margin."""
    a, fs = 0.1, 10000.0
    exc = ex.quadratic_chirp(20.0, fs, gain=5.0, a=a)
    t = exc.t
    assert np.max(np.abs(exc.u)) <= 5.0
    zc = _zero_crossings(t, exc.u)
    k = np.arange(1, zc.size + 1)
    np.testing.assert_allclose(zc, np.sqrt(k / a), rtol=1e-6)
    mid = 0.5 * (zc[1:] + zc[:-1])
    f_half_cycle = 1.0 / (2.0 * np.diff(zc))
    np.testing.assert_allclose(f_half_cycle, a * mid, rtol=1e-5)


@pytest.mark.parametrize("method", ["linear", "log"])
def test_sweep_instantaneous_frequency(method):
    """Between consecutive zero crossings the phase advances by pi, so the integral of f(t) over each half
    cycle is 1/2: F(t_b) - F(t_a) = 1/2 with F(t) = f0 t + (f1-f0) t^2/(2T) (linear) or
    f0 T/ln(f1/f0) (f1/f0)^(t/T) (log). Zero crossings interpolated at 10 kHz: tolerance 1e-5 absolute."""
    f0, f1, T, fs = 0.5, 8.0, 10.0, 10000.0
    exc = ex.sweep(T, fs, gain=1.0, f_start=f0, f_stop=f1, method=method, mode="velocity")
    assert exc.unit == "rad/s" and exc.u[0] == pytest.approx(0.0, abs=1e-12)
    zc = _zero_crossings(exc.t, exc.u)
    if method == "linear":
        F = f0 * zc + (f1 - f0) * zc**2 / (2 * T)
    else:
        F = f0 * T / math.log(f1 / f0) * (f1 / f0) ** (zc / T)
    assert zc.size > 40
    np.testing.assert_allclose(np.diff(F), 0.5, atol=1e-5)


# ---- stepped sine -----------------------------------------------------------------------------------------


def test_stepped_sine_windows_hold_whole_periods():
    """Every settle and measure window holds an integer number of periods of the played frequency: its DFT
    has a single line at bin = number of periods with the step amplitude and no leakage (tolerance 1e-9
    relative to the amplitude, i.e. float rounding)."""
    fs = 1000.0
    freqs = [0.7, 1.3, 3.0, 7.77]
    amps = [0.4, 2.0]
    exc = ex.stepped_sine(fs, frequencies=freqs, amplitudes=amps, settle_periods=4, measure_periods=6)
    w = exc.windows
    assert len(w) == len(freqs) * len(amps)
    # amplitude outer loop, frequency inner loop
    np.testing.assert_array_equal(w["amplitude"], np.repeat(amps, len(freqs)))
    np.testing.assert_array_equal(w["frequency_requested"], np.tile(freqs, len(amps)))
    # windows tile the signal with no gap
    assert w["settle_start"][0] == 0 and w["measure_stop"][-1] == exc.u.size
    np.testing.assert_array_equal(w["settle_stop"], w["measure_start"])
    np.testing.assert_array_equal(w["measure_stop"][:-1], w["settle_start"][1:])
    g = math.gcd(4, 6)
    for row in w:
        f, amp = row["frequency"], row["amplitude"]
        # snapping bound: |f - f_req| / f_req <= f_req / (2 g fs)
        assert abs(f - row["frequency_requested"]) <= row["frequency_requested"] ** 2 / (2 * g * fs) + 1e-12
        for start, stop, periods in (
            (row["settle_start"], row["settle_stop"], row["settle_periods"]),
            (row["measure_start"], row["measure_stop"], row["measure_periods"]),
        ):
            seg = exc.u[start:stop]
            assert (stop - start) * f / fs == pytest.approx(periods, abs=1e-9)
            spec = 2 * np.abs(np.fft.rfft(seg)) / seg.size
            assert spec[periods] == pytest.approx(amp, rel=1e-9)
            others = np.delete(spec, periods)
            assert np.max(others) < 1e-9 * amp
        assert exc.u[row["settle_start"]] == 0.0  # each step starts at phase 0: continuous signal


def test_stepped_sine_rejects_bad_input():
    with pytest.raises(ValueError, match="whole number"):
        ex.stepped_sine(1000.0, frequencies=[1.0], amplitudes=[1.0], measure_periods=2.5)
    with pytest.raises(ValueError, match="Nyquist"):
        ex.stepped_sine(1000.0, frequencies=[300.0], amplitudes=[1.0])
    with pytest.raises(ValueError, match="at least one"):
        ex.stepped_sine(1000.0, frequencies=[], amplitudes=[1.0])


# ---- modes and validation ---------------------------------------------------------------------------------


def test_modes_and_limits():
    exc = ex.quadratic_chirp(2.0, 1000.0, gain=3.0, a=0.5, mode="velocity")
    assert exc.protocol()["unit"] == "rad/s" and exc.protocol()["mode"] == "velocity"
    with pytest.raises(ValueError, match="exceeds the current-mode limit"):
        ex.quadratic_chirp(2.0, 1000.0, gain=3.0, a=0.5, limit=2.0)
    with pytest.raises(ValueError, match="exceeds the current-mode limit 50"):
        ex.stepped_sine(1000.0, frequencies=[1.0], amplitudes=[60.0])
    with pytest.raises(ValueError, match="mode must be one of"):
        ex.quadratic_chirp(2.0, 1000.0, gain=1.0, a=0.5, mode="torque")
    with pytest.raises(ValueError, match="Nyquist"):
        ex.random_enveloped(1.0, 100.0, amplitude=1.0, period=1.0, cutoff=50.0)
    with pytest.raises(ValueError, match="period must be"):
        ex.random_enveloped(1.0, 1000.0, amplitude=1.0, period=0.0)
    with pytest.raises(ValueError, match="fs must be"):
        ex.sweep(1.0, float("nan"), gain=1.0, f_start=1.0, f_stop=2.0)
