"""Candidates cannot crash each other (issue 39).

A candidate bound to a model (``Term.bind``: the model's level force held with its fitted coefficients) keeps the
threshold grid that model was fitted on; the loop later fits it under other grids (the spring element, a
``local_presliding`` candidate's shortened grid). On a real displacement-driven tribometer record the
Maxwell-slip coefficients of a 40-threshold grid were applied to a 25-threshold one
(``ValueError: matmul ... size 25 is different from 41``).

Records from the second independent generator (tests/foreign/generator.py: Bouc-Wen friction, its own RK4).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import threshold_grid
from hilbench.analysis.residual import (
    DEFAULT_START,
    EMPS_START,
    REGISTRY,
    LoopOptions,
    family_start,
    prepare_run,
    residual_loop,
)
from hilbench.analysis.residual.candidates import CANDIDATE_NAMES
from hilbench.analysis.residual.design import Setting, fit_model, predict
from hilbench.analysis.residual.diagnostics import Signals, run_diagnostics
from hilbench.analysis.residual.selection import _setting_for, _with
from tests.foreign.generator import BoucWen, displacement_record, torque_record


def test_a_tribometer_record_with_a_level_along_the_travel_does_not_crash_the_loop():
    """The issue's record shape: force (N) against an imposed displacement (m), 100 reversals, split in halves,
    inertia 0, the default start. A friction level rising along the travel makes the loop keep
    position_dependent_friction on the 40-threshold grid, then try preload_variation on its shortened grid: on the
    old code that raised ``ValueError: matmul ... (size 30 is different from 40)``."""
    rec = displacement_record(1, BoucWen(coulomb=40.0, delta=0.08e-3, viscous=0.0, slope=1000.0))
    train, valid = (prepare_run(h.position, h.torque, h.fs, axis="linear", timing="instant", name=f"half-{i}")
                    for i, h in enumerate((rec.half(0), rec.half(1))))
    res = residual_loop(train, valid, start=DEFAULT_START,
                        options=LoopOptions(sim_window=None, record="displacement-driven", fixed_inertia=0.0))
    tried = {c["name"] for r in res.rounds for c in r["candidates"]}
    assert "preload_variation" in tried
    # the loop ran to its end and scored the final model on the held-out half
    assert res.error_after["validation"]["force_rel_pct"] <= res.error_before["validation"]["force_rel_pct"]


KINDS = ("rotary-torque", "linear-torque", "rotary-displacement", "linear-displacement")
STARTS = ("default", "emps", "coulomb_viscous", "stribeck", "maxwell_slip", "dahl", "lugre", "gms", "continuous")
GRIDS = (6, 17, 25, 40)


@cache
def _runs(kind: str):
    axis, drive = kind.split("-")
    law = BoucWen(eccentric=(0.2, 0.4)) if axis == "rotary" else BoucWen(slope=0.1)
    out = []
    for seed in (1, 2):
        if drive == "torque":
            r = torque_record(seed, law, stroke=1.5, duration=2.0, substeps=4, axis=axis)
            out.append(prepare_run(r.position, r.torque, r.fs, axis=axis, timing="hold_next", name=f"{kind}-{seed}"))
        else:
            r = displacement_record(seed, BoucWen(coulomb=40.0, delta=0.08e-3, viscous=50.0, slope=800.0),
                                    duration=20.0, reversals=20, substeps=2)
            out.append(prepare_run(r.position, r.torque, r.fs, axis=axis, timing="instant", name=f"{kind}-{seed}"))
    return tuple(out)


@cache
def _start(kind: str, name: str) -> tuple:
    train = list(_runs(kind)[:1])
    entries = {"default": list(DEFAULT_START), "emps": list(EMPS_START)}.get(name)
    if entries is None:
        try:
            entries = family_start(name, train, output_error=False)
        except AnalysisError:  # a family its identification refuses on this record (one clear line): no start
            return ()
    return tuple((e, {}) if isinstance(e, str) else (e[0], dict(e[1])) for e in entries)


def _settings(term, train, diags) -> list[dict]:
    out = term.settings(train, diags)
    if not out and term.name.startswith("position_"):
        out = [{"wavenumbers": [1.0, 3.0]}]  # no spectrum line: the columns still exist
    return out


def _add(model, name, train, diags, setting):
    """``model`` plus candidate ``name`` at its first setting, bound to ``model`` fitted under ``setting``; None
    when the candidate does not apply to this model."""
    term = REGISTRY[name]
    if name in {t.name for t, _ in model} or name in {r for t, _ in model for r in t.replaces}:
        return None
    cur = _setting_for(model, setting)
    if term.applicable(cur, [t.name for t, _ in model]) or term.unfit_reason(train):
        return None
    nls = _settings(term, train, diags)
    if not nls:
        return None
    nl = nls[len(nls) // 2]
    if term.needs_fit:
        nl = term.bind(nl, model, fit_model(model, train, cur, covariance=False))
    return _with(model, term, nl)


@settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(kind=st.sampled_from(KINDS), start=st.sampled_from(STARTS), grids=st.tuples(*[st.sampled_from(GRIDS)] * 3),
       order=st.permutations(CANDIDATE_NAMES))
def test_every_candidate_on_every_start_under_any_grid_raises_nothing(kind, start, grids, order):
    """Every candidate is added to the start model bound on grid A, the model refitted and predicted under grid B;
    then a second candidate is bound to that model and the pair refitted under grid C. Nothing may raise (a
    candidate that does not apply is skipped, as the loop skips it)."""
    runs = _runs(kind)
    train, valid = [runs[0]], [runs[1]]
    drive = kind.split("-")[1]
    inertia = 0.0 if drive == "displacement" else None
    entries = _start(kind, start)
    assume(entries)
    base = [(REGISTRY[n], dict(nl)) for n, nl in entries]
    diags = run_diagnostics(Signals.from_runs(train, fit_model(
        base, train, Setting(inertia, threshold_grid(train[0].position, 40))).residual), 0.01, 0.01)
    sa, sb, sc = (Setting(inertia, threshold_grid(train[0].position, n)) for n in grids)
    for first in order:
        m1 = _add(base, first, train, diags, sa)
        if m1 is None:
            continue
        f1 = fit_model(m1, train, _setting_for(m1, sb))
        y, e = predict(f1, valid)
        assert np.all(np.isfinite(e)) and e.shape == y.shape
        for t, nl in m1:
            t.parameters(f1, nl, train[0].axis)
        second = next((n for n in order if n != first and _add(m1, n, train, diags, sb) is not None), None)
        if second is None:
            continue
        m2 = _add(m1, second, train, diags, sb)
        f2 = fit_model(m2, train, _setting_for(m2, sc))
        y, e = predict(f2, valid)
        assert np.all(np.isfinite(e))
        for t, nl in m2:
            t.parameters(f2, nl, train[0].axis)


@pytest.mark.parametrize("kind", KINDS)
def test_the_loop_runs_on_every_record_kind_with_a_small_grid(kind):
    """The whole loop, a 17-threshold grid (the local grid and the spring element then differ in size from it)."""
    runs = _runs(kind)
    disp = kind.endswith("displacement")
    res = residual_loop(runs[0], runs[1], start=DEFAULT_START, options=LoopOptions(
        sim_window=None, n_thresholds=17, record="displacement-driven" if disp else "torque-driven"))
    assert res.error_after["validation"]["torque_rel_pct"] >= 0
