"""Values a client library delivers from its own thread (MAVSDK callbacks), and bounded waits on them."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any


class Watch:
    """Values a MAVSDK callback delivers (from its own thread), and a bounded wait for one that fits."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.values: list[Any] = []

    def __call__(self, value: Any, _user_data: Any = None) -> None:
        with self.cond:
            self.values.append(value)
            self.cond.notify_all()

    def wait(self, pred: Callable[[Any], bool], timeout: float) -> Any:
        """The first value (already seen or arriving within ``timeout`` s) satisfying ``pred``, or None."""
        end = time.monotonic() + timeout
        seen = 0
        with self.cond:
            while True:
                for v in self.values[seen:]:
                    if pred(v):
                        return v
                seen = len(self.values)
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self.cond.wait(left)

    def last(self) -> Any:
        with self.cond:
            return self.values[-1] if self.values else None
