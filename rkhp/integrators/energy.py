"""H at every state of a trajectory, by one compiled loop over the system's Hamiltonian tape (the
tape interpreter of rkhp.taylor, in jets of degree 0; docs/engine.md).

Used for long trajectories (energy errors of the studies, the energy column of a trajectory file),
where the system's own evaluation, one interpreter call per state from Python, costs about 27 us a
state on the rigid body. Compiled and cached on disk like the other kernels (kind "invariants" of
rkhp.integrators.kernels).
"""

from __future__ import annotations

import numpy as np

from ..base.errors import NumericalFailure
from ..taylor.compiler import NJIT
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import address_of, as_plain, interpreter, run_from, tape_work
from ..taylor.jets import jet_space

#: whether the compiled loop has been compared with a system's own evaluation in this process
_VERIFIED: set[str] = set()


@nb.njit(**NJIT)
def _hamiltonian_loop(run, htape, space, states, work, out):
    """out[r] = H(states[r]) by the interpreter of the tape's class at the address `run`."""
    n = states.shape[1]
    ho = htape.outputs[0]
    W = work.W
    tape_at, space_at, work_at = address_of(htape), address_of(space), address_of(work)
    for r in range(states.shape[0]):
        W[:, :] = 0.0
        for i in range(n):
            W[i, 0] = states[r, i]
        run_from(run, tape_at, np.int64(0), space_at, work_at)
        out[r] = W[ho, 0]


def hamiltonian_values(system, states) -> np.ndarray:
    """H at every row of ``states`` (compiled loop over the system's Hamiltonian tape)."""
    states = np.ascontiguousarray(states, dtype=np.float64).reshape(-1, system.dim)
    space = jet_space(0, 0)
    ht = system.h_tape
    out = np.empty(len(states))
    _hamiltonian_loop(interpreter(ht).address, as_plain(ht), space, states, tape_work((ht,), space.size), out)
    if "hamiltonian" not in _VERIFIED and len(out):
        want = system.hamiltonian(states[0])
        if not abs(out[0] - want) <= 1e-12 * max(1.0, abs(want)):
            raise NumericalFailure("compiled Hamiltonian kernel of rkhp.integrators.energy disagrees with "
                                   f"{system.name}'s own evaluation (stale numba cache after a source change?)")
        _VERIFIED.add("hamiltonian")
    return out
