"""Check the birealisation axioms of a system at random points (docs/theory.md §4, paper §2).

On T*M, {F, G} = F_x . G_p - F_p . G_x. With the Jacobians of alpha and beta at (x, p), computed
exactly by forward-mode automatic differentiation (degree-1 jets in the 2n variables, the same
compiled interpreter as the integrators, `rkhp.taylor.interpreter`) and pi from the system's
family (`rkhp.systems.families`), the axioms read
alpha(x, 0) = beta(x, 0) = x, {alpha_i, alpha_j} = pi_ij(alpha), {beta_i, beta_j} = -pi_ij(beta),
{alpha_i, beta_j} = 0. Degeneracy (paper, eq. (degen)): d_p alpha(x, 0) is antisymmetric.
Symmetry (docs/theory.md §8): beta(x, p) = alpha(x, -p) to round-off at the samples.

Each deviation is measured against the size of what it is computed from, so that round-off,
which grows with those sizes, is never taken for a violated axiom: a bracket {F_i, G_j} =
sum_k dF_i/dx_k dG_j/dp_k - dF_i/dp_k dG_j/dx_k is a sum of 2n products, at most
`bracket_size` = 2n max|dF| max|dG| (at least 1) in size, and its deviation is divided by that
size at each sample; the identity's by max(1, |x|). The tolerance `TOLERANCE` applies to those
relative deviations: the absolute one at a sample is TOLERANCE times its size (the largest:
`BirealisationCheck.scale`). A structure that is not Poisson deviates by about 1e-2 of it
(docs/theory.md §9), ten orders of magnitude above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base import bounds

#: the largest deviation accepted, relative to the size of what it is computed from (the module)
TOLERANCE = 1e-12
#: how the tolerance applies, in words (the JSON's ``tolerance_rule``)
TOLERANCE_RULE = ("relative: a bracket's deviation divided by its size 2n max|dF| max|dG| (at least 1), "
                  "the identity's by max(1, |x|), at each sample")


@dataclass(frozen=True)
class BirealisationCheck:
    """Maximum deviations over the samples, each relative to the size of what it is computed from
    (the module); ``scale``: the largest size of a bracket over the samples, so that the largest
    absolute tolerance used is ``tolerance * scale``."""

    system: str
    realisation: str
    degenerate: bool
    samples: int
    seed: int
    identity: float
    poisson: float
    anti_poisson: float
    commute: float
    degeneracy: float
    tolerance: float
    symmetric: bool = False
    symmetry: float = 0.0
    scale: float = 1.0

    tolerance_rule = TOLERANCE_RULE
    #: docs/json.md "rkhp check": the axioms' deviations, then those of degeneracy and symmetry
    json_keys = ("system", "realisation", "degenerate", "symmetric", "samples", "seed", "tolerance", "tolerance_rule",
                 "scale", "deviations", "degeneracy", "symmetry", "ok")

    @property
    def deviations(self) -> dict[str, float]:
        return {"identity": self.identity, "poisson": self.poisson,
                "anti_poisson": self.anti_poisson, "commute": self.commute}

    @property
    def ok(self) -> bool:
        return all(v <= self.tolerance for v in self.deviations.values())


def sample_points(system, samples: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random (x, p): x around x0 within the domain (factors in [1/2, 3/2] on the positive
    orthant, x0 + N(0, 1) scaled by max(1, |x0|) elsewhere), p uniform in [-1/2, 1/2]^n."""
    rng = np.random.default_rng(seed)
    n = system.dim
    x0 = np.asarray(system.x0, dtype=np.float64)
    if system.domain == "positive orthant":
        xs = x0 * rng.uniform(0.5, 1.5, size=(samples, n))
    else:
        xs = x0 + max(1.0, float(np.abs(x0).max())) * rng.normal(size=(samples, n))
    ps = rng.uniform(-0.5, 0.5, size=(samples, n))
    return xs, ps


def _bracket(J: np.ndarray, K: np.ndarray, n: int) -> np.ndarray:
    """{F_i, G_j} from the Jacobians (rows: components, columns: x then p)."""
    return J[:, :n] @ K[:, n:].T - J[:, n:] @ K[:, :n].T


def bracket_size(J: np.ndarray, K: np.ndarray, n: int) -> float:
    """The size of the brackets {F_i, G_j} of two Jacobians: 2n max|J| max|K| (at least 1), a
    bound of each bracket's 2n products, to which its round-off is proportional."""
    return max(1.0, 2 * n * float(np.abs(J).max()) * float(np.abs(K).max()))


def check_birealisation(system, samples: int = 100, seed: int = 0,
                        tolerance: float = TOLERANCE) -> BirealisationCheck:
    """Maximum deviation of each axiom over `samples` random points (seeded), relative to the
    sizes involved (see the module)."""
    from ..taylor.interpreter import evaluate

    bounds.integer(samples, "--samples", 1, bounds.MAX_SAMPLES)
    bounds.seed(seed, "--seed")
    n = system.dim
    dev = dict(identity=0.0, poisson=0.0, anti_poisson=0.0, commute=0.0, degeneracy=0.0,
               symmetry=0.0)
    largest = 1.0
    for x, p in zip(*sample_points(system, samples, seed), strict=True):
        a, Ja = evaluate(system.alpha_tape, np.concatenate([x, p]), 1, 2 * n)
        b, Jb = evaluate(system.beta_tape, np.concatenate([x, p]), 1, 2 * n)
        a0, J0 = evaluate(system.alpha_tape, np.concatenate([x, 0 * p]), 1, 2 * n)
        b0 = evaluate(system.beta_tape, np.concatenate([x, 0 * p]))
        a_minus = evaluate(system.alpha_tape, np.concatenate([x, -p]))
        pa, pb = system.poisson(a), system.poisson(b)
        sizes = {"poisson": bracket_size(Ja, Ja, n), "anti_poisson": bracket_size(Jb, Jb, n),
                 "commute": bracket_size(Ja, Jb, n)}
        largest = max(largest, *sizes.values())
        dev["identity"] = max(dev["identity"], max(np.abs(a0 - x).max(), np.abs(b0 - x).max())
                              / max(1.0, np.abs(x).max()))
        dev["poisson"] = max(dev["poisson"], np.abs(_bracket(Ja, Ja, n) - pa).max() / sizes["poisson"])
        dev["anti_poisson"] = max(dev["anti_poisson"],
                                  np.abs(_bracket(Jb, Jb, n) + pb).max() / sizes["anti_poisson"])
        dev["commute"] = max(dev["commute"], np.abs(_bracket(Ja, Jb, n)).max() / sizes["commute"])
        D = J0[:, n:]
        dev["degeneracy"] = max(dev["degeneracy"],
                                np.abs(D + D.T).max() / max(1.0, np.abs(D).max()))
        dev["symmetry"] = max(dev["symmetry"],
                              np.abs(b - a_minus).max() / max(1.0, np.abs(b).max()))
    dev = {k: float(v) for k, v in dev.items()}
    return BirealisationCheck(system=system.name, realisation=system.realisation,
                              degenerate=dev["degeneracy"] <= tolerance,
                              symmetric=dev["symmetry"] <= tolerance, samples=samples,
                              seed=seed, tolerance=tolerance, scale=largest, **dev)
