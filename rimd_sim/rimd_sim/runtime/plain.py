"""``RIMD_PLAIN``: a benchmarking switch that puts plain rclpy and Python in place of pieces of the rig's tuning.

The rig's processes are tuned piece by piece for CPU. ``benchmarks/bench_layers.py`` runs the composed rig with
every piece on, then with one piece plain at a time, then with all plain, to tell what each piece buys. The
variable holds a comma-separated list of pieces, or ``all``; unset or empty, every piece is on (the rig's normal
behaviour). Each process reads it where it chooses the piece, as it starts; ``rimd rig``'s nodes inherit it.

* ``outbox``: the composed rig's DDS writes go through :class:`rimd_sim.ros.nodes.outbox.Outbox` (a thread of
  their own when the rig runs fast, rcl's C function called through ctypes without the GIL, a compiled batch
  loop). Plain: rclpy's ``Publisher.publish`` on the pacing thread as each message is sent. Read by
  :func:`rimd_sim.ros.nodes._sim_publishers.feeding_send`.
* ``polling``: the recorder and the Rerun bridge take their subscriptions from a timer whose period follows the
  traffic (:class:`rimd_sim.ros.nodes.polling.PolledSubscriptions`). Plain: their DDS subscriptions are
  ordinary rclpy subscriptions whose callbacks the executor runs, one per message, without the message info
  (a recording then stores publish time 0 for those topics); the composed rig's in-process hand-overs, which
  have no rclpy counterpart, are taken by a timer at the fixed shortest period. Read by ``PolledSubscriptions``.
* ``executor``: rclpy's events executor. Plain: rclpy's ``SingleThreadedExecutor``, as with
  ``RIMD_EXECUTOR=single`` (an explicit ``RIMD_EXECUTOR`` wins). Read by
  :func:`rimd_sim.ros.nodes.base.executor_kind`.
* ``collector``: the cycle collector's settings (:mod:`rimd_sim.runtime.collector`: a raised young threshold
  while a process imports, its imports frozen). Plain: CPython's defaults. Read by the collector's functions.
* ``threads``: the rig's threads named for the kernel (:mod:`rimd_sim.runtime.threads`). Plain: named for
  Python only. Read by :func:`rimd_sim.runtime.threads.named_thread`.
* ``heap``: a node process fixes glibc's mmap threshold and gives the C heap's free pages back once a minute
  (:mod:`rimd_sim.runtime.heap`). Plain: the allocator's defaults, which keep them. Read by
  :func:`rimd_sim.runtime.heap.start`.

A name that is not a piece is refused (:class:`~rimd_sim.errors.InputError`, naming the valid ones): a node
prints it and exits 2 before it starts, ``rimd`` exits 2.
"""

from __future__ import annotations

import os

from rimd_sim.errors import InputError

__all__ = ["PIECES", "PLAIN_ENV", "plain", "plain_pieces"]

#: The environment variable.
PLAIN_ENV = "RIMD_PLAIN"
#: The pieces it can make plain (see the module docstring).
PIECES = ("outbox", "polling", "executor", "collector", "threads", "heap")


def plain_pieces() -> frozenset[str]:
    """The pieces ``RIMD_PLAIN`` makes plain (empty when it is unset or empty).

    Raises:
        InputError: It names something that is not a piece (nor ``all``).
    """
    text = os.environ.get(PLAIN_ENV, "")
    names = {name.strip() for name in text.split(",")} - {""}
    unknown = names - {*PIECES, "all"}
    if unknown:
        raise InputError(f"{PLAIN_ENV}={text!r} refused: {', '.join(sorted(unknown))} is not a piece; "
                         f"give a comma-separated list of {', '.join(PIECES)}, or all")
    return frozenset(PIECES) if "all" in names else frozenset(names)


def plain(piece: str) -> bool:
    """Whether ``RIMD_PLAIN`` makes ``piece`` (one of :data:`PIECES`) plain.

    Raises:
        InputError: ``RIMD_PLAIN`` names something that is not a piece.
    """
    return piece in plain_pieces()
