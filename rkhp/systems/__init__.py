"""Poisson systems and their birealisations (NOTES §4, paper §2)."""
