"""Linear stability and phase of RKHP methods (docs/theory.md §13, docs/stability.md).

On the harmonic oscillator pi = [[0, 1], [-1, 0]], H = (x1^2 + x2^2)/2 (any constant-pi system with
a quadratic Hamiltonian is a sum of such oscillators after a linear symplectic change of variables),
z = h omega, with the symmetric birealisation alpha, beta = x -/+ pi p/2, every stage of the RKHP
step (paper §5.2) is a multiple of x: Z_i(x) = m_i x with

    m_i = z sum_j a_ij (1 + m_j^2/4),        m = z sum_i b_i (1 + m_i^2/4),

and the step is the Cayley transform (I + m J/2)(I - m J/2)^-1: an exact rotation by
theta(z) = 2 arctan(m(z)/2). The exact flow has m = 2 tan(z/2). Amplitude is exact for every z; what
a method changes is the phase theta(z) - z (its order p and leading constant), where theta stops
growing with z (the wrap limit), and for an implicit tableau whether the stage equations have a
solution at all (the existence limit z*, a fold of the branch through m(0) = 0).

With the ``shifted`` realisation (alpha, beta = x + Q p -/+ pi p/2, Q symmetric) the stages are
symmetric matrices M_i = z sum_j a_ij (I + D M_j)^T (I + D M_j), D = Q - pi/2, the step matrix is
R = (I + D' P)(I + D P)^-1 (D' = Q + pi/2, P the same sum with b), and the trace of R decides: |tr R| < 2 is an elliptic
(bounded) step, a rotation by arccos(tr R / 2) in a skew frame; |tr R| > 2 is hyperbolic. tr R depends
on delta = det(P^-1 + Q) alone (elliptic iff delta > 0), explicit and implicit stages alike; an implicit
tableau's matrix stages are followed from M = 0 to their fold (`shifted_branch`).

Everything here is exact (sympy, in the number field of the tableau's entries) where the tableau is
exact; a tableau given by decimals is read at its digits and its values have no exact text.

Modules: `field` (numbers, the field of the entries), `series` (truncated series), `phase`,
`roots` (exact positive roots), `explicit`, `implicit` (continuation of the symmetric stages),
`shifted` (the shifted realisation), `report` (`analyse`).
"""

from .explicit import m_polynomial, wrap_limit_explicit, wrap_limit_numeric
from .field import Number, Z
from .implicit import implicit_branch
from .phase import Phase, composition_phase, phase
from .report import Stability, analyse, analyse_composition, rotation_angle, rotation_angles
from .series import phase_coefficients_numeric
from .shifted import shifted_branch, shifted_trace, step_matrix_shifted

__all__ = ["Number", "Phase", "Stability", "Z", "analyse", "analyse_composition", "composition_phase",
           "implicit_branch", "m_polynomial", "phase", "phase_coefficients_numeric", "rotation_angle",
           "rotation_angles", "shifted_branch", "shifted_trace", "step_matrix_shifted",
           "wrap_limit_explicit", "wrap_limit_numeric"]
