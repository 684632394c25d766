"""Child processes that die with their parent.

A process pool's workers block on a queue whose write end they hold
themselves, so a parent killed with ``kill -9`` (no ``finally``, no
``atexit``) leaves them running: measured, ``babble --workers 2`` left its
pool processes alive 30 s and more. :func:`die_with_parent`, called first in
a child (a pool's initializer, a decomposition's process), starts a daemon
thread that ends the child within :data:`POLL` seconds of its parent's death
(the child is re-parented: ``os.getppid()`` changes). Not Linux's
``PR_SET_PDEATHSIG``: its signal follows the parent *thread* that spawned
the child, and a pool first used from a worker thread (the babbling report
runs its runs in threads) would lose its processes when that thread ends.
"""

from __future__ import annotations

import os
import threading

__all__ = ["POLL", "die_with_parent", "init_worker"]

POLL = 0.25  # s between two looks at the parent's pid


def die_with_parent(parent_pid: int | None = None) -> None:
    """Ends this process (``os._exit``) when its parent ``parent_pid`` (default:
    the current parent) is gone. Call it once, first thing in the child."""
    parent = os.getppid() if parent_pid is None else int(parent_pid)
    if os.getppid() != parent:  # the parent died before we looked
        os._exit(1)

    def watch():
        import time

        while True:
            time.sleep(POLL)
            if os.getppid() != parent:  # re-parented: the parent is gone
                os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def init_worker(parent_pid, initializer=None, initargs=()) -> None:
    """A pool initializer: :func:`die_with_parent`, then ``initializer(*initargs)``."""
    die_with_parent(parent_pid)
    if initializer is not None:
        initializer(*initargs)
