"""Validation suite configuration.

Every property test here pins its own hypothesis settings (``_refs.FAST`` / ``_refs.SLOW``:
``derandomize=True``, ``deadline=None``, a fixed ``max_examples``), so a run is reproducible
whatever profile the top-level conftest loads. The default run keeps a few examples per
property; the ``slow`` variants sweep many more (``python -m pytest tests/validation -m slow``).
"""
