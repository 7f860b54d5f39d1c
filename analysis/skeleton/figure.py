"""The skeleton curves' figure (``hilbench skeleton --plot``, the registry entry's report)."""

from __future__ import annotations


def skeleton_figure(curves, names: list[str], pos: str, trq: str):
    """Restoring force against displacement amplitude and damping force against velocity amplitude: each run's
    instantaneous points (small dots, one colour per run) under the composed curve (black), broken where bins are
    missing (a gap between the runs' amplitude ranges is not bridged). Small values in mrad, mN*m; the legend
    below the axes; a log amplitude axis labelled at 1-2-5 only (no minor labels running into each other)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from hilbench.analysis.figure_style import engineering, plain_numbers, with_gaps

    fa, au = engineering(pos, curves.points_amplitude)
    fv, vu = engineering(f"{pos}/s", curves.points_velocity)
    fk, ku = engineering(trq, np.r_[curves.points_restoring_force, curves.points_damping_force])
    fig = Figure(figsize=(11, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 2)
    handles = []
    for i in np.unique(curves.points_run):
        m = curves.points_run == i
        dots = ax[0].plot(fa * curves.points_amplitude[m], fk * curves.points_restoring_force[m], ".", ms=1.5,
                          alpha=0.5, rasterized=True)
        ax[1].plot(fv * curves.points_velocity[m], fk * curves.points_damping_force[m], ".", ms=1.5, alpha=0.5,
                   color=dots[0].get_color(), rasterized=True)
        handles.append(Line2D([], [], ls="none", marker="o", ms=5, color=dots[0].get_color(), label=names[i]))
    a, f = with_gaps(curves.amplitude, curves.restoring_force)
    ax[0].plot(fa * a, fk * f, "ko-", ms=3, lw=1)
    v, d = with_gaps(curves.velocity, curves.damping_force)
    ax[1].plot(fv * v, fk * d, "ko-", ms=3, lw=1)
    handles.append(Line2D([], [], color="k", marker="o", ms=4, lw=1, label="composed (bin medians; gaps: no data)"))
    span = fa * curves.points_amplitude[curves.points_amplitude > 0]
    if span.size and span.max() > 3 * span.min():  # a log axis only over a range worth one
        ax[0].set_xscale("log")
        ax[0].xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax[0].xaxis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
        ax[0].xaxis.set_minor_formatter(NullFormatter())
    ax[0].set_xlabel(f"displacement amplitude A ({au})")
    ax[0].set_ylabel(f"restoring force k_eq*A ({ku})")
    ax[1].set_xlabel(f"velocity amplitude V ({vu})")
    ax[1].set_ylabel(f"damping force c_eq*V ({ku})")
    ax[0].set_title("restoring force skeleton", fontsize=10)
    ax[1].set_title("damping force skeleton", fontsize=10)
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.tick_params(labelsize=9)
        plain_numbers(a)
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=min(4, len(handles)), frameon=False)
    shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
    fig.suptitle(f"ForceVib skeleton curves of {len(names)} run{'s' if len(names) != 1 else ''}: {shown}")
    return fig
