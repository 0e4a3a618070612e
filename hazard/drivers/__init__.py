"""Drivers on top of the pipeline: scenario studies, convergence tables, probabilistic risk."""
