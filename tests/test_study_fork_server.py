"""casflex.study.fork_server: the process a sweep's local workers are forked from."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(os.name != "posix", reason="the fork server and signal masks (POSIX)")

#: a process that starts the fork server and at once sends it SIGINT (a Ctrl-C at a terminal reaches it with the
#: command), then says whether the server is still there a moment later
SCRIPT = """
import os, signal, time
from multiprocessing import forkserver
from casflex.study.fork_server import fork_server
assert fork_server()
pid = forkserver._forkserver._forkserver_pid
os.kill(pid, signal.SIGINT)
time.sleep(3.0)
print("alive" if os.waitpid(pid, os.WNOHANG) == (0, 0) else "ended")
"""


def test_a_ctrl_c_as_the_fork_server_starts_leaves_it_running_without_a_traceback():
    # the server used to start with SIGINT as Python's default until its first module ignored it: a Ctrl-C in its
    # first 50-300 ms (Python's start, the site's imports) ended it with a KeyboardInterrupt's traceback on the
    # command's stderr; it starts with SIGINT blocked now (multiprocessing's resource tracker, started first, unblocks
    # it after its own start: it was unblocked again before the server's)
    got = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert got.returncode == 0, got.stderr
    assert got.stdout.strip() == "alive" and "KeyboardInterrupt" not in got.stderr, got.stderr
