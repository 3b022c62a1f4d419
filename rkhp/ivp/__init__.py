"""Initial value problems to a tolerance, in scipy's terms: `rkhp.solve`, events, dense output and
Poincaré sections (docs/solve.md)."""
