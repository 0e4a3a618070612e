"""One analysis per bundled example (and ``keep_history``), shared by every test module
of a session.

A bundled scene's default analysis is the same whichever test asks for it (the analysis
is deterministic and does not depend on the thread count), so the test modules that only
read it share one run instead of each running it again (steel_vs_copper was analysed by
six modules, airspace by five calls). The tests that use it read the result and never
change it; a test that patches the engine (``monkeypatch``) or needs other keywords
calls :func:`hazard.analyze` itself.
"""

from __future__ import annotations

import functools

import hazard
import scenes


@functools.lru_cache(maxsize=None)
def bundled(name: str, keep_history: bool | None = None):
    """The :func:`hazard.analyze` result of bundled example ``name`` (read only)."""
    return hazard.analyze(scenes.load(scenes.example_path(name)), keep_history=keep_history)
