"""The click front end of rkhp (installed as ``rkhp_cli``): parse options, call the library, render.

When the process is the `rkhp` command (the console script or ``python -m rkhp``), Ctrl-C, SIGTERM
or SIGHUP during the imports that precede the command's own handler (`rkhp_cli.terminal`) ends it
at once with the one line and status of an interrupt (docs/exit-status.md): 130 and
``rkhp: interrupted`` for Ctrl-C, not a traceback; 143 and ``rkhp: interrupted by SIGTERM``, 129
and ``... by SIGHUP``, not a silent end.
"""

import os as _os
import signal as _signal
import sys as _sys


def _interrupted_while_starting(signum, frame):
    try:
        name = "" if signum == _signal.SIGINT else f" by {_signal.Signals(signum).name}"
        _os.write(2, f"rkhp: interrupted{name}\n".encode())
    except OSError:
        pass
    _os._exit(128 + signum)


def _is_the_command() -> bool:
    path = _sys.argv[0] if _sys.argv else ""
    name = _os.path.basename(path)
    return name == "rkhp" or (name == "__main__.py" and _os.path.basename(_os.path.dirname(path)) == "rkhp")


if _is_the_command():
    if _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
        _signal.signal(_signal.SIGINT, _interrupted_while_starting)
    for _name in ("SIGTERM", "SIGHUP"):
        if hasattr(_signal, _name) and _signal.getsignal(getattr(_signal, _name)) == _signal.SIG_DFL:
            _signal.signal(getattr(_signal, _name), _interrupted_while_starting)
