"""A small library of materials with provenance: ``material(name, wavelength_nm)``.

Every entry says where its numbers come from and at which wavelength they hold:

- the five-parameter fits of Zhang et al. (Optica Applicata 40(1), 2010; spec
  `five-parameter-brdf.md`, "Published fits"), measured at 1.06 um: white spray paint on
  aluminium, cement plate, khaki-painted forged steel, bare forged steel, polyimide film.
  The polyimide fit has kd = 2.267 /sr (pi kd = 7.1: its hemispherical reflectance
  exceeds 1), a fit artefact the paper reports as is: listed, and refused by scenes like
  any material that returns more than it receives;
- ideal Lambertian panels (reflectance 0.99, 0.5, 0.05: a diffuse reference panel, a grey
  card, a black panel; exact by definition);
- Fresnel mirrors of the bundled optical constants (``brdfmodels/data``: Cu, Al; their
  provenance is in each file's first line), at the laser's wavelength.
"""

from __future__ import annotations

from dataclasses import dataclass

from .models import Lambertian, Specular, TorranceSparrow5

__all__ = ["LibraryEntry", "LIBRARY", "entry", "material", "library_names"]

ZHANG_2010 = "Zhang et al., Optica Applicata 40(1), 2010, tables of fitted parameters (1.06 um; spec five-parameter-brdf.md)"


@dataclass(frozen=True)
class LibraryEntry:
    """A material: its kind (``ts5``, ``lambertian``, ``fresnel``), parameters, where
    they come from, the wavelength they hold at (None: any) and a note."""

    kind: str
    params: dict
    source: str
    wavelength_nm: float | None
    note: str = ""

    def build(self, wavelength_nm: float | None = None):
        if self.kind == "ts5":
            return TorranceSparrow5(**self.params)
        if self.kind == "lambertian":
            return Lambertian(**self.params)
        if wavelength_nm is None:
            raise ValueError(f"a Fresnel mirror of {self.params['table']!r} needs the laser's wavelength_nm")
        return Specular.for_material(self.params["table"], wavelength_nm)


LIBRARY = {
    "white-paint": LibraryEntry("ts5", dict(kb=5.708, kr=2.240, a=0.452, b=-58.722, kd=0.220), ZHANG_2010, 1060.0,
                                "aluminium with white spray paint; fit error E 4.17 %; model DHR 73.4 % at normal incidence "
                                "(integrating sphere 79.6 %)"),
    "cement": LibraryEntry("ts5", dict(kb=0.003, kr=2.961, a=15.572, b=-18.301, kd=0.067), ZHANG_2010, 1060.0,
                           "cement plate; fit error E 5.98 %"),
    "khaki-painted-steel": LibraryEntry("ts5", dict(kb=0.0698, kr=0.478, a=0.777, b=-28.935, kd=0.107), ZHANG_2010, 1060.0,
                                        "forged steel with khaki paint; fit error E 0.69 %"),
    "forged-steel": LibraryEntry("ts5", dict(kb=0.072, kr=16.125, a=0.959, b=-29.917, kd=0.081), ZHANG_2010, 1060.0,
                                 "bare forged steel; fit error E 0.95 %"),
    "polyimide": LibraryEntry("ts5", dict(kb=5.439, kr=3.257, a=0.495, b=-23.098, kd=2.267), ZHANG_2010, 1060.0,
                              "polyimide film; fit error E 10.1 %; NOT physical: kd = 2.267 /sr gives a hemispherical "
                              "reflectance above 1 (refused in scenes)"),
    "lambertian-0.99": LibraryEntry("lambertian", dict(reflectance=0.99), "ideal diffuse reference panel (definition)", None),
    "lambertian-0.5": LibraryEntry("lambertian", dict(reflectance=0.5), "ideal grey card (definition)", None),
    "lambertian-0.05": LibraryEntry("lambertian", dict(reflectance=0.05), "ideal black panel (definition)", None),
    "copper-mirror": LibraryEntry("fresnel", dict(table="cu"), "Fresnel (Born & Wolf 1.5.2) with the bundled Cu n, k table "
                                  "(brdfmodels/data/cu_nk.csv)", None, "polished copper, 300-1700 nm"),
    "aluminium-mirror": LibraryEntry("fresnel", dict(table="al"), "Fresnel (Born & Wolf 1.5.2) with the bundled Al n, k table "
                                     "(McPeak et al. 2015, brdfmodels/data/al_nk.csv)", None, "polished aluminium, 150-1700 nm"),
}


def library_names() -> list:
    return sorted(LIBRARY)


def entry(name: str) -> LibraryEntry:
    """The library's entry ``name``; ValueError listing the names otherwise."""
    if name not in LIBRARY:
        raise ValueError(f"library={name!r}: expected one of {library_names()}")
    return LIBRARY[name]


def material(name: str, wavelength_nm: float | None = None):
    """The library's model ``name`` (at ``wavelength_nm`` for Fresnel mirrors)."""
    return entry(name).build(wavelength_nm)
