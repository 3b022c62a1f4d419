"""Studies: references, convergence, work-precision, stress (docs/studies.md)."""
