"""Plots of the studies (matplotlib, Agg backend, imported only when a plot is written).

The format follows the file's extension: png, svg or pdf. :func:`check_plot_path` validates a path
before a study runs, so a bad path costs nothing.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..base.bounds import check_output_path
from ..base.files import atomic_path, check_target

FORMATS = ("png", "svg", "pdf")


def check_plot_path(path, force: bool = False) -> Path:
    """The plot path, after checking its extension and that it can be written (`rkhp.base.bounds`;
    an existing file or a link only with ``force``, `rkhp.base.files`)."""
    return check_target(check_output_path(path, tuple("." + f for f in FORMATS), "plot file"), "plot file", force)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, force: bool) -> None:
    """Write the figure atomically (`rkhp.base.files`: an existing file only with ``force``)."""
    try:
        with atomic_path(path, "plot file", force) as tmp:
            fig.savefig(tmp, format=path.suffix.lower().lstrip("."), bbox_inches="tight")
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def plot_convergence(study, path, force: bool = False) -> Path:
    """Log-log global error against h, one line per method, with dashed reference slopes h^p
    for each expected order p, and the reference's accuracy floor."""
    path = check_plot_path(path, force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    for m in study.methods:
        pts = [(r.h, r.error) for r in m.rows if r.error is not None]
        if not pts:
            continue
        hs, es = zip(*pts, strict=True)
        obs = "n/a" if m.observed_order is None else f"{m.observed_order:.2f}"
        line, = ax.loglog(hs, es, "o-", label=f"{m.method} (observed {obs}, expected {m.expected_order})")
        fit = [(m.rows[i].h, m.rows[i].error) for i in m.fit.fit_rows]
        if fit:
            h0, e0 = fit[-1]
            hmax = max(hs)
            ax.loglog([h0, hmax], [e0, e0 * (hmax / h0) ** m.expected_order], "--", color=line.get_color(),
                      alpha=0.5, linewidth=1)
    floor = study.reference.floor
    ax.axhline(floor, color="grey", linestyle=":", linewidth=1, label=f"reference accuracy x10 ({floor:.1e})")
    ax.set_xlabel("step size h")
    ax.set_ylabel(f"global error at T = {study.t_final:g}")
    ax.set_title(f"{study.system} ({study.realisation} realisation); dashed: slope = expected order", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, path, force)
    return path


def plot_work_precision(bench, path, force: bool = False) -> Path:
    """Log-log wall time (median) against error at T, one line per method or peer."""
    path = check_plot_path(path, force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    for curve in bench.curves:
        pts = [(p.error, p.seconds) for p in curve.points if p.error is not None and p.seconds > 0]
        if pts:
            es, ts = zip(*pts, strict=True)
            ax.loglog(es, ts, "o-" if curve.kind != "scipy" else "s--", label=f"{curve.method} ({curve.kind})")
    for target in bench.targets:
        ax.axvline(target, color="grey", linestyle=":", linewidth=0.8)
    ax.set_xlabel(f"global error at T = {bench.t_final:g}")
    ax.set_ylabel("wall time, median of repeats [s]")
    ax.set_title(f"work-precision, {bench.system} ({bench.realisation} realisation)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.invert_xaxis()
    ax.legend(fontsize=7)
    _save(fig, path, force)
    return path


def plot_stress(stress, path, force: bool = False) -> Path:
    """Casimir and energy drift per window of the long run (part b), log scale; the classical
    RK4 peer dashed."""
    path = check_plot_path(path, force)
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for run in (*stress.long_run.runs, stress.long_run.peer):
        x = range(1, len(run.casimir_windows) + 1)
        style = "s--" if run is stress.long_run.peer else "o-"
        axes[0].semilogy(x, [max(v, 1e-17) for v in run.casimir_windows], style, label=run.method)
        axes[1].semilogy(x, [max(v, 1e-17) for v in run.energy_windows], style, label=run.method)
    for ax, what in zip(axes, ("Casimir", "energy"), strict=True):
        ax.set_xlabel(f"window (of {stress.long_run.windows}, {stress.long_run.steps} steps in all)")
        ax.set_ylabel(f"max {what} error in window")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"long run, {stress.system}, h = {stress.long_run.h:g}", fontsize=9)
    _save(fig, path, force)
    return path


def plot_phase(tableaux, realisation: str, z_max: float, path, force: bool = False) -> Path:
    """theta(z) (with the exact flow's z, wrapped to (-pi, pi]) and |theta(z) - z| on a log scale,
    one line per method, over 0 < z <= z_max (docs/stability.md)."""
    import numpy as np

    from ..tableaux.stability import rotation_angle

    path = check_plot_path(path, force)
    plt = _pyplot()
    zs = np.linspace(z_max / 400, z_max, 400)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 7.2), sharex=True)
    top.plot(zs, [math.remainder(z, 2 * math.pi) for z in zs], "k:", label="exact flow (z mod 2 pi)")
    for t in tableaux:
        theta = np.array([np.nan if (v := rotation_angle(t, float(z), realisation)) is None else v for z in zs])
        line, = top.plot(zs, theta, label=t.name)
        with np.errstate(invalid="ignore"):
            bottom.semilogy(zs, np.abs(theta - zs), color=line.get_color(), label=t.name)
    top.set_ylabel("theta(z), rotation per step")
    top.set_title(f"phase of RKHP steps on the harmonic oscillator ({realisation} realisation)", fontsize=9)
    bottom.set_ylabel("|theta(z) - z|")
    bottom.set_xlabel("z = h omega")
    for ax in (top, bottom):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    _save(fig, path, force)
    return path


def plot_long_time(system: str, runs, path, force: bool = False) -> Path:
    """Log-log running maximum of |H(y_n) - H(y_0)| against t, one line per method, with its fitted
    exponent (rkhp.studies.longtime)."""
    path = check_plot_path(path, force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    for r in runs:
        if not r.times:
            continue
        k = "n/a" if r.exponent is None else f"{r.exponent:.2f}"
        ax.loglog(r.times, [max(e, 1e-17) for e in r.errors], label=f"{r.method} (growth t^{k})")
    ax.set_xlabel("t")
    ax.set_ylabel("max over [0, t] of |H(y_n) - H(y_0)|")
    ax.set_title(f"{system}: long-time energy error", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, path, force)
    return path
