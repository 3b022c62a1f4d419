"""Butcher tableaux: the `Tableau` type (`rkhp.tableaux.tableau`), tableau files
(`rkhp.tableaux.files`), elementary weights (`rkhp.tableaux.weights`) and exact order
verification (`rkhp.tableaux.verification`); docs/theory.md §2."""
