"""Cost of one RKHP Euler substep by each substep provider that takes it: the direct forms
(rkhp.integrators.closed_euler, rkhp.integrators.spray_euler) against the Taylor tower
(rkhp.integrators.tower_substep), each run by the driver's compiled loop (prints measured
figures; run: python benchmarks/substeps.py).

Cases: RKHP Euler and the triple jump tj4 of it on the rigid body (lie-poisson, so(3)*),
Lotka–Volterra (log-canonical) and the periodic Toda lattice of size 12 (lie-poisson, n = 12),
whose direct form is the closed one; on the planar charged particle, the Nambu system and the Toda
lattice of size 12 built in the general family (`as_general`: the spray realisation of a linear
pi), whose direct form is the spray's. For each: microseconds per Euler substep (the compiled
loop's own time divided by steps x substeps), warm (compiled before timing), the providers
alternating, minima over REPEATS runs; iterations per substep (chord iterations and fixed-point sweeps of a direct form,
Newton iterations of the tower); and the largest difference of the two trajectories over the
tower's steps, relative to the largest |y|.

Second table, the race's settings (the composition and steps with which rkhp reaches 1e-10 at
T = 10 in docs/results/work-precision.md; kahan-li8 at h = 0.25 on the heavy top and the pendulum,
which that page does not race): per substep, microseconds, iterations, fixed-point sweeps (of the
substeps without previous solutions), Jacobians (chord matrices or Newton's), and an estimate of
the floating-point operations the substep ran
(`flops`: per iteration the point x(z) and y1, H's gradient (its compiled code's operations, or
forward mode on the tape) and the linear solve; per sweep the point and the gradient;
per Jacobian its assembly and factorisation) and of those the mathematics needs (`limit`: two
iterations and the closing point, with one Jacobian (Newton's method) or the chord matrices the
run built where it built fewer), with the rate the run achieved (flops / time).

Third table, the spray's direct form at the race's settings of the general family (as the second
table's): the spec file benchmarks/data/vortices-8.toml (four point vortices, n = 8, a non-affine
pi) with the kernel of bcm8-s13 at h = 10/609, and the charged particle with bcm6-s11's at
h = 10/45: per substep,
microseconds, chord iterations, fixed-point sweeps, refreshes of the chord matrix, the
collocation nodes Q, and estimates of the operations run and of those the mathematics needs
(`compiled_spray_flops`, the model of `rkhp.integrators.spray_euler.spray_flops`: per iteration
the stages' field, the gradient and the product with the inverse; per sweep the field and the
gradient; per matrix its derivatives,
assembly and inversion; `limit`: the equations evaluated twice a substep (two sweeps, the
cheapest evaluation the form has), the matrices as the run built them (a matrix built at every
substep costs more than the iterations it saves: Newton's method is no limit here), and the
substep's start and close), with the rate achieved.

Timed: `rkhp.integrators.driver.drive` called directly with its arguments built once (no Python
in the timed call), in CPU seconds of the calling thread (`time.thread_time`: on a shared machine
the time the other work takes from it is not counted; the minimum is then the fairer figure).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rkhp.integrators.driver import drive, record, run, setup
from rkhp.integrators.substeps import TOWER, choose
from rkhp.systems import get_system
from rkhp.systems.problems import as_general
from rkhp.tableaux.compositions import load_composition
from rkhp.tableaux.files import load_tableau

REPEATS = 7
CASES = (("rigid-body", "tj4", 0.1, 2000, 500), ("lotka-volterra", "tj4", 0.1, 2000, 500),
         ("toda:12", "tj4", 0.05, 1000, 50), ("charged-particle", "euler", 0.1, 2000, 100),
         ("nambu", "euler", 0.1, 2000, 100), ("toda:12 (general)", "euler", 0.1, 200, 10))
"""(system, method, h, steps of the direct form, steps of the tower) per case."""


def system_of(label: str):
    name = label.split()[0]
    return as_general(name) if label.endswith("(general)") else get_system(name)


def loop(system, provider, gammas, h: float, steps: int):
    """A call of the driver's compiled loop over `provider`'s substeps, its arguments built once."""
    ready = setup(system, load_tableau("euler"), gammas, provider=provider)  # None: the table's
    y0, out = np.array(system.x0), record(steps, system.dim, True)
    return lambda: drive(y0, ready.gammas, 0, h, steps, ready.data, ready.solver, out)


def seconds(call) -> float:
    """CPU seconds of this thread spent in one call."""
    t0 = time.thread_time()
    call()
    return time.thread_time() - t0


def measure(label: str, method: str, h: float, direct_steps: int, tower_steps: int) -> dict:
    system = system_of(label)
    gammas = (1.0,) if method == "euler" else load_composition(method).gamma_float
    s = len(gammas)
    euler = load_tableau("euler")
    direct = choose(system, euler).provider
    calls = {"direct": loop(system, direct, gammas, h, direct_steps),
             "tower": loop(system, TOWER, gammas, h, tower_steps)}
    times = {key: [] for key in calls}
    for call in calls.values():
        call()  # compile (or load the cache)
    for _ in range(REPEATS):
        for key, call in calls.items():
            times[key].append(seconds(call))
    fast = run(system, euler, h, direct_steps, gammas=gammas, provider=direct)
    slow = run(system, euler, h, tower_steps, gammas=gammas, provider=TOWER)
    gap = np.abs(fast.states[: tower_steps + 1] - slow.states).max() / np.abs(slow.states).max()
    return {
        "provider": direct.name,
        "direct_us": 1e6 * min(times["direct"]) / (direct_steps * s),
        "tower_us": 1e6 * min(times["tower"]) / (tower_steps * s),
        "iterations": float(np.mean(fast.newton_iterations)) / s,
        "sweeps": float(np.mean(fast.stage_sweeps)) / s,
        "tower_iterations": float(np.mean(slow.newton_iterations)) / s,
        "gap": float(gap),
    }


RACE = (("rigid-body", "bcm8-s13", 27), ("lotka-volterra", "bcm8-s13", 108), ("toda:12", "bcm8-s13", 54),
        ("heavy-top", "kahan-li8", 40), ("pendulum", "kahan-li8", 40))
"""(system, composition, steps over T = 10) of the second table: closed direct forms."""


def closed_flops(system, form, n: int) -> dict:
    """Flop estimates of the closed direct form's parts on `form` (see the module): H's gradient
    and Hessian by the operations of their compiled code (`rkhp.systems.field_code.
    derivatives_code`) where the form has them, else by forward mode on the tape and differences
    of the gradient (the chord matrix's Hessian)."""
    from rkhp.integrators import closed_euler
    from rkhp.systems.field_code import derivatives_code

    ops = form.hamiltonian.ops.shape[0]
    forward = 2 * ops * (n + 1) + 2 * n  # a gradient by forward mode on the tape
    gradient = derivatives_code(system, False).operations if form.derivatives_at else forward
    hessian = derivatives_code(system, True).operations if form.derivatives_at and form.exact else 2 * n * forward
    if form.kind == closed_euler.LIE_POISSON and form.rotation:
        point = 70 if n == 3 else 190  # Rodrigues' forms; on se(3)* with their derivative along r
    elif form.kind == closed_euler.LIE_POISSON and form.diagonal.size:
        columns = int(np.count_nonzero(form.diagonal >= 0))
        point = 2 * len(form.coefs) + 40 * columns + 4 * (len(form.pairs) - columns) + 2 * n  # an exponential a column
    elif form.kind == closed_euler.LIE_POISSON:
        point = 12 * (4 * len(form.coefs) + 6 * n)  # about 12 terms of two series (|K| about 0.1)
    else:
        point = 2 * n * n + (40 * n if form.kind == closed_euler.LOG_CANONICAL else 2 * n)
    solve = 2 * n * n + (6 * n * n if not form.exact else 0)  # the chord path's Broyden update
    jacobian = 2 * n**3 + (2 * n**3 // 3) + 2 * n**3 + (0 if form.hessian_constant else hessian)
    return {"iteration": point + gradient + solve, "sweep": point + gradient, "jacobian": jacobian, "point": point}


def race(name: str, composition: str, steps: int) -> dict:
    """Time, iterations, Jacobians and flops per substep of a composition by its direct form."""
    system = get_system(name)
    gammas = load_composition(composition).gamma_float
    h, s = system.t_final / steps, len(gammas)
    call = loop(system, None, gammas, h, steps)
    call()
    best = min(seconds(call) for _ in range(REPEATS))
    trajectory = run(system, load_tableau("euler"), h, steps, gammas=gammas)
    substeps = steps * s
    iterations = float(np.sum(trajectory.newton_iterations)) / substeps
    sweeps = float(np.sum(trajectory.stage_sweeps)) / substeps
    jacobians = float(np.sum(trajectory.extra["refreshes"])) / substeps
    parts = closed_flops(system, setup(system, load_tableau("euler"), gammas).data.form, system.dim)
    flops = iterations * parts["iteration"] + sweeps * parts["sweep"] + jacobians * parts["jacobian"] + parts["point"]
    limit = 2 * parts["iteration"] + min(1.0, jacobians) * parts["jacobian"] + parts["point"]
    us = 1e6 * best / substeps
    return {"us": us, "iterations": iterations, "sweeps": sweeps, "jacobians": jacobians, "flops": flops,
            "limit": limit, "rate": flops / us / 1e3, "h": h}


SPRAY_RACE = (("benchmarks/data/vortices-8.toml", "bcm8-s13", 609, 10.0),
              ("charged-particle", "bcm6-s11", 45, 10.0))
"""(system, composition, steps, T) of the third table: the spray's direct form."""


def compiled_spray_flops(system, tapes, n: int, q: float):
    """Flop estimates of the spray's direct form's parts with q nodes
    (`rkhp.integrators.spray_euler.spray_flops`): X, X with d_y X, and with pi too, by the
    operations of their compiled code (`rkhp.systems.field_code.spray_code`'s branches) where the
    tapes have it, else by forward mode on the tape; H's gradient likewise (`derivatives_code`)."""
    from rkhp.integrators import spray_euler
    from rkhp.systems.field_code import derivatives_code, spray_code

    counts = spray_euler.tape_counts(tapes.field, tapes.hamiltonian, n)
    if tapes.field_at:
        counts = counts._replace(**dict(zip(("field", "jacobian", "both"), spray_code(system).branches, strict=True)))
    if tapes.derivatives_at:
        counts = counts._replace(gradient=derivatives_code(system, False).operations)
    return spray_euler.spray_flops(n, q, counts)


def spray_race(name: str, composition: str, steps: int, t_final: float) -> dict:
    """Time, iterations and refreshes per substep of a composition's kernel by the spray's direct
    form."""
    system = get_system(name)
    gammas = load_composition(composition).gamma_float
    h, s = t_final / steps, len(gammas)
    call = loop(system, None, gammas, h, steps)
    call()
    best = min(seconds(call) for _ in range(REPEATS))
    trajectory = run(system, load_tableau("euler"), h, steps, gammas=gammas)
    substeps = steps * s
    extra = trajectory.extra
    iterations = float(np.sum(trajectory.newton_iterations)) / substeps
    sweeps = float(np.sum(trajectory.stage_sweeps)) / substeps
    refreshes = sum(extra["refreshes"]) / substeps
    tapes = setup(system, load_tableau("euler"), gammas).data.tapes
    parts = compiled_spray_flops(system, tapes, system.dim, float(np.mean(extra["nodes"])))
    flops = iterations * parts.iteration + sweeps * parts.sweep + refreshes * parts.matrix + parts.substep
    limit = 2 * parts.sweep + refreshes * parts.matrix + parts.substep
    us = 1e6 * best / substeps
    return {"us": us, "h": h, "iterations": iterations, "sweeps": sweeps, "refreshes": refreshes, "flops": flops,
            "limit": limit, "rate": flops / us / 1e3,
            "nodes": "/".join(str(q) for q in sorted(set(extra["nodes"])))}


def main() -> None:
    print("$ python benchmarks/substeps.py")
    print(f"microseconds per Euler substep (min of {REPEATS}, thread CPU time)")
    print(f"{'system':<18} {'method':<6} {'h':>5} {'direct':>7} {'us':>7} {'tower us':>9} {'ratio':>7} "
          f"{'iter':>5} {'sweeps':>6} {'Newton':>6} {'rel diff':>9}")
    for case in CASES:
        m = measure(*case)
        label, method, h = case[:3]
        print(f"{label:<18} {method:<6} {h:>5g} {m['provider']:>7} {m['direct_us']:>7.2f} {m['tower_us']:>9.1f} "
              f"{m['tower_us'] / m['direct_us']:>6.1f}x {m['iterations']:>5.2f} {m['sweeps']:>6.2f} "
              f"{m['tower_iterations']:>6.2f} {m['gap']:>9.1e}")
        sys.stdout.flush()
    print()
    print(f"the race's settings: per substep (min of {REPEATS}, thread CPU time)")
    print(f"{'system':<18} {'method':<22} {'h':>6} {'us':>6} {'iter':>5} {'sweeps':>6} {'jac':>5} {'flops':>7} "
          f"{'limit':>6} {'GFLOP/s':>8}")
    for name, composition, steps in RACE:
        m = race(name, composition, steps)
        print(f"{name:<18} {composition:<22} {m['h']:>6.3f} {m['us']:>6.2f} {m['iterations']:>5.2f} "
              f"{m['sweeps']:>6.2f} {m['jacobians']:>5.2f} {m['flops']:>7.0f} {m['limit']:>6.0f} {m['rate']:>8.2f}")
        sys.stdout.flush()
    print()
    print(f"the spray's direct form at the race's settings: per substep (min of {REPEATS}, thread CPU time)")
    print(f"{'system':<18} {'method':<10} {'h':>7} {'us':>6} {'iter':>5} {'sweeps':>6} {'refresh':>8} {'Q':>5} "
          f"{'flops':>7} {'limit':>6} {'GFLOP/s':>8}")
    for name, composition, steps, t_final in SPRAY_RACE:
        m = spray_race(name, composition, steps, t_final)
        label = name.rsplit("/", 1)[-1].removesuffix(".toml")
        print(f"{label:<18} {composition:<10} {m['h']:>7.4f} {m['us']:>6.2f} {m['iterations']:>5.2f} "
              f"{m['sweeps']:>6.2f} {m['refreshes']:>8.3f} {m['nodes']:>5} {m['flops']:>7.0f} "
              f"{m['limit']:>6.0f} {m['rate']:>8.2f}")
        sys.stdout.flush()


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/substeps.py", __doc__).parse_args()
    main()
