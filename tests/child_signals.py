"""The signal dispositions a test gives the rkhp processes it starts.

A process started in the background by a non-interactive shell ignores SIGINT, and one started
under ``nohup`` ignores SIGHUP; a child inherits what is ignored. The tests that signal an rkhp
process start it as an interactive shell starts a command: SIGINT, SIGTERM and SIGHUP at their
default action (`default_signals`, a ``preexec_fn``), whatever ran the test suite.
"""

from __future__ import annotations

import signal


def default_signals() -> None:
    """In a child before it runs: SIGINT, SIGTERM and SIGHUP back to their default action."""
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)
