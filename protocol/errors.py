"""Counting rejected input: every long-running process counts what it refuses and keeps going."""

from __future__ import annotations

import logging
import threading
from collections import Counter
from dataclasses import dataclass, field

log = logging.getLogger("swarmloc.protocol")


@dataclass
class ErrorCounter:
    """Rejected inputs, counted per kind and logged once per sender."""

    counts: Counter = field(default_factory=Counter)
    _seen: set = field(default_factory=set)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def record(self, sender: str, kind: str, error: Exception) -> None:
        with self._lock:
            self.counts[kind] += 1
            if (sender, kind) not in self._seen:
                self._seen.add((sender, kind))
                log.warning("rejected %s from %s: %s", kind, sender, error)

    @property
    def total(self) -> int:
        return sum(self.counts.values())
