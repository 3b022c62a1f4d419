"""Prepared runs, built once and lent to one run at a time (docs/engine.md "One driver, many
substeps").

What a run of the driver needs besides its start and its step (the substep provider chosen for
the system and the base method, the provider's data with its work arrays, the solver) depends on
the system, the base method, the number of substeps and the solver's settings alone. A
:class:`Lender` keeps what was built for such a key, per system (while the system lives) and
base method, and lends it to one run at a time: a run takes it, runs, and gives it back; a run that finds none
free (the first, or another thread's run holding it) builds its own, which is kept afterwards.
So the threads of an ensemble each hold data of their own, and a run never shares work arrays
with another that is under way.

Reusing data is safe because a provider's ``begin`` starts every run afresh (the state and the
memory of the substeps, `rkhp.integrators.substeps`), and what a run reports of its provider
(``extra``) is copied out before the data is given back. Data whose arrays hold more than
KEEP_BYTES is not kept (it is built again for every run), nor more than one item per core and
key.
"""

from __future__ import annotations

import threading
import weakref
from typing import NamedTuple

import numpy as np

from ..base.executors import available_cores

KEEP_BYTES = 64 * 2**20
"""Prepared data whose arrays hold more bytes than this is not kept between runs."""


def array_bytes(value) -> int:
    """Bytes held by the numpy arrays in `value` and the tuples (NamedTuples) it nests."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, tuple):
        return sum(array_bytes(v) for v in value)
    return 0


class Slot(NamedTuple):
    """The free items of one key: the base method they were built for (held, so that the key's
    id of it names no other object while the slot lives) and the items."""

    owner: object
    items: list


class Lent(NamedTuple):
    """A prepared item on loan: the item, whether it was built for this run (its first), and the
    slot it goes back to."""

    item: object
    built: bool
    slot: Slot


class Lender:
    """Items built once per (system, base method, key) and lent to one run at a time (see the
    module)."""

    def __init__(self, per_key: int | None = None, keep_bytes: int = KEEP_BYTES):
        self._slots: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self._lock = threading.Lock()
        self._per_key = per_key or max(2, available_cores())
        self._keep_bytes = keep_bytes

    def take(self, system, owner, key, build) -> Lent:
        """A free item of (system, owner, key), or a new one from ``build()``; `owner` (the base
        method) is told apart by identity."""
        with self._lock:
            slots = self._slots.get(system)
            if slots is None:
                slots = self._slots[system] = {}
            slot = slots.get((id(owner), key))
            if slot is None or slot.owner is not owner:
                slot = slots[(id(owner), key)] = Slot(owner, [])
            if slot.items:
                return Lent(slot.items.pop(), False, slot)
        return Lent(build(), True, slot)

    def give(self, lent: Lent) -> None:
        """Give back a lent item: kept for the next run unless it is too large (measured when it
        was built) or enough are kept."""
        if lent.built and array_bytes(lent.item) > self._keep_bytes:
            return
        with self._lock:
            if len(lent.slot.items) < self._per_key:
                lent.slot.items.append(lent.item)

    def clear(self) -> None:
        """Forget every kept item."""
        with self._lock:
            self._slots.clear()
