"""H's gradient and Hessian, and the spray's frozen field, compiled per system, for the direct
forms of the Euler step (`rkhp.integrators.closed_euler`, `rkhp.integrators.spray_euler`;
docs/engine.md "Derivatives compiled per system").

`derivatives_at(system, hessian)` is the address of ``derivatives(u, out, what)``
(`rkhp.systems.field_code.derivatives_code`, compiled by `rkhp.taylor.generated`): ``what`` = 0
writes grad H(x) into out[0:n], ``what`` = 1 grad H(x) and Hess H(x) (n x n, by rows) into out[0:n +
n^2]. The generated module is named by a hash of the Hamiltonian's tape (its rows, constants and
outputs), of the dimension, of whether it holds the Hessian and of the generator's source: a
system met again, in this process or another, finds its module without sympy. 0 where H's tape
holds an operation without a plain-arithmetic form, or the module cannot be kept: the caller then
interprets the tape (`rkhp.integrators.direct_form.gradient`), which agrees to round-off.

`spray_at(system, field)` is the address of ``spray(u, out, what)`` (`rkhp.systems.field_code.
spray_code`): X(y, p) = pi(y) p, with d_y X and pi(y) on request, its module named by a hash of
the field's plain tape `field` (what X is, whatever the text of pi) and of the generator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..systems import field_code
from ..taylor import generated

GENERATOR = Path(__file__).resolve().parent.parent / "systems" / "field_code.py"
"""The source that writes the derivatives (its content is part of a generated module's key)."""
NAME = "derivatives"
"""The name of the generated function of H's derivatives."""
SPRAY = "spray"
"""The name of the generated function of the spray's field."""


def _tape_bytes(tape) -> tuple[bytes, ...]:
    """What a plain tape computes, as bytes: its rows, constants and outputs."""
    return (np.ascontiguousarray(tape.ops, dtype=np.int64).tobytes(),
            np.ascontiguousarray(tape.fpar, dtype=np.float64).tobytes(),
            np.ascontiguousarray(tape.outputs, dtype=np.int64).tobytes())


def derivatives_key(system, hessian: bool) -> str:
    """The key of the generated module of `system`'s derivatives (see the module)."""
    tape = system.h_tape
    return generated.key_of(*_tape_bytes(tape), f"{system.dim} {int(tape.main)} {bool(hessian)}".encode(),
                            GENERATOR.read_bytes())


def derivatives_at(system, hessian: bool) -> int:
    """The address of `system`'s compiled derivatives (with the Hessian when `hessian`), or 0
    (see the module)."""
    try:
        return generated.compiled_address(derivatives_key(system, hessian), NAME,
                                          lambda: field_code.derivatives_code(system, hessian).source)
    except InputError:
        return 0


def spray_at(system, field) -> int:
    """The address of `system`'s compiled spray field (`field`: its plain tape, `rkhp.integrators.
    spray_euler.field_tape`), or 0 (see the module)."""
    key = generated.key_of(b"spray", *_tape_bytes(field), f"{system.dim}".encode(), GENERATOR.read_bytes())
    try:
        return generated.compiled_address(key, SPRAY, lambda: field_code.spray_code(system).source)
    except InputError:
        return 0
