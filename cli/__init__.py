"""The click front end of rkhp (installed as ``rkhp_cli``): parse options, call the library, render."""
