"""hazard: what is dangerous.

MPE per ANSI Z136.1 / IEC 60825-1 (2014 editions, 2007 for comparison), nominal ocular
hazard distances, and (in later modules) reflected irradiance at observers, exposure over
time, keep-out zones and reports. ``import hazard`` is light: heavy dependencies (ray
tracing, rendering, clusters) load only in the stages that need them.
"""

from .mpe import (
    DEFAULT_STANDARD,
    STANDARDS,
    MPEResult,
    correction_factors,
    ocular_mpe,
    repetitive_pulse_mpe,
    skin_mpe,
)
from .nohd import (
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
    if name in ("render", "plots", "study", "convergence"):
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'hazard' has no attribute {name!r}")


def analyze(scene, **kwargs):
    """Run the hazard analysis of a loaded scene; see :func:`hazard.analysis.analyze`."""
    from .analysis import analyze as _analyze

    return _analyze(scene, **kwargs)


__all__ = [
    "analyze",
    "DEFAULT_STANDARD", "MPEResult", "NOHDResult", "STANDARDS", "attenuation_from_visibility",
    "correction_factors", "hazard_distance", "nohd_diffuse", "nohd_direct", "nohd_from_intensity",
    "nohd_specular", "ocular_mpe", "optical_gain", "repetitive_pulse_mpe", "skin_mpe",
]
