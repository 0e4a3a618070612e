"""The analysis as a plan of stages (:mod:`hazard.pipeline.plan`), one module per stage.

Each stage takes and returns explicit data; :func:`hazard.analysis.analyze` runs them.
"""
