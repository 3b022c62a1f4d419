"""Series of the RKHP step evaluated on Poisson systems: elementary differentials
(`rkhp.series.differentials`), modified Hamiltonians (`rkhp.series.modified`) and compositions
of generating functions (`rkhp.series.composed_steps`); docs/theory.md §8, §11."""
