"""Progress of a long analysis: a tqdm bar over its stages (optional) and the time each stage took."""
from __future__ import annotations

import time


class Progress:
    """Stages of one run: :meth:`stage` starts one, :meth:`done` ends it and records its time (``timings``, s)."""

    def __init__(self, enabled: bool, total: int, desc: str) -> None:
        self.bar = None
        if enabled:
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc=desc, unit='stage', leave=False)
        self.timings: dict[str, float] = {}
        self._t = time.perf_counter()

    def stage(self, name: str) -> None:
        now = time.perf_counter()
        if self.bar is not None:
            self.bar.set_postfix_str(name)
        self._name, self._t = name, now

    def done(self) -> None:
        now = time.perf_counter()
        self.timings[self._name] = round(now - self._t, 4)
        if self.bar is not None:
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
