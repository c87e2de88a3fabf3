"""PyBullet DIRECT clients kept between the sessions that load the same files.

A session whose ``SessionOptions.files_key`` names the exact contents of the files it loads (a candidate's digest
in its workspace, :meth:`asset2sim.tasks.assemble.candidate.Workspace.session`) takes a client an earlier session
of that key left idle, emptied by ``resetSimulation``, and leaves its own for the next; the results are the same to
the bit as in a new client, and connecting and building the collision shapes again is saved (about 12 % of a
dev row's refine, ``benchmarks/bench_sessions.py``). The key is what makes that safe: a client keeps the meshes it
loaded by file name for its whole life, ``resetSimulation`` included, so a client kept across a rewrite of a
collision file at the same path would load the file's old geometry.
"""

from __future__ import annotations

import threading

from asset2sim.engines.quiet import quiet_stdout

#: Most idle clients kept in a process (their worlds empty, their mesh caches holding the files of their key).
MAX_IDLE = 3
#: The idle clients, oldest first: (files key, client id).
IDLE: list[tuple[str, int]] = []
_LOCK = threading.Lock()


def take(p, files_key: str | None) -> int:
    """An idle client kept under ``files_key`` (its world empty), else a new DIRECT client of the ``pybullet``
    module ``p``."""
    if files_key is not None:
        with _LOCK:
            for i, (key, cid) in enumerate(IDLE):
                if key == files_key:
                    del IDLE[i]
                    return cid
    with quiet_stdout():
        return p.connect(p.DIRECT)


def give_back(p, cid: int, files_key: str | None) -> None:
    """Empty client ``cid`` (``resetSimulation``) and keep it under ``files_key``, disconnecting the oldest idle
    client beyond :data:`MAX_IDLE`; without a key (or when it cannot be emptied), disconnect it."""
    if files_key is None:
        p.disconnect(cid)
        return
    try:
        p.resetSimulation(physicsClientId=cid)
    except Exception:  # a client that cannot be emptied is not kept
        p.disconnect(cid)
        return
    with _LOCK:
        IDLE.append((files_key, cid))
        excess = max(len(IDLE) - MAX_IDLE, 0)
        dropped = IDLE[:excess]
        del IDLE[:excess]
    for _, old in dropped:
        p.disconnect(old)
