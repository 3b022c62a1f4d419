"""The click front end of rkhp (installed as ``rkhp_cli``): parse options, call the library, render.

When the process is the `rkhp` command (the console script or ``python -m rkhp``), Ctrl-C during
the imports that precede the command's own handler (`rkhp_cli.terminal`) ends it at once with the
one line and status 130 of an interrupt (docs/exit-status.md), not with a traceback.
"""

import os as _os
import signal as _signal
import sys as _sys


def _interrupted_while_starting(signum, frame):
    _os.write(2, b"rkhp: interrupted\n")
    _os._exit(130)


def _is_the_command() -> bool:
    path = _sys.argv[0] if _sys.argv else ""
    name = _os.path.basename(path)
    return name == "rkhp" or (name == "__main__.py" and _os.path.basename(_os.path.dirname(path)) == "rkhp")


if _is_the_command() and _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
    _signal.signal(_signal.SIGINT, _interrupted_while_starting)
