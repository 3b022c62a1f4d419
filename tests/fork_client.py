"""The test side of tests/forkserver.py: one server process per test process, one request per case.

Both hostile corpora (tests/test_hostile.py, tests/test_corpus.py) run their cases through it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

#: one thread per library, so that the CPU time a case reports is its own
ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class ForkServer:
    """tests/forkserver.py, started with :data:`ENV`: it has imported the command line and forks a
    process per request (a case: its arguments, folder, environment, output files and limits)."""

    def __init__(self):
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).with_name("forkserver.py"))],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     env={**os.environ, **ENV})
        assert json.loads(self.proc.stdout.readline()) == {"ready": True}

    def run(self, request: dict) -> dict:
        """The server's answer to one case: its exit status (or "timeout"), wall and CPU seconds,
        peak memory."""
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=60)
