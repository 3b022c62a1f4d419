"""Tableau search: residual systems, multistart, polishing, recognition, proofs (issue 4)."""
