"""CSV text of result columns, shared by observers.csv (:mod:`hazard.outputs.report`) and the
moving observers' track_<name>.csv (:mod:`hazard.outputs.motion_outputs`): exact float reprs and
the geodetic columns of scenes with a ``[site]``. Below both (no import of either)."""

from __future__ import annotations

import numpy as np

__all__ = ["GEO_COLUMNS", "column_text", "observer_geodetic"]


def column_text(values, blank_nan: bool = False) -> list:
    """One column as CSV text: floats by repr (exact round trip; NaN an empty cell with
    ``blank_nan``, where it means "not applicable"), bools as True/False. The reprs are
    made by the list's own repr (one C loop, the same strings as ``repr`` of each value)."""
    values = np.asarray(values)
    if not len(values):
        return []
    if values.dtype == bool:
        return repr(values.tolist())[1:-1].split(", ")
    v = values.astype(float)
    text = _reprs(v)
    if blank_nan:
        nan = np.isnan(v)
        if nan.all():
            return [""] * len(v)
        for i in np.flatnonzero(nan).tolist():
            text[i] = ""
    return text


def _reprs(v: np.ndarray) -> list:
    """``[repr(x) for x in v.tolist()]`` of a float64 column: a value repeated through it
    (grid coordinates, a constant MPE) formatted once (values told apart by their bits:
    -0.0 is not 0.0)."""
    bits = np.ascontiguousarray(v, float).view(np.int64)
    if not len(v) or len(np.unique(bits[:256])) * 10 > 9 * min(len(v), 256):  # mostly distinct: every value formatted
        return repr(v.tolist())[1:-1].split(", ") if len(v) else []
    _, first, inv = np.unique(bits, return_index=True, return_inverse=True)
    text = repr(v[first].tolist())[1:-1].split(", ")
    return [text[i] for i in inv.ravel().tolist()]


GEO_COLUMNS = ["lat_deg", "lon_deg", "height_m"]  # after z_m, in scenes with a [site]


def observer_geodetic(result, pos) -> np.ndarray:
    """(M, 3) latitude, longitude [deg] and height in the site's vertical datum [m] of the
    observers at world ``pos``: the true positions, the apparent refraction rise of the
    analysis frame (:mod:`scenes.geo`) taken off."""
    frame = result.scene.site.frame
    true = pos.copy()
    true[:, 2] -= frame.refraction_rise_m(pos[:, 0], pos[:, 1])
    lat, lon, h = frame.geodetic(true)
    return np.column_stack([lat, lon, frame.datum_height_m(lat, lon, h)])
