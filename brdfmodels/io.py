"""Readers of measured BRDF files into :class:`brdfmodels.screen.Samples` (so every fit,
``hazard fit sh|ts5|abg FILE``, takes them). Each reader names the file and the line of a
malformed entry.

- :func:`read_bsdf`: the Zemax / Radiant "BSDF data interchange" ASCII layout (``*.bsdf``;
  spec `range-safety.md` section 9, [C] Rykowski 2008, Zemax KB 229, libbsdf's
  ZemaxBsdfReader). Keywords case-insensitive: ``Symmetry`` (PlaneSymmetrical,
  Asymmetrical, Asymmetrical4D), ``SpectralContent`` (Monochrome only here),
  ``ScatterType`` (BRDF only), ``SampleRotation`` (one rotation: isotropic, as the
  OpticStudio DLL), ``AngleOfIncidence`` (a misnomer: the *specular* angle, deg),
  ``ScatterAzimuth`` and ``ScatterRadial`` (deg), then ``DataBegin``, per angle of
  incidence a ``TIS <value>`` line followed by nAzimuth x nRadial values (azimuth outer,
  radial inner), ``DataEnd``. The scattered direction is the specular direction turned
  by the radial angle, in the plane at the scatter azimuth; azimuth 0 points from the
  specular direction toward the sample normal. PlaneSymmetrical data (0-180 deg) are
  mirrored to the other half. Directions at or below the horizon are dropped.
- :func:`read_astm_e1392`: ASTM E1392-96 scatter tables ([C] libbsdf's AstmReader):
  ``NUM_POINTS <n>`` and ``VARS <names>`` header keywords, then comma-separated rows
  ``theta_i, phi_i, theta_s, phi_s`` [rad] and one BRDF column [1/sr] (read here as the
  spherical angles of the directions from the sample to the source and to the receiver;
  the standard's own text on the columns was not read). Duplicate angle tuples are
  skipped. Value columns named by their wavelengths (``532nm, 1064nm``: libbsdf's
  convention) or a ``wavelength_nm`` column of the rows select the laser's wavelength as
  the CSV's column does (``wavelength_nm``); other value columns beyond one (polarisations)
  are refused unless all but one are named in ``ignore_columns``; ``symmetry="plane"``
  mirrors one-sided data.
- :func:`read_merl`: MERL ``.binary`` (Matusik et al. 2003; the format of its reference
  reader BRDFRead.cpp): three int32 dimensions (90, 90, 180 for the database: theta_h,
  theta_d, phi_d), then each colour channel's values as float64 (R block, G block, B
  block), scaled by 1/1500, 1.15/1500, 1.66/1500. theta_h is sampled as
  ``index = sqrt(theta_h / (pi/2)) n_h``, theta_d and phi_d (over [0, pi): reciprocity)
  uniformly; negative values mark cells without data. Samples are taken at each cell's
  centre (phi_h = 0: isotropic), one channel or the channels' mean. MERL data are
  visible-light RGB: shapes of real lobes, not reflectances at a laser's wavelength.
- :func:`read_brdf_csv`: a documented generic CSV: columns ``theta_i_deg, phi_i_deg,
  theta_r_deg, phi_r_deg`` (spherical angles of the directions to the source and to the
  observer in the sample frame, z the normal, x the grooves) and exactly one value
  column, ``brdf_per_sr`` (BRDF [1/sr]) or ``reflectance_factor`` (R = pi f_r, converted
  as f_r = R / pi); optional ``time_s``, ``temperature_k``, ``test_id``, ``weight``;
  state columns ``extinction``, ``melt_fraction`` and ``state_<name>`` (into
  ``Samples.states``); ``wavelength_nm`` (the rows at the laser's wavelength, or the two
  nearest interpolated with a note, refused when ambiguous). Every other column is an
  error naming its position, unless listed in ``ignore_columns``. ``symmetry="plane"``
  mirrors data measured on one side of the plane of incidence.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np

from .fileio import check_limit, count_values, read_csv_columns, read_input_text
from .geometry import spherical_to_vector
from .screen import Samples

__all__ = ["read_bsdf", "read_astm_e1392", "read_brdf_csv", "read_merl", "merl_grid", "read_samples", "read_csv_columns",
           "MERL_SCALE", "mirror_plane_symmetric", "CSV_STATES"]


def _samples(wi, wo, f, test_id=None, time_s=None, temperature_k=None, weight=None):
    n = len(f)
    return Samples(np.asarray(wi, float), np.asarray(wo, float), np.asarray(f, float),
                   np.zeros(n) if time_s is None else np.asarray(time_s, float),
                   np.full(n, np.nan) if temperature_k is None else np.asarray(temperature_k, float),
                   np.array(["0"] * n) if test_id is None else np.asarray(test_id).astype(str),
                   np.zeros(n, int), np.ones(n) if weight is None else np.asarray(weight, float))


# -- Zemax / Radiant .bsdf -------------------------------------------------------------
_BSDF_LISTS = ("samplerotation", "angleofincidence", "scatterazimuth", "scatterradial")
# the header's other keywords (the format's: Source, Symmetry, SpectralContent, ScatterType, and the
# channel line before DataBegin, Monochrome or TristimulusX/Y/Z); anything else is no header line
_BSDF_WORDS = {"source": "Source", "symmetry": "Symmetry", "spectralcontent": "SpectralContent", "scattertype": "ScatterType",
               "monochrome": "Monochrome", "tristimulusx": "TristimulusX", "tristimulusy": "TristimulusY",
               "tristimulusz": "TristimulusZ"}


def _numbers(tokens, path, line_no, what, first_column=1):
    """The tokens as floats; the first that is not a number is named by its line and column
    (never quoted: an input file's contents stay out of error messages)."""
    out = []
    for j, t in enumerate(tokens):
        try:
            out.append(float(t))
        except ValueError:
            raise ValueError(f"{path}: line {line_no}, column {first_column + j}: {what}: expected a number") from None
    return out


def _count(tokens, path, line_no, what) -> int:
    """A header count: a whole number >= 1 (3.7 is refused, not truncated)."""
    if not tokens:
        return -1
    x = _numbers(tokens[:1], path, line_no, what, 2)[0]
    if not (math.isfinite(x) and x == int(x) and x >= 1):
        raise ValueError(f"{path}: line {line_no}, column 2: {what}: expected a whole number of values >= 1")
    return int(x)


# the angle lists of a .bsdf header: (name in messages, lowest, highest) [deg]
_BSDF_RANGES = {"samplerotation": ("SampleRotation", -360.0, 360.0), "angleofincidence": ("AngleOfIncidence", 0.0, 90.0),
                "scatterazimuth": ("ScatterAzimuth", 0.0, 360.0), "scatterradial": ("ScatterRadial", 0.0, 180.0)}


def _angles(vals, path, line_no, key) -> np.ndarray:
    """A header's angle list [deg], each finite and within its range (an incidence below 90)."""
    name, lo, hi = _BSDF_RANGES[key]
    a = np.array(_numbers(vals, path, line_no, name, 3))
    bad = ~(np.isfinite(a) & (a >= lo) & (a <= hi)) | ((a >= 90.0) if key == "angleofincidence" else False)
    if bad.any():
        j = int(np.flatnonzero(bad)[0])
        upper = "below 90" if key == "angleofincidence" else f"at most {hi:g}"
        raise ValueError(f"{path}: line {line_no}: {name}: angle {j + 1} of {len(a)} is {'not finite' if not np.isfinite(a[j]) else 'out of range'}; "
                         f"expected finite angles of {lo:g} to {upper} deg")
    return a


def _bsdf_header(lines, path):
    """Header keywords -> values, and the index of the line after ``DataBegin``. A keyword
    the format does not have (a damaged ``ScatterType`` was skipped and BRDF assumed) and
    a keyword given twice (the last was kept) are refused, naming the lines only."""
    head, i, seen = {}, 0, {}
    while i < len(lines):
        no, toks = lines[i]
        key = toks[0].lower()
        if key == "databegin":
            return head, i + 1
        if key in seen:
            raise ValueError(f"{path}: line {no}: {_BSDF_WORDS.get(key) or _BSDF_RANGES[key][0]} is given a second time "
                             f"(first on line {seen[key]}); expected each header keyword once")
        if key not in _BSDF_LISTS and key not in _BSDF_WORDS and not (key[0].isdigit() or key[0] in "+-."):
            raise ValueError(f"{path}: line {no}: not a keyword of the .bsdf header; expected one of "
                             f"{', '.join([*_BSDF_WORDS.values()][:4] + [_BSDF_RANGES[k][0] for k in _BSDF_LISTS])} or DataBegin")
        seen[key] = no
        if key in _BSDF_LISTS:
            name = _BSDF_RANGES[key][0]
            n = _count(toks[1:2], path, no, name)
            vals = toks[2:]
            while len(vals) < n and i + 1 < len(lines) and lines[i + 1][1][0].lower() not in _BSDF_LISTS + ("databegin",):
                i += 1
                vals += lines[i][1]
            if n < 1 or len(vals) != n:
                raise ValueError(f"{path}: line {no}: {name}: expected a count and that many angles")
            head[key] = _angles(vals, path, no, key)
        elif key[0].isdigit() or key[0] in "+-.":  # was dropped: a count smaller than the angles listed
            raise ValueError(f"{path}: line {no}: numbers outside a keyword's list; expected a keyword (is the count "
                             f"of the list above smaller than its angles?)")
        else:
            head[key] = " ".join(toks[1:])
        i += 1
    raise ValueError(f"{path}: no DataBegin line")


def _scatter_directions(theta_spec, az, rad):
    """Unit scattered directions (nAz, nRad, 3) about the specular direction at
    ``theta_spec`` [rad] in the x-z plane (incidence from +x: the source direction is
    (sin t, 0, cos t))."""
    s = np.array([-math.sin(theta_spec), 0.0, math.cos(theta_spec)])
    toward = np.array([0.0, 0.0, 1.0]) - s[2] * s  # from the specular direction toward the normal
    nt = np.linalg.norm(toward)
    e1 = toward / nt if nt > 1e-12 else np.array([1.0, 0.0, 0.0])
    e2 = np.cross(s, e1)
    a, r = np.meshgrid(az, rad, indexing="ij")
    return (np.cos(r)[..., None] * s + np.sin(r)[..., None] * (np.cos(a)[..., None] * e1 + np.sin(a)[..., None] * e2))


def _block_values(block, tokens, start, path) -> np.ndarray:
    """The values of a data block as floats; the first bad one named by its line and
    column (``tokens``: (line, column, text))."""
    try:
        v = np.array(block, dtype=float)
    except ValueError:
        v = None
    if v is None or not np.all(np.isfinite(v)) or np.any(v < 0):
        for j, x in enumerate(block):
            try:
                ok = math.isfinite(float(x)) and float(x) >= 0
            except ValueError:
                ok = False
            if not ok:
                no, col, _ = tokens[start + j]
                raise ValueError(f"{path}: line {no}, column {col}: data: expected a finite BRDF >= 0")
    return v


def read_bsdf(path):
    """Samples from a Zemax / Radiant ASCII ``.bsdf`` file (see the module notes)."""
    path = Path(path)
    text = read_input_text(path, "BSDF file")
    check_limit("TEXT_VALUES", count_values(text), f"{path}: values")  # before the split: 0.6 kB a value
    lines = [(k + 1, ln.split()) for k, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    head, i = _bsdf_header(lines, path)
    for key, name, want in (("spectralcontent", "SpectralContent", "Monochrome"), ("scattertype", "ScatterType", "BRDF")):
        if key not in head:  # was taken as BRDF: a BTDF (transmission) file whose ScatterType line was lost read as reflection
            raise ValueError(f"{path}: the header has no {name} line; expected {name} {want}")
        if head[key].lower() != want.lower():
            raise ValueError(f"{path}: {name}: only {want} data are read (expected {name} {want})")
    sym = head.get("symmetry", "").lower()
    if sym not in ("planesymmetrical", "asymmetrical", "asymmetrical4d"):
        raise ValueError(f"{path}: Symmetry: expected PlaneSymmetrical, Asymmetrical or Asymmetrical4D")
    if len(head.get("samplerotation", [0.0])) != 1:
        raise ValueError(f"{path}: SampleRotation: one rotation is read (isotropic samples)")
    for key in _BSDF_LISTS[1:]:
        if key not in head:
            raise ValueError(f"{path}: missing the {key} list")
    aoi, az, rad = (np.radians(head[k]) for k in _BSDF_LISTS[1:])
    tokens = [(no, j + 1, t) for no, toks in lines[i:] for j, t in enumerate(toks)]
    values = [t for _, _, t in tokens]
    wi, wo, f, tid = [], [], [], []
    pos = 0
    need = len(az) * len(rad)
    for t in aoi:
        if pos >= len(values) or values[pos].lower() != "tis":
            where = f"line {tokens[pos][0]}: " if pos < len(tokens) else ""
            raise ValueError(f"{path}: {where}expected 'TIS <value>' before the block of AngleOfIncidence {math.degrees(t):g} deg")
        tis = _numbers(values[pos + 1:pos + 2], path, tokens[pos][0], "TIS", tokens[pos][1] + 1)
        if len(tis) != 1 or not math.isfinite(tis[0]) or tis[0] < 0:  # unused, but NaN / inf / missing is no file
            raise ValueError(f"{path}: line {tokens[pos][0]}: TIS: expected a finite total integrated scatter >= 0")
        block = values[pos + 2:pos + 2 + need]
        if len(block) != need or any(x.lower() in ("tis", "dataend") for x in block):
            raise ValueError(f"{path}: line {tokens[pos][0]}: the block of AngleOfIncidence {math.degrees(t):g} deg holds "
                             f"fewer than {len(az)} x {len(rad)} values")
        v = _block_values(block, tokens, pos + 2, path).reshape(len(az), len(rad))
        pos += 2 + need
        d = _scatter_directions(t, az, rad)
        if sym == "planesymmetrical":  # mirror the 0-180 deg half
            d = np.concatenate([d, d * [1.0, -1.0, 1.0]])
            v = np.concatenate([v, v])
        keep = d[..., 2] > 0
        wo.append(d[keep])
        f.append(v[keep])
        wi.append(np.broadcast_to([math.sin(t), 0.0, math.cos(t)], (int(keep.sum()), 3)))
        tid += [f"aoi{math.degrees(t):g}"] * int(keep.sum())
    if values[pos:] and values[pos].lower() != "dataend":
        raise ValueError(f"{path}: line {tokens[pos][0]}, column {tokens[pos][1]}: expected DataEnd after the last block")
    if not values[pos:]:  # was accepted: a file cut at a block's end
        raise ValueError(f"{path}: the file ends after the last block without DataEnd (truncated?); expected DataEnd")
    if values[pos + 1:]:  # was ignored: a second set of blocks (two files joined) or anything else
        raise ValueError(f"{path}: line {tokens[pos + 1][0]}, column {tokens[pos + 1][1]}: data after DataEnd; "
                         "expected the file to end there")
    return _samples(np.vstack(wi), np.vstack(wo), np.concatenate(f), tid)


# -- ASTM E1392 -----------------------------------------------------------------------
def read_astm_e1392(path, *, wavelength_nm=None, ignore_columns=(), symmetry=None):
    """Samples from an ASTM E1392 scatter table (see the module notes).

    Parameters
    ----------
    path : path-like
    wavelength_nm : float, optional
        The laser's wavelength [nm]: with value columns named by their wavelength
        (``532nm, 1064nm``: libbsdf's convention) or a ``wavelength_nm`` column of the
        rows, the values measured there (within 0.5 nm), or the two nearest measured
        wavelengths interpolated linearly (a note in ``info["notes"]``); refused outside
        the measured wavelengths, and without ``wavelength_nm`` when the file holds several.
    ignore_columns : sequence of str
        VARS names (case-insensitive) to skip.
    symmetry : {"plane", "none"}, optional
        "plane": one-sided data mirrored about the plane of incidence
        (:func:`mirror_plane_symmetric`).
    """
    path = Path(path)
    names, a, notes = _astm_table(path, {c.strip().lower() for c in ignore_columns})
    by_wavelength = "wavelength_nm" in names or len(names) > 5 or (wavelength_nm is not None and _nm(names[4]) is not None)
    if "wavelength_nm" in names:  # a column of the rows: the CSV reader's selection
        d = {c: a[:, j] for j, c in enumerate(_ANGLES + ("brdf_per_sr", "wavelength_nm"))}
        d = _at_wavelength(path, d, wavelength_nm, notes)
        a = np.column_stack([d[c] for c in _ANGLES + ("brdf_per_sr",)])
    elif len(names) > 5 or (wavelength_nm is not None and _nm(names[4]) is not None):  # columns named by wavelength
        a = np.column_stack([a[:, :4], _astm_wavelength_column(path, names[4:], a[:, 4:], wavelength_nm, notes)])
    keep = (np.cos(a[:, 0]) > 0) & (np.cos(a[:, 2]) > 0)
    out = _samples(spherical_to_vector(a[keep, 0], a[keep, 1]), spherical_to_vector(a[keep, 2], a[keep, 3]), a[keep, 4])
    out.info["notes"] = notes
    out.info["by_wavelength"] = by_wavelength  # a wavelength column or columns named by wavelength
    return mirror_plane_symmetric(out) if _plane(path, symmetry) else _one_sided_note(out, symmetry)


_NM_NAME = re.compile(r"^\s*(?:brdf_?)?([0-9]+(?:\.[0-9]*)?(?:e[+-]?[0-9]+)?)\s*_?nm\s*$", re.IGNORECASE)


def _nm(name) -> float | None:
    """The wavelength [nm] a VARS value column's name gives (``1064nm``, ``brdf_1064nm``), else None."""
    m = _NM_NAME.match(name)
    return float(m.group(1)) if m else None


def _astm_vars(path, k, s, ignore):
    """The VARS names used (the four angles, then value columns; ``wavelength_nm`` of the
    rows last) and their indices among all the line's names."""
    names = [x.strip().lower() for x in (s.split(None, 1) + [""])[1].split(",")]
    if any(n in ignore for n in names[:4]):
        raise ValueError(f"{path}: line {k}: VARS: ignore_columns names one of the four angle columns; expected "
                         f"only value columns to skip")
    used = [j for j, n in enumerate(names) if n not in ignore and n != "wavelength_nm"]
    if "wavelength_nm" in names and "wavelength_nm" not in ignore:
        used.append(names.index("wavelength_nm"))
    vals = [names[j] for j in used[4:]]
    by_nm = [_nm(n) for n in vals]
    if len(used) < 5 or (len(vals) > 1 and not (all(x is not None for x in by_nm) or vals[1:] == ["wavelength_nm"])):
        raise ValueError(f"{path}: line {k}: VARS: expected five names used (theta_i, phi_i, theta_s, phi_s and one "
                         f"BRDF column: monochrome; several value columns are refused unless named by their wavelengths "
                         f"(532nm, 1064nm) or with a wavelength_nm column; name the others in ignore_columns), got "
                         f"{len(used)} of {len(names)}")
    if [names[j] for j in used[:4]] != ["theta_i", "phi_i", "theta_s", "phi_s"]:  # were read by position, whatever named
        raise ValueError(f"{path}: line {k}: VARS: expected the angle columns theta_i, phi_i, theta_s, phi_s first, in "
                         f"that order (the rows are read by position)")
    return [names[j] for j in used], used, len(names)


def _astm_table(path, ignore):
    """(the VARS names used, their rows (M, n) [rad, 1/sr, nm], notes) of an ASTM table;
    rows repeating another's angles (and wavelength) skipped, NUM_POINTS checked."""
    text = read_input_text(path, "ASTM E1392 file")
    check_limit("TEXT_VALUES", count_values(text), f"{path}: values")  # before any row is parsed
    n_points, names, rows, seen, n_rows, first = None, None, [], set(), 0, {}
    for k, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        key = s.split(None, 1)[0].upper()
        if key in first:  # the second was read over the first
            raise ValueError(f"{path}: line {k}: {key} is given a second time (first on line {first[key]}); expected it once")
        if key in ("NUM_POINTS", "VARS"):
            first[key] = k
        elif not (s[0].isdigit() or s[0] in "+-."):  # was skipped silently (a damaged NUM_POINTS: its check with it)
            raise ValueError(f"{path}: line {k}: not a header keyword or a data row; expected NUM_POINTS, VARS, numbers "
                             f"or a '#' comment")
        if key == "NUM_POINTS":
            n_points = _count(s.split()[1:2], path, k, "NUM_POINTS")
        elif key == "VARS":
            names, used, n_all = _astm_vars(path, k, s, ignore)
        elif s[0].isdigit() or s[0] in "+-.":
            cells = [x for x in s.split(",") if x.strip()]
            if names is None or len(cells) != n_all:
                raise ValueError(f"{path}: line {k}: expected {n_all if names else 'VARS before the'} columns")
            vals = _numbers([cells[j] for j in used], path, k, "data row")
            if not all(math.isfinite(v) for v in vals) or min(vals[4:]) < 0:
                raise ValueError(f"{path}: line {k}: data row: expected finite angles [rad] and finite BRDF values >= 0")
            bad = _angle_out_of_range(vals[:4], math.pi)
            if bad is not None:
                raise ValueError(f"{path}: line {k}, column {bad + 1}: data row: expected {_ANGLE_RANGES[bad % 2]} [rad]")
            n_rows += 1
            key_row = tuple(vals[:4]) + (tuple(vals[-1:]) if names[-1] == "wavelength_nm" else ())
            if key_row not in seen:
                seen.add(key_row)
                rows.append(vals)
    if names is None:
        raise ValueError(f"{path}: expected VARS with theta_i, phi_i, theta_s, phi_s and a BRDF column")
    if not rows:
        raise ValueError(f"{path}: no data rows")
    if n_points is not None and n_points != n_rows:
        raise ValueError(f"{path}: NUM_POINTS {n_points} but {n_rows} data rows")
    return names, np.array(rows), []


def _astm_wavelength_column(path, names, values, wavelength_nm, notes) -> np.ndarray:
    """The BRDF at the laser's wavelength from value columns named by their wavelengths
    (``values`` (M, n) [1/sr]): the column within 0.5 nm, or the two nearest interpolated
    linearly (said in ``notes``); refused outside them, or unnamed when several."""
    lams = np.array([_nm(n) for n in names])
    order = np.argsort(lams)
    lams, values = lams[order], values[:, order]
    listed = ", ".join(f"{x:g}" for x in lams)
    if wavelength_nm is None:
        if len(lams) > 1:
            raise ValueError(f"{path}: VARS: the file holds {len(lams)} wavelengths ({listed} nm); which one is ambiguous: "
                             f"expected the laser's wavelength (a scene gives its laser's; in Python "
                             f"read_samples(path, wavelength_nm=...); hazard fit --wavelength-nm) or one value column")
        return values[:, 0]
    lam = float(wavelength_nm)
    near = np.abs(lams - lam) <= WAVELENGTH_MATCH_NM
    if near.any():
        return values[:, int(np.argmin(np.abs(lams - lam)))]
    if not lams[0] < lam < lams[-1]:
        raise ValueError(f"{path}: VARS: the laser's {lam:g} nm is outside the measured wavelengths ({listed} nm); "
                         f"expected a file measured at or around it")
    j = int(np.searchsorted(lams, lam))
    t = (lam - lams[j - 1]) / (lams[j] - lams[j - 1])
    notes.append(f"{path.name}: f_r interpolated linearly between the measured {lams[j - 1]:g} and {lams[j]:g} nm to the "
                 f"laser's {lam:g} nm (weight {t:.3g} on {lams[j]:g} nm)")
    return (1 - t) * values[:, j - 1] + t * values[:, j]


# -- generic CSV ---------------------------------------------------------------------
_ANGLES = ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")
_ANGLE_RANGES = ("a polar angle from 0 to pi", "an azimuth from -2 pi to 2 pi")
_ANGLE_RANGES_DEG = ("a polar angle from 0 to 180 deg", "an azimuth from -360 to 360 deg")


def _angle_out_of_range(angles, half_turn) -> int | None:
    """Index of the first of (theta, phi, theta, phi) that is no spherical angle (a polar
    angle outside [0, half turn], an azimuth outside [-2, 2] half turns; 1e-9 of a half turn
    of rounding allowed), else None. An angle of 1e308 rad or deg gave a garbage direction."""
    tol = 1e-9 * half_turn
    for j, a in enumerate(angles):
        if (j % 2 == 0 and not -tol <= a <= half_turn + tol) or (j % 2 == 1 and not abs(a) <= 2 * half_turn + tol):
            return j
    return None


_CSV_FIXED = ("test_id", "time_s", "temperature_k", "weight", "wavelength_nm")
CSV_STATES = ("extinction", "melt_fraction")  # state columns by name; any other as state_<name>
WAVELENGTH_MATCH_NM = 0.5  # a measured wavelength this close to the laser's is the laser's


def _csv_header(path, cols, ignore):
    """The value column of a generic CSV header; each column known, ignored or refused."""
    missing = [c for c in _ANGLES if c not in cols]
    value = [c for c in ("brdf_per_sr", "reflectance_factor") if c in cols]
    if missing or len(value) != 1:
        raise ValueError(f"{path}: line 1: expected columns {list(_ANGLES)} and one of brdf_per_sr or reflectance_factor"
                         f"{'; missing ' + ', '.join(missing) if missing else ''} (the header has {len(cols)} column(s))")
    needed = [c for c in ignore if c in _ANGLES or c in value]
    if needed:
        raise ValueError(f"ignore_columns: {needed[0]} is a column this reader needs; expected only columns to skip")
    for j, c in enumerate(cols):
        known = c in _ANGLES or c in value or c in _CSV_FIXED or c in CSV_STATES or c in ignore
        if not known and not (c.startswith("state_") and len(c) > 6):
            raise ValueError(f"{path}: line 1, column {j + 1}: not a column this reader uses; expected "
                             f"{', '.join(_ANGLES)}, one value column (brdf_per_sr or reflectance_factor), "
                             f"{', '.join(_CSV_FIXED + CSV_STATES)} or state_<name>; a column to skip goes in ignore_columns")
        if cols.count(c) > 1 and c not in ignore:
            name = c if c in _ANGLES + _CSV_FIXED + CSV_STATES + ("brdf_per_sr", "reflectance_factor") else j + 1
            raise ValueError(f"{path}: line 1: column {name} appears {cols.count(c)} times; expected once")
    return value[0]


def read_brdf_csv(path, *, wavelength_nm=None, ignore_columns=(), symmetry=None):
    """Samples from the generic angle CSV (see the module notes).

    Parameters
    ----------
    path : path-like
    wavelength_nm : float, optional
        The laser's wavelength: with a ``wavelength_nm`` column, the rows measured there
        (within 0.5 nm), or the two nearest measured wavelengths interpolated linearly
        (a note in ``info["notes"]``); refused outside the measured range, and without
        ``wavelength_nm`` when the file holds several.
    ignore_columns : sequence of str
        Columns to skip (any other unknown column is an error naming its position).
    symmetry : {"plane", "none"}, optional
        "plane": the data are one side of the plane of incidence; mirrored to the other.
    """
    path = Path(path)
    text = read_input_text(path, "BRDF CSV")
    check_limit("CSV_ROWS", text.count("\n") + 1, f"{path}: lines")  # before any row is parsed
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise ValueError(f"{path}: empty file")
    cols = [c.strip() for c in rows[0]]
    ignore = set(ignore_columns)
    value = _csv_header(path, cols, ignore)
    idx = {c: cols.index(c) for c in cols}
    body = [(k, r) for k, r in enumerate(rows[1:], start=2) if any(x.strip() for x in r)]
    short = next(((k, r) for k, r in body if len(r) != len(cols)), None)
    if short is not None:
        raise ValueError(f"{path}: line {short[0]}: {len(short[1])} cells, expected {len(cols)}")
    if not body:
        raise ValueError(f"{path}: no data rows")
    d = {c: _csv_column(path, body, idx[c], c) for c in cols if c != "test_id" and c not in ignore}
    d["test_id"] = np.array([r[idx["test_id"]] if "test_id" in idx else "0" for _, r in body])
    notes = []
    by_wavelength = "wavelength_nm" in d
    if by_wavelength:
        d = _at_wavelength(path, d, wavelength_nm, notes)
    f = d[value] / (math.pi if value == "reflectance_factor" else 1.0)
    wi = spherical_to_vector(np.radians(d["theta_i_deg"]), np.radians(d["phi_i_deg"]))
    wo = spherical_to_vector(np.radians(d["theta_r_deg"]), np.radians(d["phi_r_deg"]))
    states = {c[6:] if c.startswith("state_") else c: d[c] for c in d if c in CSV_STATES or c.startswith("state_")}
    s = _samples(wi, wo, f, d["test_id"], d.get("time_s"), d.get("temperature_k"), d.get("weight"))
    s = s.with_states(states) if states else s
    s.info["notes"] = notes
    s.info["by_wavelength"] = by_wavelength  # rows chosen by their wavelength (else the file names none)
    return mirror_plane_symmetric(s) if _plane(path, symmetry) else _one_sided_note(s, symmetry)


def _csv_column(path, body, j, c) -> np.ndarray:
    """Column ``j`` (named ``c``) of the rows ``body`` as finite numbers, each angle within
    its range; the first bad cell named by its line and column."""
    try:
        v = np.array([r[j] for _, r in body], dtype=float)
        ok = np.isfinite(v)
        if c in _ANGLES:
            ok &= ((v >= -1.8e-7) & (v <= 180.0 + 1.8e-7)) if c.startswith("theta") else (np.abs(v) <= 360.0 + 1.8e-7)
    except ValueError:
        ok = None
    if ok is None or not ok.all():
        for k, r in body:
            _csv_cell(path, k, j, c, r[j])
    return v


def _csv_cell(path, k, j, c, text) -> float:
    """One cell of a generic CSV as a finite number (an angle within its range)."""
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{path}: line {k}, column {j + 1} ({c}): expected a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{path}: line {k}, column {j + 1} ({c}): expected a finite number")
    if c in _ANGLES and _angle_out_of_range([v] if c.startswith("theta") else [0.0, v], 180.0) is not None:
        raise ValueError(f"{path}: line {k}, column {j + 1} ({c}): expected {_ANGLE_RANGES_DEG[c.startswith('phi')]}")
    return v


def _plane(path, symmetry) -> bool:
    if symmetry not in (None, "none", "plane"):
        raise ValueError(f"symmetry={symmetry!r}: expected 'plane' or 'none'")
    return symmetry == "plane"


def _at_wavelength(path, d, wavelength_nm, notes) -> dict:
    """The columns ``d`` at the laser's wavelength (module notes of :func:`read_brdf_csv`)."""
    w = d["wavelength_nm"]
    have = np.unique(w)
    listed = ", ".join(f"{x:g}" for x in have[:6]) + (" ..." if len(have) > 6 else "")
    if wavelength_nm is None:
        if len(have) > 1:
            raise ValueError(f"{path}: wavelength_nm: the file holds {len(have)} wavelengths ({listed} nm); which one is "
                             f"ambiguous: expected the laser's wavelength (a scene gives its laser's; in Python "
                             f"read_samples(path, wavelength_nm=...); hazard fit --wavelength-nm) or a file of one wavelength")
        return d
    lam = float(wavelength_nm)
    near = np.abs(have - lam) <= WAVELENGTH_MATCH_NM
    if near.any():
        return {c: v[w == have[near][np.argmin(np.abs(have[near] - lam))]] for c, v in d.items()}
    if not have[0] < lam < have[-1]:
        raise ValueError(f"{path}: wavelength_nm: the laser's {lam:g} nm is outside the measured wavelengths ({listed} nm); "
                         f"expected a file measured at or around it")
    lo, hi = have[have < lam][-1], have[have > lam][0]
    t = (lam - lo) / (hi - lo)
    a, b = ({c: v[w == x] for c, v in d.items()} for x in (lo, hi))
    order = [np.lexsort(np.round([x[c] for c in _ANGLES], 9)[::-1]) for x in (a, b)]
    keys = [np.round(np.column_stack([x[c] for c in _ANGLES]), 9)[o] for x, o in zip((a, b), order)]
    if keys[0].shape != keys[1].shape or np.any(keys[0] != keys[1]):
        raise ValueError(f"{path}: wavelength_nm: the laser's {lam:g} nm lies between the measured {lo:g} and {hi:g} nm, "
                         f"whose rows are not at the same angles; expected the same angles at both to interpolate")
    out = {c: v[order[0]] for c, v in a.items()}
    for c in ("brdf_per_sr", "reflectance_factor"):
        if c in out:
            out[c] = (1 - t) * a[c][order[0]] + t * b[c][order[1]]
    notes.append(f"{path.name}: f_r interpolated linearly between the measured {lo:g} and {hi:g} nm to the laser's "
                 f"{lam:g} nm (weight {t:.3g} on {hi:g} nm)")
    return out


def _one_sided_note(s, symmetry):
    """``s``, with a note when no symmetry was declared and every sample off its plane of
    incidence lies on one side of it (a half-plane measurement): the other side is then
    interpolated across the plane, not measured (issue 32: 0.97-1.20 of a symmetric truth
    there), so the reader is told to declare ``symmetry = "plane"`` if it holds."""
    if symmetry is not None:
        return s
    side = s.wi[:, 0] * s.wo[:, 1] - s.wi[:, 1] * s.wo[:, 0]  # z . (wi x wo): which side of the plane of incidence
    off = np.abs(side) > 1e-9
    above, below = int(np.sum(side[off] > 0)), int(np.sum(side[off] < 0))
    if min(above, below) == 0 and max(above, below) >= 3:
        s.info["notes"] = list(s.info.get("notes", ())) + [
            f"all {max(above, below)} samples off their plane of incidence lie on one side of it: the other side is "
            f"interpolated across the plane, not measured; declare symmetry = \"plane\" if the material is plane-symmetric "
            f"(or symmetry = \"none\" to say it is not)"]
    return s


def mirror_plane_symmetric(s):
    """Samples with each one's mirror image about its plane of incidence added (data
    declared plane-symmetric: measured on one side only). Returns new Samples."""
    u = np.column_stack([s.wi[:, 0], s.wi[:, 1], np.zeros(len(s))])
    n = np.linalg.norm(u, axis=1, keepdims=True)
    u = np.where(n > 1e-12, u / np.where(n > 1e-12, n, 1.0), [1.0, 0.0, 0.0])  # normal incidence: the x-z plane
    z = np.array([0.0, 0.0, 1.0])
    wo = 2 * np.sum(s.wo * u, axis=1, keepdims=True) * u + 2 * s.wo[:, 2:3] * z - s.wo
    mirrored = Samples(s.wi, wo, s.brdf_per_sr, s.time_s, s.temperature_k, s.test_id, s.frame_id, s.weight, dict(s.info),
                       dict(s.states))
    out = Samples.concatenate([s, mirrored])
    out.info.update(s.info)
    return out


MERL_SCALE = {"R": 1.0 / 1500.0, "G": 1.15 / 1500.0, "B": 1.66 / 1500.0}


def _merl_table(path):
    """(dims (3,), raw channel values (3, n)) of a MERL ``.binary`` file, its size checked
    against the header."""
    from .fileio import check_input_file

    path = check_input_file(path, "MERL file")
    raw = path.read_bytes()
    if len(raw) < 12:
        raise ValueError(f"{path}: not a MERL file (shorter than its 12-byte header)")
    dims = np.frombuffer(raw[:12], dtype="<i4")
    n = int(np.prod(dims.astype(np.int64)))
    if np.any(dims < 1) or len(raw) != 12 + 3 * 8 * n:  # the dims are not quoted: they are the file's first 12 bytes
        raise ValueError(f"{path}: not a MERL file of the size its header gives (12 + 24 n_h n_d n_phi bytes; the file has "
                         f"{len(raw)})")
    return tuple(int(x) for x in dims), np.frombuffer(raw[12:], dtype="<f8").reshape(3, n)


def merl_grid(path, channel="mean"):
    """The cells of a MERL ``.binary`` file: their centres (theta_h_deg, theta_d_deg,
    phi_d_deg; theta_h on the square-root scale) and f_r [1/sr] (n_h, n_d, n_phi) of
    ``channel`` ("R", "G", "B" or "mean"), NaN where a used channel has no data."""
    if channel not in ("R", "G", "B", "mean"):
        raise ValueError(f"channel={channel!r}: expected R, G, B or mean")
    dims, data = _merl_table(path)
    used = [0, 1, 2] if channel == "mean" else ["RGB".index(channel)]
    v = sum(data[k] * MERL_SCALE["RGB"[k]] for k in used) / len(used)
    v = np.where(np.all(data[used] >= 0, axis=0) & np.isfinite(v), v, np.nan)  # negative: no data in that cell
    nh, nd, nphi = dims
    nodes = (((np.arange(nh) + 0.5) / nh) ** 2 * 90.0, (np.arange(nd) + 0.5) / nd * 90.0, (np.arange(nphi) + 0.5) / nphi * 180.0)
    return nodes, v.reshape(dims)


def read_merl(path, channel="mean"):
    """Samples from a MERL ``.binary`` file (see the module notes); ``channel``: "R",
    "G", "B" or "mean"."""
    from .geometry import half_diff_to_directions

    nodes, v = merl_grid(path, channel)
    th, td, pd = (np.radians(g).ravel() for g in np.meshgrid(*nodes, indexing="ij"))
    wi, wo = half_diff_to_directions(th, np.zeros(th.size), td, pd)
    v = v.ravel()
    keep = np.isfinite(v) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
    return _samples(wi[keep], wo[keep], v[keep])


def read_samples(path, *, wavelength_nm=None, ignore_columns=(), symmetry=None):
    """Measured samples by the file's form: ``.bsdf`` (Zemax), ``.astm`` / ``.e1392``
    (ASTM E1392), ``.binary`` (MERL, the channels' mean), a CSV with ``theta_i_deg`` columns (generic), else this package's own
    samples CSV / Parquet (:meth:`brdfmodels.screen.Samples.read`). ``wavelength_nm``
    (the laser's), ``ignore_columns`` and ``symmetry`` as :func:`read_brdf_csv` takes
    them (a ``.bsdf`` declares its symmetry in its header: ``symmetry`` is refused there)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".bsdf", ".binary") and (symmetry not in (None, "none") or ignore_columns):
        raise ValueError(f"{p}: symmetry and ignore_columns are for CSV and ASTM files; a {suffix} file declares its own layout")
    if suffix == ".bsdf":
        return read_bsdf(p)
    if suffix in (".astm", ".e1392"):
        return read_astm_e1392(p, wavelength_nm=wavelength_nm, ignore_columns=ignore_columns, symmetry=symmetry)
    if suffix == ".binary":
        return read_merl(p)
    if suffix == ".csv":
        first = read_input_text(p, "samples").split("\n", 1)[0]
        if "theta_i_deg" in first:
            return read_brdf_csv(p, wavelength_nm=wavelength_nm, ignore_columns=ignore_columns, symmetry=symmetry)
    return Samples.read(p)
