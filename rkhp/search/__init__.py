"""Tableau search: minimal-stage tableaux, polished, recognised, verified, proved.

Modules, one idea each:

- :mod:`.system`: unknowns, order-condition residuals and their exact Jacobian (forward pass);
- :mod:`.multistart`: seeded restarts of scipy least squares, on an executor (:mod:`rkhp.base.executors`);
- :mod:`.polish`: Newton's method in mpmath to D digits;
- :mod:`.recognise`: closed forms (free parameters fixed at simple values, PSLQ), exact check;
- :mod:`.prove`: Groebner-basis certificates of impossibility;
- :mod:`.optimise`: minimal principal error on the solution family (SLSQP);
- :mod:`.driver`: :func:`search`, which ties them together.

``from rkhp.search import search, SearchOptions`` loads the driver on first use.
"""

from __future__ import annotations

from .._lazy import lazy_getattr

_LAZY = {"search": "rkhp.search.driver", "SearchOptions": "rkhp.search.driver",
         "SearchResult": "rkhp.search.driver", "prove_impossible": "rkhp.search.prove",
         "ResidualSystem": "rkhp.search.system"}

__all__ = sorted(_LAZY)

__getattr__ = lazy_getattr("rkhp.search", _LAZY)
