"""`python -m rkhp` runs the command line."""
from rkhp_cli.main import main

if __name__ == "__main__":
    main()
