"""The residual loop: what does a fitted friction model get wrong, and which physical effect is it?

    from hilbench.analysis.residual import prepare_run, residual_loop
    result = residual_loop(prepare_run(x, tau, fs), validation=prepare_run(x2, tau2, fs))
    result.to_dict()   # the JSON report (docs/residual-report.md)

    from hilbench.analysis.residual import ResidualSettings, analyse, read, report
    res = analyse(read("run.h5"), ResidualSettings(), validation=[read("run2.h5")])   # a record in, as the CLI
    report(res, "out")                                                                  # the figures and summary

Modules: ``rundata`` (filtered rows of a run), ``design`` (joint bounded least squares),
``candidates`` (the registry of model terms), ``diagnostics`` (statistics and tests on a residual),
``selection`` (the loop), ``simulation_error`` (windowed simulation with the C plant), ``report``
(JSON, PNG figures and a Markdown summary), ``runs`` (reading run files with h5py).
"""

from hilbench.analysis.residual.candidates import REGISTRY, Term, get_term, register
from hilbench.analysis.residual.family_start import family_start
from hilbench.analysis.residual.record_analysis import ResidualAnalysis, ResidualSettings, analyse, read, report
from hilbench.analysis.residual.rundata import RunData, prepare_run
from hilbench.analysis.residual.selection import (
    DEFAULT_START,
    EMPS_START,
    NO_EFFECT,
    LoopOptions,
    LoopResult,
    residual_loop,
)

__all__ = ["DEFAULT_START", "EMPS_START", "NO_EFFECT", "REGISTRY", "LoopOptions", "LoopResult", "ResidualAnalysis",
           "ResidualSettings", "RunData", "Term", "analyse", "family_start", "get_term", "prepare_run", "read",
           "register", "report", "residual_loop"]
