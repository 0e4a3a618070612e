"""Independent validation suite: the hazard engine against references written from the spec formulas."""
