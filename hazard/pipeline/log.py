"""The record of an analysis run: one :class:`~hazard.pipeline.results.Stage` per planned stage."""

from __future__ import annotations

import time
from contextlib import contextmanager

from hazard.pipeline.results import Stage
from hazard.pipeline.stages import stage_records

__all__ = ["StageLog"]


class StageLog:
    """Collects what each stage did (or why it was skipped) and its wall time.

    ``progress`` is called with ``"<name>..."`` as a stage starts. :meth:`stages` returns
    the records in the plan's order; every stage must be recorded exactly once.
    """

    def __init__(self, progress=None):
        self._say = progress or (lambda msg: None)
        self._done = {}

    @contextmanager
    def run(self, name, detail=""):
        """Time a stage; the body may set ``.detail`` on the yielded record."""
        self._say(f"{name}...")
        t0 = time.perf_counter()
        st = Stage(name, True, detail)
        yield st
        st.seconds = time.perf_counter() - t0
        self._add(st)

    def ran(self, name, detail, seconds):
        """Record a stage whose time was measured elsewhere (inside the map's blocks)."""
        self._add(Stage(name, True, detail, float(seconds)))

    def skip(self, name, why):
        self._add(Stage(name, False, why))

    def _add(self, st):
        if st.name in self._done:
            raise RuntimeError(f"stage {st.name!r} recorded twice")
        self._done[st.name] = st

    def stages(self) -> list:
        order = stage_records()  # derived from the stages' declarations
        missing = [n for n in order if n not in self._done and n != "extended_source"]
        if missing:
            raise RuntimeError(f"stages never recorded: {missing}")
        return [self._done[n] for n in order if n in self._done]
