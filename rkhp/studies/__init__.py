"""Studies: references, convergence, work-precision, stress (issue 6)."""
