"""Safety limits and optics: MPE, NOHD, the beam, reflections, ray tracing, near fields, keep-out lobes."""
