"""Named Butcher tableaux shipped with rkhp, one TOML file per method (schema: README, "Tableau files")."""
