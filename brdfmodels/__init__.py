"""brdfmodels: how a surface reflects.

Pluggable BRDF models (Lambertian, ideal mirror, five-parameter Torrance-Sparrow, ABg and
Gaussian scatter lobes,
spherical-harmonic in halfway/difference coordinates, dynamic over a state table,
conservative envelopes, sums and scaled models), their registry and JSON persistence,
surface state histories (oxidation, thin-plate heating) and integrals over a BRDF.
This package knows nothing of scenes or hazards.

Frames: z = outward normal, x = material tangent (groove direction); ``wi`` and ``wo``
point from the surface to the source and to the observer; BRDF values in 1/sr.
"""

from .analysis import DHRResult, EnvelopeReport, envelope_report, hemispherical_reflectance
from .geometry import (
    half_diff,
    half_diff_to_directions,
    local_frame,
    local_to_world,
    mirror_direction,
    rotate_about_normal,
    spherical_to_vector,
    to_material_frame,
    vector_to_spherical,
    world_to_local,
)
from .history import HeatingResult, History, OxidationModel, ThinPlateHeating
from .models import (
    FR_MAX,
    BRDFModel,
    DynamicBRDF,
    Envelope,
    Lambertian,
    Scaled,
    Specular,
    SphericalHarmonicBRDF,
    Sum,
    TorranceSparrow5,
)
from .optics import fresnel_reflectance, optical_constants
from .scatter import ABg, GaussianLobe
from .tabulated import TabulatedBRDF
from .scattered import ScatteredBRDF
from .registry import available_models, create, dumps, load, loads, model_from_dict, register, save
from .sh import SHBasis, fan_out, real_sph_harm
from .states import StateTable
from .variability import VariabilityResult, sample_variability

try:  # one version source: hazard.__version__, read by pyproject.toml into the distribution's metadata
    from importlib.metadata import PackageNotFoundError as _NotInstalled, version as _dist_version

    __version__ = _dist_version("laser-hazard")
except _NotInstalled:  # a source tree that was never installed
    __version__ = "unknown"

__all__ = [
    "ABg", "BRDFModel", "DHRResult", "DynamicBRDF", "Envelope", "EnvelopeReport", "FR_MAX", "GaussianLobe", "HeatingResult",
    "History", "Lambertian", "OxidationModel", "SHBasis", "Scaled", "Specular", "SphericalHarmonicBRDF",
    "ScatteredBRDF", "StateTable", "TabulatedBRDF", "Sum", "ThinPlateHeating", "TorranceSparrow5", "available_models", "create", "dumps",
    "envelope_report", "fan_out", "fresnel_reflectance", "half_diff", "half_diff_to_directions",
    "hemispherical_reflectance", "load", "loads", "local_frame", "local_to_world", "mirror_direction",
    "model_from_dict", "optical_constants", "real_sph_harm", "register", "rotate_about_normal", "save",
    "spherical_to_vector", "to_material_frame", "vector_to_spherical", "world_to_local",
    "VariabilityResult", "sample_variability",
]
