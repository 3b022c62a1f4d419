"""Plots of the studies (matplotlib, Agg backend, imported only when a plot is written).

The format follows the file's extension: png, svg or pdf. :func:`check_plot_path` validates a path
before a study runs, so a bad path costs nothing. Beside each plot, the same name with the suffix
``.csv`` holds the data of every curve drawn (columns panel, curve, x, y; rkhp.base.tables), with
the provenance record of the run (rkhp.base.provenance).
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

from ..base.bounds import check_output_path
from ..base.files import check_target
from ..base.provenance import provenance, write_output
from ..base.tables import csv_text

#: the columns of a plot's data file
DATA_COLUMNS = ("panel", "curve", "x", "y")

FORMATS = ("png", "svg", "pdf")


def check_plot_path(path, what: str = "plot file", force: bool = False) -> Path:
    """The plot path, after checking its extension and that it and its data file
    (:func:`data_path`) can be written (`rkhp.base.bounds`; an existing file or a link only with
    ``force``, `rkhp.base.files`); ``what`` names it in messages."""
    path = check_target(check_output_path(path, tuple("." + f for f in FORMATS), what), what, force)
    data_what = f"{what} (its data file)"
    check_target(check_output_path(data_path(path), (".csv",), data_what), data_what, force)
    return path


def data_path(path) -> Path:
    """The data file beside a plot: the same name with the suffix .csv."""
    return Path(path).with_suffix(".csv")


def _points(panel: str, curve: str, xs, ys) -> list[tuple]:
    return [(panel, curve, float(x), float(y)) for x, y in zip(xs, ys, strict=True)]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, rows, record: dict | None, force: bool) -> None:
    """Write the figure and, beside it, its data (``rows`` of :data:`DATA_COLUMNS`), both with the
    provenance ``record`` (default: this process's), atomically (an existing file only with
    ``force``, rkhp.base.provenance.write_output)."""
    record = provenance() if record is None else record
    fmt = path.suffix.lower().lstrip(".")
    # matplotlib's metadata keys per format: the record as the file's description
    key = {"png": "Description", "svg": "Description", "pdf": "Subject"}[fmt]
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format=fmt, bbox_inches="tight", metadata={key: json.dumps(record)})
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
    write_output(path, buffer.getvalue(), "plot file", force)
    write_output(data_path(path), csv_text(DATA_COLUMNS, rows, record), "plot data file", force)


#: the slope lines are drawn over the data (matplotlib draws lines at zorder 2)
SLOPE_ZORDER = 3
#: tick values of a log axis spanning under two decades: m 10^k for these m, labels a factor
#: MIN_TICK_RATIO apart at least
NICE_MANTISSAS = (1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0)
MIN_TICK_RATIO = 1.2


def _readable_log_ticks(axis, lo: float, hi: float) -> None:
    """Labels of a log axis over [lo, hi] that never overlap: within two decades, the values
    m 10^k (NICE_MANTISSAS) inside the range, each MIN_TICK_RATIO above the one before, written
    as plain numbers (%g), and no minor labels (matplotlib labels every minor tick of a narrow
    range, 3x10^-1 beside 3.2x10^-1); wider ranges keep matplotlib's decades."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    if not (0 < lo < hi) or hi / lo >= 100:
        return
    ticks = []
    for k in range(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1):
        for m in NICE_MANTISSAS:
            v = float(f"{m * 10.0 ** k:.12g}")
            if lo <= v <= hi and (not ticks or v >= MIN_TICK_RATIO * ticks[-1]):
                ticks.append(v)
    if not ticks:
        return
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def plot_convergence(study, path, record: dict | None = None, force: bool = False) -> Path:
    """Log-log global error against h, one line per method, with dashed reference slopes h^p
    for each expected order p, and the reference's accuracy floor."""
    path = check_plot_path(path, force=force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    panel = "global error at T against h"
    rows = []
    for m in study.methods:
        pts = [(r.h, r.error) for r in m.rows if r.error is not None]
        if not pts:
            continue
        hs, es = zip(*pts, strict=True)
        obs = "n/a" if m.observed_order is None else f"{m.observed_order:.2f}"
        line, = ax.loglog(hs, es, "o-", label=f"{m.method} (observed {obs}, expected {m.expected_order})")
        rows += _points(panel, m.method, hs, es)
        fit = [(m.rows[i].h, m.rows[i].error) for i in m.fit.fit_rows]
        if fit:
            h0, e0 = fit[-1]
            hmax = max(hs)
            slope = ([h0, hmax], [e0, e0 * (hmax / h0) ** m.expected_order])
            ax.loglog(*slope, "--", color=line.get_color(), alpha=0.8, linewidth=1, zorder=SLOPE_ZORDER)
            rows += _points(panel, f"{m.method} slope {m.expected_order}", *slope)
    floor = study.reference.floor
    ax.axhline(floor, color="grey", linestyle=":", linewidth=1, label=f"reference accuracy x10 ({floor:.1e})")
    rows += _points(panel, "reference accuracy x10", [min(r.h for m in study.methods for r in m.rows)] * 2,
                    [floor, floor])
    all_h = [r.h for m in study.methods for r in m.rows]
    _readable_log_ticks(ax.xaxis, min(all_h), max(all_h))
    ax.set_xlabel("step size h")
    ax.set_ylabel(f"global error at T = {study.t_final:g}")
    ax.set_title(f"{study.system} ({study.realisation} realisation); dashed: slope = expected order", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, path, rows, record, force)
    return path


def plot_work_precision(bench, path, record: dict | None = None, force: bool = False) -> Path:
    """Log-log wall time (median) against error at T, one line per method or peer."""
    path = check_plot_path(path, force=force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    rows = []
    for curve in bench.curves:
        pts = [(p.error, p.seconds) for p in curve.points if p.error is not None and p.seconds > 0]
        if pts:
            es, ts = zip(*pts, strict=True)
            ax.loglog(es, ts, "o-" if curve.kind != "scipy" else "s--", label=f"{curve.method} ({curve.kind})")
            rows += _points("wall time against error at T", curve.method, es, ts)
    for target in bench.targets:
        ax.axvline(target, color="grey", linestyle=":", linewidth=0.8)
    ax.set_xlabel(f"global error at T = {bench.t_final:g}")
    ax.set_ylabel("wall time, median of repeats [s]")
    ax.set_title(f"work-precision, {bench.system} ({bench.realisation} realisation)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.invert_xaxis()
    ax.legend(fontsize=7)
    _save(fig, path, rows, record, force)
    return path


def plot_stress(stress, path, record: dict | None = None, force: bool = False) -> Path:
    """Casimir and energy drift per window of the long run (part b), log scale; the classical
    RK4 peer dashed."""
    path = check_plot_path(path, force=force)
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    rows = []
    for run in (*stress.long_run.runs, stress.long_run.peer):
        style = "s--" if run is stress.long_run.peer else "o-"
        for ax, what, values in ((axes[0], "Casimir", run.casimir_windows), (axes[1], "energy", run.energy_windows)):
            if values:  # a system without a Casimir (or a run that failed at once) has no windows
                x = range(1, len(values) + 1)
                ax.semilogy(x, [max(v, 1e-17) for v in values], style, label=run.method)
                rows += _points(f"max {what} error per window", run.method, x, values)
    for ax, what in zip(axes, ("Casimir", "energy"), strict=True):
        ax.set_xlabel(f"window (of {stress.long_run.windows}, {stress.long_run.steps} steps in all)")
        ax.set_ylabel(f"max {what} error in window")
        ax.grid(True, which="both", alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, f"no {what} data", transform=ax.transAxes, ha="center")
    fig.suptitle(f"long run, {stress.system}, h = {stress.long_run.h:g}", fontsize=9)
    _save(fig, path, rows, record, force)
    return path


def plot_phase(tableaux, realisation: str, z_max: float, path, record: dict | None = None,
               force: bool = False) -> Path:
    """theta(z) (with the exact flow's z, wrapped to (-pi, pi]) and |theta(z) - z| on a log scale,
    one line per method, over 0 < z <= z_max (docs/stability.md); the data beside it."""
    import numpy as np

    from ..tableaux.stability import rotation_angles

    path = check_plot_path(path, force=force)
    plt = _pyplot()
    zs = np.linspace(z_max / 400, z_max, 400)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 7.2), sharex=True)
    exact = [math.remainder(z, 2 * math.pi) for z in zs]
    top.plot(zs, exact, "k:", label="exact flow (z mod 2 pi)")
    rows = _points("theta(z)", "exact flow", zs, exact)
    for t in tableaux:
        theta = np.array([np.nan if v is None else v for v in rotation_angles(t, [float(z) for z in zs], realisation)])
        line, = top.plot(zs, theta, label=t.name)
        with np.errstate(invalid="ignore"):
            bottom.semilogy(zs, np.abs(theta - zs), color=line.get_color(), label=t.name)
        rows += _points("theta(z)", t.name, zs, theta) + _points("|theta(z) - z|", t.name, zs, np.abs(theta - zs))
    top.set_ylabel("theta(z), rotation per step")
    top.set_title(f"phase of RKHP steps on the harmonic oscillator ({realisation} realisation)", fontsize=9)
    bottom.set_ylabel("|theta(z) - z|")
    bottom.set_xlabel("z = h omega")
    for ax in (top, bottom):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    _save(fig, path, rows, record, force)
    return path


def plot_long_time(system: str, runs, path, record: dict | None = None, force: bool = False) -> Path:
    """Log-log running maximum of |H(y_n) - H(y_0)| against t, one line per method, with its fitted
    exponent (rkhp.studies.longtime); the data beside it."""
    path = check_plot_path(path, force=force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    rows = []
    for r in runs:
        if not r.times:
            continue
        k = "n/a" if r.exponent is None else f"{r.exponent:.2f}"
        ax.loglog(r.times, [max(e, 1e-17) for e in r.errors], label=f"{r.method} (growth t^{k})")
        rows += _points("max |H(y_n) - H(y_0)| against t", r.method, r.times, r.errors)
    ax.set_xlabel("t")
    ax.set_ylabel("max over [0, t] of |H(y_n) - H(y_0)|")
    ax.set_title(f"{system}: long-time energy error", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, path, rows, record, force)
    return path


def plot_section(section, axes: tuple[int, int], path, record: dict | None = None, force: bool = False) -> Path:
    """The points of a Poincaré section (rkhp.ivp.poincare) in the plane of two coordinates;
    the data beside it."""
    path = check_plot_path(path, force=force)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.6, 5.6))
    i, j = axes
    xs, ys = section.points[:, i], section.points[:, j]
    ax.plot(xs, ys, ".", markersize=2)
    ax.set_xlabel(f"x{i + 1}")
    ax.set_ylabel(f"x{j + 1}")
    r = section.result
    ax.set_title(f"{r.system}: section {section.expression} = 0 ({section.direction}), {len(xs)} points, "
                 f"{r.method}", fontsize=9)
    ax.grid(True, alpha=0.3)
    _save(fig, path, _points("section", f"x{j + 1} against x{i + 1}", xs, ys), record, force)
    return path
