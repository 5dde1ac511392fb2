"""The readers the transport must match before the simulator's next block, and how long the caller waits for them.

A volatile topic reaches only the readers its writer has matched, and a reader can show in the ROS graph before
it is matched. So the caller of the runtime waits, at most :data:`MATCH_TIMEOUT_S` (in lockstep
:data:`MATCH_TIMEOUT_LOCKSTEP_S`), until the transport has matched: every reader before the run's first block, and
the readers of each lockstep consumer that joined since the last wait before the next block (its subscriptions
may be newer than its report). :class:`ReaderMatches` keeps which.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

__all__ = ["MATCH_TIMEOUT_LOCKSTEP_S", "MATCH_TIMEOUT_S", "ReaderMatches"]

#: Longest the caller waits for the transport to match the readers the graph already shows before the first block
#: (s).
MATCH_TIMEOUT_S = 2.0
#: The same in lockstep (s), before the first block and whenever a consumer joins, where nothing may be lost: a
#: reader that misses the first block after its consumer joined holds the run until lockstep.timeout, and with
#: on_timeout wait for good (the slow start sends that block alone and waits for its confirmation). A join waits
#: only for the readers that consumer has (named in its report, or those the graph shows for its node) and ends as
#: soon as they are matched; the bound is reached only when they never match (a ``node`` the graph does not show, a
#: reader whose QoS its writer cannot serve), and the caller's warning then names them.
MATCH_TIMEOUT_LOCKSTEP_S = 15.0


class ReaderMatches:
    """The joins of lockstep consumers whose readers the transport has yet to match.

    Args:
        published: The topics the simulator publishes (a consumer's named topics are kept to these).
    """

    def __init__(self, published: Iterable[str]) -> None:
        self._published = set(published)
        #: A consumer joined since the last wait: wait for the transport to match its readers.
        self.pending = False
        self._joining: dict[str, list[str] | None] = {}   # node -> its topics (None: unnamed), of new joins
        self._all = False   # a consumer that did not name its node joined: wait for every reader
        self._reporting: dict[str, tuple[str, tuple[str, ...]]] = {}   # consumer -> (node, topics) of its last report

    def reported(self, consumer: str, node: str, topics: Sequence[str]) -> None:
        """What ``consumer``'s last report named: its node and topics (a report taken later is read with them)."""
        self._reporting[consumer] = (node, tuple(topics))

    def joined(self, consumer: str) -> None:
        """``consumer`` joined: its readers are waited for before the next block.

        Those of the published topics its report named, or (None) those the graph shows its node reading; every
        reader the graph shows when its report named no node.
        """
        node, topics = self._reporting.get(consumer, ("", ()))
        if node:
            self._joining[node] = [t for t in topics if t in self._published] if topics else None
        else:
            self._all = True
        self.pending = True

    def take(self, start: bool = False) -> tuple[bool, dict[str, list[str] | None]]:
        """Whether to wait for every reader (always at the ``start``), and the joining nodes' readers to wait for.

        The wait is then no longer pending; a join that comes meanwhile makes it pending again.
        """
        joining = dict(self._joining)
        everyone, self._all = start or self._all, False
        self.pending = False
        return everyone, joining

    def matched(self, joining: Mapping[str, list[str] | None]) -> None:
        """The wait for the joins :meth:`take` returned is over."""
        for node in joining:
            self._joining.pop(node, None)
