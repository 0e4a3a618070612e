"""hazard: what is dangerous.

MPE per ANSI Z136.1 / IEC 60825-1 (2014 editions, 2007 for comparison), nominal ocular
hazard distances, and (in later modules) reflected irradiance at observers, exposure over
time, keep-out zones and reports. ``import hazard`` is light: heavy dependencies (ray
tracing, rendering, clusters) load only in the stages that need them.
"""

from hazard.physics.mpe import (
    DEFAULT_STANDARD,
    STANDARDS,
    MPEResult,
    correction_factors,
    ocular_mpe,
    repetitive_pulse_mpe,
    skin_mpe,
)
from hazard.physics.nohd import (
    NOHDResult,
    attenuation_from_visibility,
    hazard_distance,
    nohd_diffuse,
    nohd_direct,
    nohd_from_intensity,
    nohd_specular,
    optical_gain,
)

__version__ = "0.1.0"


def __getattr__(name):
    # heavy modules load on first use (pyvista, matplotlib): ``import hazard`` stays light
    lazy = {"render": "hazard.pictures.render", "plots": "hazard.pictures.plots",
            "study": "hazard.drivers.study", "convergence": "hazard.drivers.convergence"}
    if name in lazy:
        import importlib

        return importlib.import_module(lazy[name])
    raise AttributeError(f"module 'hazard' has no attribute {name!r}")


def analyze(scene, **kwargs):
    """Run the hazard analysis of a loaded scene; see :func:`hazard.pipeline.analysis.analyze`."""
    from hazard.pipeline.analysis import analyze as _analyze

    return _analyze(scene, **kwargs)


__all__ = [
    "analyze",
    "DEFAULT_STANDARD", "MPEResult", "NOHDResult", "STANDARDS", "attenuation_from_visibility",
    "correction_factors", "hazard_distance", "nohd_diffuse", "nohd_direct", "nohd_from_intensity",
    "nohd_specular", "ocular_mpe", "optical_gain", "repetitive_pulse_mpe", "skin_mpe",
]
