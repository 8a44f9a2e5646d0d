"""The live view's core: received messages in, encoded scene messages out (no Zenoh here).

The same :class:`~shared.foxglove.stream.SceneStream` as the executor's MCAP log, so the live scene and
the recorded one are the same messages; messages arrive on several threads (one per subscription), so
the core serialises them.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from shared.foxglove.scene import SceneBuilder
from shared.foxglove.stream import DRAWS, SceneStream, VizMessage
from shared.protocol import Message

__all__ = ["ViewCore"]


class ViewCore:
    """Turns each received message into the scene messages that draw it (throttled as the log is).

    Args:
        builder: Builds the scene.
        viz_period_s: Smallest time (message stamps) between two updates of the robot, the human or the
            occupancy; plans and posteriors are drawn every time.
        clock: Receive-time source in ns (default ``time.time_ns``).

    Attributes:
        drawn: Scene messages produced per topic.
        errors: Messages whose drawing raised (the view goes on).
    """

    def __init__(self, builder: SceneBuilder, viz_period_s: float = 0.1,
                 clock: Callable[[], int] = time.time_ns) -> None:
        self.stream = SceneStream(builder, viz_period_s)
        self._clock = clock
        self._lock = threading.Lock()
        self.drawn: dict[str, int] = {}
        self.errors = 0

    def static(self) -> list[VizMessage]:
        """The table, cups and robot base, stamped now (sent at start and again for clients that join later)."""
        with self._lock:
            return self.stream.static(self._clock())

    def on_message(self, msg: Message, watched: Callable[[str], bool] | None = None) -> list[VizMessage]:
        """The scene messages of ``msg`` received now ([] when it is not drawn: no picture, or too soon).

        Args:
            msg: The message.
            watched: Whether a client subscribes to a topic (None: draw as if one did). A message none of whose
                topics (:data:`~shared.foxglove.stream.DRAWS`) is watched is not drawn, and does not count as
                drawn: the next one of its kind is drawn for a client that subscribes meanwhile.
        """
        with self._lock:
            log_time = self._clock()  # in the lock: the messages of one topic leave in the order of their times
            topic = self.stream.due(msg)
            if topic is None or (watched is not None and not any(map(watched, DRAWS[topic]))):
                return []
            self.stream.mark(topic, msg)
            try:
                out = self.stream.draw(msg, log_time)
            except Exception:
                self.errors += 1
                raise
            for m in out:
                self.drawn[m.topic] = self.drawn.get(m.topic, 0) + 1
            return out
