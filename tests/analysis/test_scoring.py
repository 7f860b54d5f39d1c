"""The one scoring function (analysis.scoring): a closed form, an oracle, continuity across a 70/30 split, and the
same figure from every door (identify, compare's maxwell_slip row, residual's start model) for the same model on
the same data, at 2, 10 and 20 kHz, on a 70/30 split and on two runs (issue #37)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.identification.chunked import array_chunks
from hilbench.analysis.identification.regressors import edge_samples
from hilbench.analysis.record import load_record
from hilbench.analysis.record_split import split
from hilbench.analysis.scoring import ScoreSettings, score, score_chunks
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import PlantParams, simulate
from tests.analysis.identification.test_identification import random_enveloped

J = 2e-3  # kg*m^2


def _inertia_run(fs: float, seconds: float, seed: int = 0):
    """A pure inertia driven by a held random torque (no friction): position exact, torque held (hold_next)."""
    n = int(seconds * fs)
    tau = random_enveloped(n, fs, seed, 0.05)
    out = simulate(PlantParams(inertia=J), tau, 1 / fs)
    return out.theta, tau


def test_a_known_sinusoidal_error_gives_its_rms():
    """The model J (the truth) scored on a torque with a sinusoid d = A sin(w t) added: the equation error is
    e = L[aligned d] (for a held torque on an inertia, D^2 x = T^2/J (h[k-1] + h[k])/2 exactly), and at 7 Hz the
    fs/20 = 100 Hz Butterworth passes it with |H|^2 = 1 - 6e-10, so rms(e) is the closed form
    rms_r(A cos(wT/2) sin(w (r - 1/2) T)) over the scored rows r, to the filter start-up transient
    (e^-10 = 5e-5 at the first rows): stated tolerance 1e-4 relative."""
    fs, a, f = 2000.0, 0.01, 7.0
    x, tau = _inertia_run(fs, 10.0)
    k = np.arange(x.size)
    w = 2 * np.pi * f / fs
    sc = score(PlantParams(inertia=J), x, tau + a * np.sin(w * k), fs, keep=True)
    rows = sc.rows
    expected = np.sqrt(np.mean((a * np.cos(w / 2) * np.sin(w * (rows - 0.5))) ** 2))
    got = sc.figures["torque_nrmse"] * np.std(sc.measured)
    assert got == pytest.approx(expected, rel=1e-4)
    assert sc.figures["torque_rel_pct"] == pytest.approx(100 * expected / np.sqrt(np.mean(sc.measured**2)), rel=1e-4)
    # the rows: every fs/(2.5 fs/20) = 8th sample from the filter's start-up length to as far from the end
    edge = edge_samples(fs, fs / 20)
    assert np.all(np.diff(rows) == 8) and rows[0] == edge and x.size - edge - 8 <= rows[-1] < x.size - edge


def test_the_true_model_simulates_the_measured_path():
    """Oracle: the plant that made a noise-free record, scored on it, simulates it back (segmented every 0.5 s from
    the measured state, whose velocity is the low-passed one: within 0.1 % of the path's spread) and its torque
    error is the filter's alone (below 0.5 %)."""
    fs = 2000.0
    p = dc_motor().replace(viscous=0.01)
    n = int(4 * fs)
    tau = random_enveloped(n, fs, 3, 6.0)
    out = simulate(p, tau / p.torque_constant, 1 / fs)
    truth = p.replace(torque_constant=1.0)
    f = score(truth, out.theta, tau, fs, settings=ScoreSettings(segment=0.5)).figures
    assert f["position_nrmse_segmented"] < 1e-3 and f["torque_nrmse"] < 5e-3
    wrong = score(truth.replace(ms_stiffness=tuple(0.5 * np.asarray(truth.ms_stiffness))), out.theta, tau, fs,
                  settings=ScoreSettings(segment=0.5)).figures
    assert wrong["torque_nrmse"] > 10 * f["torque_nrmse"]


def _measured_run(fs: float, seconds: float, seed: int):
    p = dc_motor().replace(viscous=0.01, counts_per_rev=2**20, seed=seed)
    n = int(seconds * fs)
    out = simulate(p, random_enveloped(n, fs, seed, 6.0), 1 / fs)
    return out.position_meas, p.torque_constant * out.current_meas, p


def test_a_held_out_tail_scores_as_the_same_span_inside_the_run():
    """Continuity: samples cut: of the whole run score alike read in chunks of any size (torque to 1e-9, the
    simulations to 1e-7: they amplify the windows' rounding); a tail started relaxed does not (the friction state
    matters: it reads several times the in-run figure on this run)."""
    fs = 2000.0
    x, tau, p = _measured_run(fs, 6.0, 1)
    model = p.replace(torque_constant=1.0)
    cut = int(round(0.7 * x.size))
    inside = score(model, x, tau, fs, timing="hold_previous", start=cut).figures
    chunked = score_chunks(model, array_chunks(x, tau, 777), fs, timing="hold_previous", start=cut, block=3000)
    for key, value in inside.items():
        # a simulation over a segment amplifies the 1e-13 rounding of the windows' filters (3e-9 measured)
        assert chunked.figures[key] == pytest.approx(value, rel=1e-7 if key.startswith("position") else 1e-9), key
    relaxed = score(model, x[cut:], tau[cut:], fs, timing="hold_previous").figures
    assert relaxed["torque_nrmse"] > 2 * inside["torque_nrmse"]


def test_identify_scores_a_split_tail_as_the_span_of_the_whole_run(runs):
    """Continuity through the front door: identify fitted on the head of a 70/30 split and validated on the tail
    reads the figures of the one scoring function on samples cut: of the whole run (to 1e-9)."""
    from hilbench.analysis.identification import analyse

    whole = load_record(runs[2000.0, 1])
    head, tail = split(whole, 0.3)
    res = analyse(head, validation=tail)
    got = score(res.model.plant_params(), whole.position, whole.torque, whole.sample_rate, timing=whole.timing,
                start=head.t.size).figures
    for key in ("torque_nrmse", "position_nrmse", "position_nrmse_segmented"):
        assert res.figures[f"validation_{key}"] == pytest.approx(got[key], rel=1e-9), key
    assert res.figures["validation_samples"] == tail.t.size == whole.t.size - head.t.size


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two 3 s runs (seeds 1 and 2) of the DC motor at each rate, as run files."""
    d = tmp_path_factory.mktemp("scoring")
    out = {}
    for fs in (2000.0, 10_000.0, 20_000.0):
        for seed in (1, 2):
            x, tau, _ = _measured_run(fs, 3.0, seed)
            path = d / f"{int(fs)}_{seed}.h5"
            with RunWriter(path, sample_rate=fs, channels=("sample_index", "t", "torque", "position")) as w:
                w.append({"sample_index": np.arange(x.size), "t": np.arange(x.size) / fs, "torque": tau,
                          "position": x})
            out[fs, seed] = path
    return out


DOOR_KEYS = ("validation_torque_nrmse", "validation_position_nrmse_segmented")


def _doors(train, validation) -> dict[str, dict[str, float]]:
    """The maxwell_slip model's validation figures through identify's, compare's and residual's front doors."""
    from hilbench.analysis.identification import analyse as identify
    from hilbench.analysis.models.compare import CompareSettings
    from hilbench.analysis.models.compare import analyse as compare
    from hilbench.analysis.residual import ResidualSettings
    from hilbench.analysis.residual import analyse as residual

    ident = identify(train, validation=validation)
    row = compare(train, validation, CompareSettings(families=("maxwell_slip",))).rows[0]
    res = residual(train, ResidualSettings(start=("maxwell_slip",), candidates=("offset",)), validation=[validation])
    np.testing.assert_allclose(row.plant.ms_slip, ident.model.plant_params().ms_slip, rtol=1e-12)  # one model
    return {"identify": {k: ident.figures[k] for k in DOOR_KEYS},
            "compare": {"validation_torque_nrmse": row.validation["torque_nrmse"],
                        "validation_position_nrmse_segmented": row.validation["position_nrmse_segmented"]},
            "residual start": {"validation_torque_nrmse": res.start_model["figures"]["validation_torque_nrmse"]}}


@pytest.mark.parametrize("fs", [2000.0, 10_000.0, 20_000.0])
@pytest.mark.parametrize("layout", ["70/30 split", "two runs"])
def test_one_model_one_figure_through_every_door(runs, fs, layout):
    if layout == "two runs":
        train, validation = load_record(runs[fs, 1]), load_record(runs[fs, 2])
    else:
        train, validation = split(load_record(runs[fs, 1]), 0.3)
    figures = _doors(train, validation)
    ref = figures["identify"]
    for door, got in figures.items():
        for key, value in got.items():
            assert value == pytest.approx(ref[key], rel=1e-6), (door, key)
    assert 0 < ref["validation_torque_nrmse"] < 0.1  # a real fit (7.5 % at 20 kHz: the 1 kHz low-pass passes noise)


def test_a_run_read_chunk_by_chunk_is_scored_in_memory_bounded_by_the_block():
    """score_chunks keeps running sums, not the run: on 1 000 000 samples generated chunk by chunk (16 MB as
    arrays), the peak of Python allocations stays under 12 MB (the windows of 16 384 samples and their filters;
    measured 6.5 MB), where keeping the rows and simulations (``keep``) takes 39 MB."""
    import tracemalloc

    import scipy.signal  # noqa: F401 (imported before the measurement: its import allocates 44 MB)

    fs, n, size = 10_000.0, 1_000_000, 50_000
    model = dc_motor().replace(torque_constant=1.0)

    def source():
        for k0 in range(0, n, size):
            t = np.arange(k0, min(n, k0 + size)) / fs
            yield 0.01 * np.sin(2 * np.pi * 1.5 * t), 0.3 * np.sin(2 * np.pi * 1.5 * t + 0.3)

    def peak(keep: bool) -> tuple[dict, float]:
        tracemalloc.start()
        try:
            figures = score_chunks(model, source, fs, n=n, keep=keep).figures
            return figures, tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    figures, bounded = peak(False)
    kept_figures, kept = peak(True)
    assert figures["samples"] == n and figures == kept_figures
    assert bounded < 12e6 < kept, f"peak {bounded / 1e6:.1f} MB, {kept / 1e6:.1f} MB with the arrays kept"


def test_the_model_input_chain_acts_on_the_measured_torque():
    """The input chain (offset, torque-constant error, delay) turns the measured torque into the one acting, as the
    plant does: a model with an offset c0 on tau + c0, with a gain error g on tau / (1 + g) and with a delay of 3
    samples on tau advanced by 3 samples make the error of the plain model on tau (the rows start far beyond the
    delay's first samples), so the NRMSE is the plain one, times (1 + g) for the gain (its reference std(L[tau])
    shrinks by 1 + g); to 1e-9 (the delay: the error itself, row by row)."""
    fs = 2000.0
    x, tau, p = _measured_run(fs, 3.0, 4)
    model = p.replace(torque_constant=1.0)
    plain = score(model, x, tau, fs).figures
    c0, g, d = 0.05, 0.1, 3
    offset = score(model.replace(torque_offset=-c0), x, tau + c0, fs).figures
    gain = score(model.replace(torque_constant_error=g), x, tau / (1 + g), fs).figures
    only = ScoreSettings(simulate=False)
    plain_rows = score(model, x, tau, fs, settings=only, keep=True)
    delayed = score(model.replace(delay_samples=d), x, np.append(tau[d:], tau[-d:]), fs, settings=only, keep=True)
    for key in ("torque_nrmse", "position_nrmse", "position_nrmse_segmented"):
        assert offset[key] == pytest.approx(plain[key], rel=1e-9), key
    assert gain["torque_nrmse"] == pytest.approx(plain["torque_nrmse"] * (1 + g), rel=1e-9)
    assert gain["position_nrmse_segmented"] == pytest.approx(plain["position_nrmse_segmented"], rel=1e-9)
    # the same error at every row (the acting torque differs only over the first 3 samples, zeros in the delay
    # line: their filtered trace at the first row, 86 samples on, is e^-10 of a torque step)
    e_plain = plain_rows.measured - plain_rows.predicted
    e_delayed = delayed.measured - delayed.predicted
    np.testing.assert_array_equal(delayed.rows, plain_rows.rows)
    assert np.max(np.abs(e_delayed - e_plain)) < 1e-4 * np.std(plain_rows.measured)
