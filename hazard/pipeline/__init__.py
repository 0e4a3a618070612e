"""The analysis as a plan of stages (:mod:`hazard.pipeline.plan`), one module per stage.

Each stage takes and returns explicit data, declared in :mod:`hazard.pipeline.stages` (what it
needs, the frozen result it provides); :func:`hazard.pipeline.analysis.analyze` runs them in the order
derived from those declarations.
"""
