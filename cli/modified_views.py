"""The modified Hamiltonian in the commands: a method's character (`rkhp modified`, `rkhp compose`)
and the series and energy errors of `rkhp integrate --modified N` (docs/modified.md)."""

from __future__ import annotations

from .options import progress

EXACT = "exact"
"""The method name of the exact flow in `modified` and `compose` (character e(t) = 1/gamma(t))."""


def character_of(name: str, order: int):
    """(name, character a(t) on T up to `order`) of a method name of docs/methods.md, or of `exact`."""
    from rkhp.integrators.methods import resolve_method
    from rkhp.series.modified import method_character
    from rkhp.trees.algebra import exact_flow_character

    if name == EXACT:
        return EXACT, exact_flow_character(order)
    chosen = resolve_method(name)
    return chosen.name, method_character(chosen, order)


def modified_series(system, method, order: int, show_progress: bool):
    """The modified Hamiltonian of an RKHP or THP method (rkhp.integrators.methods.Method) to ``order``, in the
    class of the system's realisation (for ``rkhp integrate --modified N``)."""
    from rkhp.integrators.methods import condition_class
    from rkhp.series.modified import MAX_ORDER, method_character, modified_hamiltonian
    from rkhp.trees.rooted import check_order

    check_order(order, MAX_ORDER, what="--modified order")
    character = method_character(method, order)
    with progress(show_progress) as bar:
        bar.add_task(f"modified Hamiltonian to order {order}", total=None)
        return modified_hamiltonian(character, order, condition_class(system))


def modified_energy_report(system, series, h: float, states, show_progress: bool) -> dict:
    """The keys that ``rkhp integrate --modified N`` adds (docs/modified.md)."""
    from rkhp.integrators.modified_energy import energy_errors

    with progress(show_progress) as bar:
        task = bar.add_task(f"H~_{series.order} along the run", total=len(states))
        return energy_errors(system, series, h, states, lambda: bar.advance(task))
