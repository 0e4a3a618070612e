"""A readable summary of a loaded scene (``hazard validate``): the laser with its beam
convention and the 1/e values used, each target's shape and what its sizes mean, the
observers, and the values written with units, so that slips are visible before a run."""

from __future__ import annotations

from .conventions import beam_notes
from .quantities import as_written_lines

__all__ = ["shape_text", "summary_lines"]


def shape_text(spec) -> str:
    """What a target's (or occluder's) ``size_m`` means for its shape, in words with the values [m]."""
    s = spec.size_m or []
    f = [f"{x:.6g} m" for x in s]
    if spec.shape == "plate":
        return f"plate {f[0]} along tangent x {f[1]} across it (normal: the face's)"
    if spec.shape == "disk":
        return f"disk of diameter {f[0]} (normal: the face's)"
    if spec.shape == "box":
        return f"box {f[0]} along tangent x {f[1]} across x {f[2]} along normal"
    if spec.shape == "sphere":
        return f"sphere of diameter {f[0]}"
    if spec.shape == "cylinder":
        return f"cylinder of diameter {f[0]}, length {f[1]} along its axis = normal {list(spec.normal)}, centred on center_m"
    return f"mesh {spec.file!r} x scale {spec.scale:g} (its x along tangent, z along normal)"


def _laser_lines(scene) -> list:
    la = scene.spec.laser
    rec = scene.beam_conventions or {}
    power = (f"{la.power_w:.6g} W CW" if la.power_w is not None else
             f"{la.pulse_energy_j:.6g} J per pulse, {la.pulse_duration_s:.6g} s, {la.prf_hz:.6g} Hz ({la.average_power_w:.6g} W average)")
    d0, v0 = rec.get("beam_diameter_as_given_m"), rec.get("divergence_as_given_rad")
    dd, vd = rec.get("diameter_definition") or "1/e (default)", rec.get("divergence_definition") or "full_1/e (default)"
    given_d = f"{1e3 * d0:.6g} mm at {dd} -> " if isinstance(d0, (int, float)) and rec.get("diameter_factor") != 1.0 else f"at {dd}: "
    given_v = f"{1e3 * v0:.6g} mrad {vd} -> " if isinstance(v0, (int, float)) and rec.get("divergence_factor") != 1.0 else f"{vd}: "
    return [f"laser: {power}, {la.wavelength_nm:.6g} nm",
            f"  beam diameter {given_d}{1e3 * la.beam_diameter_m:.6g} mm (1/e, used)",
            f"  divergence {given_v}{1e3 * la.divergence_rad:.6g} mrad (1/e full angle, used)"]


def summary_lines(scene) -> list:
    """The summary as text lines: laser, exposure, targets (shape, sizes and their meaning),
    occluders, observers, values written with units and the beam-convention notes."""
    sp = scene.spec
    lines = _laser_lines(scene)
    lines.append(f"exposure: {sp.exposure.duration_s:.6g} s, {sp.exposure.standard}")
    for i, t in enumerate(sp.targets):
        lines.append(f"target {i} {t.name!r}: {shape_text(t)}; centre {list(t.center_m)} m")
    for i, o in enumerate(sp.occluders):
        lines.append(f"occluder {i} {o.name!r}: {shape_text(o)}")
    groups = ", ".join(f"{o.name} ({o.layout}, {o.n_points} point(s))" for o in sp.observers)
    lines.append(f"observers: {sum(o.n_points for o in sp.observers)} point(s)" + (f" in {groups}" if groups else ""))
    units = as_written_lines(scene)
    lines += (["written with units:"] + [f"  {u}" for u in units]) if units else ["written with units: none (SI keys)"]
    lines += beam_notes(scene.beam_conventions)
    return lines
