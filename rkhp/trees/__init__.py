"""Rooted trees and what is written on them alone: enumeration (`rkhp.trees.rooted`), the
Butcher-group algebra (`rkhp.trees.algebra`), the order conditions over T and T_0
(`rkhp.trees.conditions`) and the shipped linear relations of symmetric birealisations
(`rkhp.trees.relations`); docs/theory.md §1–§3, §8."""
