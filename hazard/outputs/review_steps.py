"""Every number with its steps on the review page (``hazard report``): the formulas of
:mod:`hazard.physics.nohd` with the scene's numbers substituted, each step's result, and the value
report.json holds.

- Direct beam (the LSDZ's NOHD, ``sdz.nohd_m``, and through each aid): ANSI Z136.1 eq. B,
  ``E(R) = 4 K P exp(-mu R) / (pi (a + R phi)^2) = MPE``, ``D0 = sqrt(4 K P / (pi MPE))``;
  ``NOHD = (D0 - a) / phi`` without attenuation, else ``((2 phi / mu) W(z) - a) / phi``
  with ``z = (mu D0 / 2 phi) exp(mu a / 2 phi)`` (Lambert W, principal branch).
- The FAA distances (``visual_interference.direct``): the same formula with the level
  ``E_lim / VCF`` in place of the MPE (range-safety.md section 5).
- A target's reflected lobe (``targets[].keepout_static`` / ``keepout_dynamic``): the
  point-source form ``I exp(-mu R) / R^2 = MPE`` with ``I = f_r cos(theta_r) P`` toward the
  lobe's farthest direction, ``R0 = sqrt(I / MPE)``, ``R = (2 / mu) W(mu R0 / 2)``.
- An observer (the ten highest hazard ratios and any named): the peak irradiance as the
  direct beam plus the reflected peak, and the hazard ratio E / MPE.

Numbers are written with 10 significant digits so that a reader (and the test) can redo
each step from the page alone; each step's result is computed here from the numbers
shown (plain math, no engine call) and set beside the value report.json holds. A
difference above 1e-6 relative is said on the page in capitals.
"""

from __future__ import annotations

import math

from hazard.physics.nohd import log_lambertw_exp

__all__ = ["steps_section", "direct_steps", "lobe_steps", "observer_steps", "analysed_times_text", "STEPS_OBSERVERS"]

STEPS_OBSERVERS = 10  # observers with their steps: the highest hazard ratios (and any named)
AGREE_RTOL = 1e-6


def g(x) -> str:
    """A number as the steps write it: 10 significant digits (``inf`` as ``inf``)."""
    x = float(x)
    return "inf" if math.isinf(x) else f"{x:.10g}"


def _check(computed: float, reported, key: str) -> dict:
    """The last line: the value report.json holds beside the one redone from the steps."""
    rep = None if reported is None else float(reported)
    if rep is None:
        return {"text": f"report.json {key}: not given", "agrees": None}
    same = (computed == rep) or (math.isfinite(rep) and abs(computed - rep) <= AGREE_RTOL * max(abs(rep), 1e-300))
    text = f"report.json {key} = {g(rep)}" + ("" if same else f": DIFFERS from the steps' {g(computed)} (relative tolerance 1e-6)")
    return {"text": text, "agrees": bool(same)}


def _beam_range(d0: float, a: float, phi: float, mu: float) -> tuple[float, list]:
    """The direct-beam range [m] and its steps after D0 (:func:`hazard.physics.nohd.nohd_direct`)."""
    if d0 <= a:
        return 0.0, [f"D0 = {g(d0)} m <= a = {g(a)} m: the irradiance at the aperture is at or below the limit, NOHD = 0 m"]
    if phi == 0.0:
        if mu == 0.0:
            return math.inf, ["phi = 0 and mu = 0: the beam never falls below the limit, NOHD = inf"]
        r = 2.0 * math.log(d0 / a) / mu
        return r, [f"collimated: NOHD = 2 ln(D0 / a) / mu = 2 ln({g(d0)} / {g(a)}) / {g(mu)} = {g(r)} m"]
    if mu == 0.0:
        r = (d0 - a) / phi
        return r, [f"NOHD = (D0 - a) / phi = ({g(d0)} - {g(a)}) / {g(phi)} = {g(r)} m"]
    log_z = math.log(mu * d0 / (2.0 * phi)) + mu * a / (2.0 * phi)
    w = math.exp(log_lambertw_exp(log_z))
    r = max(2.0 * phi / mu * w - a, 0.0) / phi
    z = f"{g(math.exp(log_z))}" if log_z < 700 else f"exp({g(log_z)})"
    return r, [f"z = (mu D0 / (2 phi)) exp(mu a / (2 phi)) = ({g(mu)} * {g(d0)} / (2 * {g(phi)})) * exp({g(mu)} * {g(a)} / "
               f"(2 * {g(phi)})) = {z}",
               f"W(z) = {g(w)} (Lambert W, principal branch: W e^W = z)",
               f"NOHD = ((2 phi / mu) W(z) - a) / phi = ((2 * {g(phi)} / {g(mu)}) * {g(w)} - {g(a)}) / {g(phi)} = {g(r)} m"]


def direct_steps(title: str, p_w: float, limit_w_m2: float, a_m: float, phi_rad: float, mu_per_m: float, k: float,
                 reported, key: str, limit_name: str = "MPE") -> dict:
    """The direct-beam formula (ANSI Z136.1 eq. B) with the numbers substituted; ``limit_name``
    names the irradiance the range is to (the MPE, or an FAA level E_lim / VCF)."""
    d0 = math.sqrt(4.0 * k * p_w / (math.pi * limit_w_m2))
    lines = [f"E(R) = 4 K P exp(-mu R) / (pi (a + R phi)^2) = {limit_name}",
             f"P = {g(p_w)} W, {limit_name} = {g(limit_w_m2)} W/m², a = {g(a_m)} m (1/e), phi = {g(phi_rad)} rad (1/e), "
             f"mu = {g(mu_per_m)} 1/m, K = {g(k)}",
             f"D0 = sqrt(4 K P / (pi {limit_name})) = sqrt(4 * {g(k)} * {g(p_w)} / (pi * {g(limit_w_m2)})) = {g(d0)} m"]
    r, more = _beam_range(d0, a_m, phi_rad, mu_per_m)
    return {"title": title, "lines": lines + more, "result_m": r, "check": _check(r, reported, key), "key": key}


def lobe_steps(title: str, lobe: dict, mpe_w_m2: float, mu_per_m: float, key: str, gain: float = 1.0, reported=None) -> dict:
    """A reflected lobe's NOHD from its peak radiant intensity (``keepout_*``), or why there
    is no closed-form step; through an optical aid (``gain`` K, ``reported`` the aid's
    NOHD) the ENOHD, K I in place of I (ANSI Z136.1 B5: the aid collects K times the
    eye's power)."""
    i_w_sr, p_w = lobe.get("peak_intensity_w_sr"), lobe.get("power_w")
    reported = lobe.get("max_nohd_m") if reported is None else reported
    if i_w_sr is None:
        why = ("report.json holds no peak intensity for it (a report of an older version, a lobe that reaches nothing, "
               "or a slumping spot whose NOHD is the union over its surface normals)")
        said = "not given" if reported is None else f"{g(reported)} m"
        return {"title": title, "lines": [f"no closed-form step: {why}"], "result_m": None,
                "check": {"text": f"report.json {key} = {said}", "agrees": None}, "key": key}
    lines = ["I exp(-mu R) / R^2 = MPE, I = f_r cos(theta_r) P: the lobe's radiant intensity toward its farthest direction"]
    fr = f", f_r cos(theta_r) = I / P = {g(i_w_sr / p_w)} 1/sr" if p_w else ""
    lines.append(f"P = {g(p_w) if p_w is not None else 'not given'} W (the spot's power), I = {g(i_w_sr)} W/sr{fr}, "
                 f"MPE = {g(mpe_w_m2)} W/m², mu = {g(mu_per_m)} 1/m")
    if gain != 1.0:
        lines[0] = "K I exp(-mu R) / R^2 = MPE, I = f_r cos(theta_r) P: the lobe's radiant intensity toward its farthest direction"
        lines.append(f"K = {g(gain)} (the aid's gain), K I = {g(gain)} * {g(i_w_sr)} = {g(gain * i_w_sr)} W/sr")
    r0 = math.sqrt(gain * i_w_sr / mpe_w_m2)
    lines.append(f"R0 = sqrt(I / MPE) = sqrt({g(i_w_sr)} / {g(mpe_w_m2)}) = {g(r0)} m" if gain == 1.0 else
                 f"R0 = sqrt(K I / MPE) = sqrt({g(gain * i_w_sr)} / {g(mpe_w_m2)}) = {g(r0)} m")
    if mu_per_m == 0.0 or r0 == 0.0:
        r = r0
        lines.append(f"mu = 0: NOHD = R0 = {g(r)} m")
    else:
        zz = mu_per_m * r0 / 2.0
        w = math.exp(log_lambertw_exp(math.log(zz)))
        r = 2.0 / mu_per_m * w
        lines.append(f"NOHD = (2 / mu) W(mu R0 / 2) = (2 / {g(mu_per_m)}) * W({g(mu_per_m)} * {g(r0)} / 2) = "
                     f"(2 / {g(mu_per_m)}) * {g(w)} = {g(r)} m")
    near = lobe.get("near_field") or {}
    if near.get("directions_raised") and reported is not None and float(reported) > r * (1.0 + AGREE_RTOL):
        lines.append(f"near the spot the far-field form is short: the lobe is the farthest root of the integral over the "
                     f"spot (hazard.physics.near_field_lobe; {near['directions_raised']} of {near.get('directions_integrated')} "
                     f"directions raised): NOHD = {g(float(reported))} m >= the far-field {g(r)} m")
        return {"title": title, "lines": lines, "result_m": float(reported),
                "check": {"text": f"report.json {key} = {g(float(reported))} (the near-field root; not redone here)",
                          "agrees": None}, "key": key}
    return {"title": title, "lines": lines, "result_m": r, "check": _check(r, reported, key), "key": key}


def _track_ratio(track: dict, r: dict, lines: list, checks: list) -> None:
    """A moving observer (``tracks[]``): the hazard ratio is its worst window's H / MPE_H."""
    w = track.get("worst_window") or {}
    h, limit = w.get("exposure_j_m2"), w.get("mpe_radiant_exposure_j_m2")
    if h is None or not limit:
        lines.append("a moving observer: its hazard ratio is the motion stage's worst window (not given in full here)")
        return
    err, path = float(track.get("exposure_error_estimate_j_m2") or 0.0), float(track.get("path_exposure_j_m2") or 0.0)
    rel = err / path if path > 0 else 0.0
    ratio = float(h) * (1.0 + rel) / float(limit)
    lines.append(f"a moving observer (tracks[{track.get('name')}]): the worst {g(w.get('duration_s'))} s window's H, raised by "
                 f"the integral's relative error estimate, over its MPE: hazard ratio = H_w (1 + err / H_path) / MPE_H = "
                 f"{g(h)} * (1 + {g(err)} / {g(path)}) / {g(limit)} = {g(ratio)}")
    checks.append(_check(ratio, r.get("hazard_ratio"), "hazard_ratio"))


def observer_steps(r: dict, static: bool, duration_s, track: dict | None = None) -> dict:
    """One observer: its peak irradiance as direct beam + reflected peak, the hazard ratio
    E / MPE (a moving observer: its worst window's H / MPE_H), and (static) H = E t."""
    name = str(r.get("name", "?"))
    d, refl = r.get("direct_irradiance_w_m2"), r.get("reflected_irradiance_w_m2")
    mpe, peak = r.get("mpe_w_m2"), r.get("peak_irradiance_w_m2")
    lines, checks = [], []
    lines.append("direct beam: the Gaussian beam 4 P exp(-mu R) / (pi d(R)^2) exp(-4 rho^2 / d(R)^2) (d = a + R phi, rho the "
                 f"distance from the axis) averaged over the {g(r.get('aperture_diameter_m') or 0.007)} m limiting aperture "
                 f"(its value at the eye's centre {g(r.get('direct_point_irradiance_w_m2') or 0.0)} W/m²)")
    lines.append("reflected: the spot's lobes, sum over the spot of f_r cos(theta_i) cos(theta_r) dP exp(-mu R) / R^2 "
                 "(diffuse and glossy), plus any mirror beam, at the peak time "
                 f"{g(r.get('peak_time_s') or 0.0)} s; line of sight {r.get('line_of_sight')}")
    if d is None or refl is None or peak is None or not mpe:
        lines.append("report.json does not give both parts and the MPE: no sum shown")
        return {"title": f"observer {name}", "lines": lines, "checks": checks}
    e = float(d) + float(refl)
    lines.append(f"E = E_direct + E_reflected = {g(d)} + {g(refl)} = {g(e)} W/m²")
    checks.append(_check(e, peak, "peak_irradiance_w_m2"))
    if track is not None:
        _track_ratio(track, r, lines, checks)
        return {"title": f"observer {name}", "lines": lines, "checks": checks}
    ratio = e / float(mpe)
    c_e = r.get("c_e")
    lines.append(f"hazard ratio = E / MPE = {g(e)} / {g(mpe)} = {g(ratio)}" + (f" (MPE with C_E = {g(c_e)})" if c_e not in (None, 1.0) else ""))
    checks.append(_check(ratio, r.get("hazard_ratio"), "hazard_ratio"))
    if static and duration_s:
        h = e * float(duration_s)
        lines.append(f"static: H = E t = {g(e)} * {g(duration_s)} = {g(h)} J/m²")
        checks.append(_check(h, r.get("radiant_exposure_j_m2"), "radiant_exposure_j_m2"))
    return {"title": f"observer {name}", "lines": lines, "checks": checks}


def _laser_numbers(doc: dict) -> dict | None:
    """P (the average power), a and phi (1/e, after any beam convention) and mu of the scene."""
    la = ((doc.get("scene") or {}).get("echo") or {}).get("laser") or {}
    conv = (doc.get("scene") or {}).get("beam_conventions") or {}
    p = la.get("power_w")
    if p is None and la.get("pulse_energy_j") is not None and la.get("prf_hz") is not None:
        p = float(la["pulse_energy_j"]) * float(la["prf_hz"])
    a, phi = conv.get("beam_diameter_m", la.get("beam_diameter_m")), conv.get("divergence_rad", la.get("divergence_rad"))
    mu = doc.get("attenuation_per_m")
    if None in (p, a, phi, mu) or not doc.get("mpe_w_m2"):
        return None
    return {"p": float(p), "a": float(a), "phi": float(phi), "mu": float(mu), "mpe": float(doc["mpe_w_m2"])}


def half_width_steps(ln: dict, length_m: float, reported) -> dict | None:
    """The LSDZ's widening: the beam's largest hazardous half-width max over R of
    w(R) sqrt(ln(E(R) / MPE)), w = d / 2, d = a + R phi; without attenuation
    h(d) = (d / 2) sqrt(2 ln(D0 / d)), largest at d* = D0 e^(-1/2) (h = D0 / (2 sqrt(e)))
    when that d lies on the drawn length, else at its nearer end; the engine adds 1e-6 of
    itself. None with attenuation (a numerical search only) or no hazard."""
    p, mpe, a, phi, mu = ln["p"], ln["mpe"], ln["a"], ln["phi"], ln["mu"]
    d0 = math.sqrt(4.0 * p / (math.pi * mpe))
    if mu != 0.0 or phi <= 0.0 or d0 <= a or not math.isfinite(length_m):
        return None
    d_star = d0 * math.exp(-0.5)
    lines = ["hazardous half-width h = max over R of (d / 2) sqrt(ln(E(R) / MPE)) = (d / 2) sqrt(2 ln(D0 / d)), d = a + R phi "
             "(mu = 0); largest at d* = D0 exp(-1/2)",
             f"d* = {g(d0)} * exp(-1/2) = {g(d_star)} m, at R* = (d* - a) / phi = ({g(d_star)} - {g(a)}) / {g(phi)} = "
             f"{g((d_star - a) / phi)} m (the zone is drawn to {g(length_m)} m)"]
    d = min(max(d_star, a), a + length_m * phi)
    h = d / 2.0 * math.sqrt(2.0 * math.log(d0 / d))
    where = "d = d*" if d == d_star else ("R* < 0: at the aperture, d = a" if d == a else "R* beyond the zone: at its end")
    lines.append(f"{where}: h = ({g(d)} / 2) * sqrt(2 ln({g(d0)} / {g(d)})) = {g(h)} m")
    h1 = h * (1.0 + 1e-6)
    lines.append(f"with the engine's margin of 1e-6: h = {g(h)} * (1 + 1e-6) = {g(h1)} m")
    return {"title": "The danger zone's widening: the beam's hazardous half-width", "lines": lines, "result_m": h1,
            "check": _check(h1, reported, "sdz.hazard_half_width_m"), "key": "sdz.hazard_half_width_m"}


def _direct_blocks(doc: dict, ln: dict) -> list:
    """The LSDZ's NOHD (naked and through each aid), its extent, and the spilled beam's NOHD."""
    out = []
    sdz = doc.get("sdz")
    if sdz:
        b = direct_steps("Direct-beam NOHD (the laser surface danger zone)", ln["p"], ln["mpe"], ln["a"], ln["phi"], ln["mu"], 1.0,
                         sdz.get("nohd_m"), "sdz.nohd_m")
        reach = sdz.get("max_range_m")
        if reach is not None:
            b["lines"].append(f"extent: each direction reaches min(NOHD, the first backstop); the farthest, sdz.max_range_m = "
                              f"{g(reach)} m" + (" (= the NOHD: no backstop stops the beam before it)"
                                                 if not sdz.get("contained") else " (every direction stopped by a backstop)"))
        out.append(b)
        hw = half_width_steps(ln, float(reach), sdz.get("hazard_half_width_m")) if reach is not None else None
        if hw is not None:
            out.append(hw)
        for i, a in enumerate(sdz.get("aided") or []):
            k = a.get("gain")
            if k is not None:
                out.append(direct_steps(f"Direct-beam ENOHD through optics {i + 1} (gain K)", ln["p"], ln["mpe"], ln["a"],
                                        ln["phi"], ln["mu"], float(k), a.get("nohd_m"), f"sdz.aided[{i}].nohd_m"))
    spill = (doc.get("beam") or {}).get("spill") or {}
    prof = spill.get("peak_profile")
    if prof:
        out.append(direct_steps(f"Spilled beam NOHD (the beam past the targets: P times its hottest remaining part of the "
                                f"profile, {g(prof)})",
                                ln["p"] * float(prof), ln["mpe"], ln["a"], ln["phi"], ln["mu"], 1.0, spill.get("nohd_m"),
                                "beam.spill.nohd_m"))
    return out


def _faa_blocks(doc: dict, ln: dict) -> list:
    """The FAA distances of the direct beam (``visual_interference.direct``), where they apply."""
    vi = doc.get("visual_interference") or {}
    direct, levels, vcf = vi.get("direct") or {}, vi.get("levels_w_m2") or {}, vi.get("vcf")
    out = []
    for key in ("lfed", "czed", "szed"):
        d = direct.get(f"{key}_m")
        if d is None or key not in levels or not vcf:
            continue
        e = float(levels[key]) / float(vcf)
        b = direct_steps(f"FAA {key.upper()} of the direct beam", ln["p"], e, ln["a"], ln["phi"],
                         float(vi.get("attenuation_per_m") or 0.0), 1.0, d, f"visual_interference.direct.{key}_m",
                         limit_name="E_lim / VCF")
        b["lines"].insert(1, f"E_lim / VCF = {g(levels[key])} / {g(vcf)} = {g(e)} W/m² (the level, over the visual correction)")
        out.append(b)
    return out


def _lobe_blocks(doc: dict, ln: dict) -> list:
    out = []
    for t in doc.get("targets") or []:
        st, dy = t.get("keepout_static") or {}, t.get("keepout_dynamic") or {}
        name = t.get("name", "?")
        if st.get("max_nohd_m"):
            out.append(lobe_steps(f"target {name}: reflected lobe NOHD (static)", st, ln["mpe"], ln["mu"],
                                  f"targets[{name}].keepout_static.max_nohd_m"))
        if dy.get("max_nohd_m") and dy != st:
            out.append(lobe_steps(f"target {name}: reflected lobe NOHD (dynamic)", dy, ln["mpe"], ln["mu"],
                                  f"targets[{name}].keepout_dynamic.max_nohd_m"))
        out += _aided_lobe_blocks(t, st, dy, ln)
        if t.get("specular_nohd_static_m") is not None:
            out.append(mirror_steps(f"target {name}: mirror beam NOHD (static)", t.get("specular_steps"), ln["mpe"], ln["mu"],
                                    t["specular_nohd_static_m"], f"targets[{name}].specular_nohd_static_m"))
    return out


def mirror_steps(title: str, steps, mpe_w_m2: float, mu_per_m: float, reported, key: str) -> dict:
    """A mirror beam's NOHD beyond the mirror from its governing part (``targets[].specular_steps``,
    :class:`hazard.physics.specular.MirrorBeamSteps`): ``E(D) = rho E_peak exp(-mu D) / ((1 + D
    v_t)(1 + D v_s)) = MPE``, in closed form where ``v_t = v_s`` (the direct beam's form with a
    = 1/v, phi = 1) or where the aperture's power cap governs, else solved by bisection here."""
    kind = (steps or {}).get("governed_by")
    if kind == "aperture power cap":
        cap = float(steps["aperture_cap_w_m2"])
        r = math.log(cap / mpe_w_m2) / mu_per_m if mu_per_m > 0 else math.inf
        lines = ["the mirror lobe's whole power over the limiting aperture governs: cap exp(-mu D) = MPE",
                 f"cap = K P_r / A = {g(cap)} W/m², MPE = {g(mpe_w_m2)} W/m², mu = {g(mu_per_m)} 1/m",
                 f"D = ln(cap / MPE) / mu = {g(r)} m"]
        return {"title": title, "lines": lines, "result_m": r, "check": _check(r, reported, key), "key": key}
    if kind not in ("sample", "whole-target bound"):
        why = {"curved side": "a curved side's Coddington spreading along its worst reflected ray",
               "curved facets": "a curved mesh's ray tubes through their focus"}.get(kind, "report.json holds no numbers for it")
        return {"title": title, "lines": [f"no closed-form step: {why} (hazard.physics.specular)"], "result_m": None,
                "check": {"text": f"report.json {key} = {g(reported)} m", "agrees": None}, "key": key}
    rho, e_in = float(steps["reflectance"]), float(steps["incident_peak_w_m2"])
    vt, vs = float(steps["vergence_t_per_m"]), float(steps["vergence_s_per_m"])
    e0 = rho * e_in
    lines = ["E(D) = rho E_peak exp(-mu D) / ((1 + D v_t)(1 + D v_s)) = MPE: the mirror beam D beyond the mirror "
             f"({'its hottest sample' if kind == 'sample' else 'the whole target: its edge bound'})",
             f"rho = {g(rho)}, E_peak = {g(e_in)} W/m² (incident), v_t = {g(vt)} 1/m, v_s = {g(vs)} 1/m (1 / the virtual "
             f"source's distance), MPE = {g(mpe_w_m2)} W/m², mu = {g(mu_per_m)} 1/m",
             f"rho E_peak = {g(e0)} W/m²"]
    if e0 < mpe_w_m2:
        r = 0.0
        lines.append("rho E_peak < MPE: NOHD = 0 m")
    elif vt == vs and vt > 0:
        d0 = math.sqrt(e0 / mpe_w_m2) / vt
        lines.append(f"v_t = v_s = v: the direct beam's form with a = 1/v = {g(1 / vt)} m, phi = 1, "
                     f"D0 = sqrt(rho E_peak / MPE) / v = {g(d0)} m")
        r, more = _beam_range(d0, 1.0 / vt, 1.0, mu_per_m)
        lines += more
    elif vt == vs == 0.0:
        r = math.log(e0 / mpe_w_m2) / mu_per_m if mu_per_m > 0 else math.inf
        lines.append(f"collimated (v = 0): D = ln(rho E_peak / MPE) / mu = {g(r)} m")
    else:
        r = _bisect_mirror(e0, vt, vs, mu_per_m, mpe_w_m2)
        lines.append(f"v_t != v_s: solved by bisection of ln(rho E_peak / MPE) - mu D - ln(1 + D v_t) - ln(1 + D v_s) = 0: "
                     f"D = {g(r)} m")
    return {"title": title, "lines": lines, "result_m": r, "check": _check(r, reported, key), "key": key}


def _bisect_mirror(e0: float, vt: float, vs: float, mu: float, mpe: float) -> float:
    """Root D [m] of ``ln(e0 / mpe) - mu D - ln(1 + D vt) - ln(1 + D vs)`` (falling in D) to 1e-12."""
    c = math.log(e0 / mpe)

    def f(d):
        return c - mu * d - math.log1p(d * vt) - math.log1p(d * vs)

    if f(1e12) >= 0:
        return math.inf
    lo, hi = 0.0, 1.0
    while f(hi) > 0:
        lo, hi = hi, 2 * hi
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    return hi


def _aided_lobe_blocks(t: dict, st: dict, dy: dict, ln: dict) -> list:
    """A target's lobe ENOHDs through each optical aid (``targets[].aided``), static and
    (when it differs) dynamic, from the lobe's peak intensity times the aid's gain."""
    out, name = [], t.get("name", "?")
    for i, a in enumerate(t.get("aided") or []):
        k = a.get("gain")
        eye = f"{g(a.get('magnification'))}x{g(1e3 * float(a.get('objective_diameter_m') or 0.0))} optics"
        for kind, lobe, field in (("static", st, "nohd_static_m"), ("dynamic", dy, "nohd_dynamic_m")):
            if k is None or not a.get(field) or (kind == "dynamic" and dy == st and a.get(field) == a.get("nohd_static_m")):
                continue
            out.append(lobe_steps(f"target {name}: reflected lobe ENOHD through {eye} ({kind})", lobe, ln["mpe"], ln["mu"],
                                  f"targets[{name}].aided[{i}].{field}", gain=float(k), reported=a.get(field)))
    return out


def analysed_times_text(doc: dict) -> str:
    """The exposure window the analysis covered (report.json ``times_s`` and the MPE's duration)."""
    t = doc.get("times_s") or {}
    dur = (doc.get("mpe") or {}).get("duration_s")
    dur_t = "not stated" if dur is None else f"{g(dur)} s"
    m_span = (doc.get("motion") or {}).get("time_span_s")
    moving = "" if not m_span else (f" The motion stage follows what moves (beam, targets, observers) from {g(m_span[0])} s to "
                                    f"{g(m_span[-1])} s, every window of up to {dur_t} in it (see Airspace and moving observers).")
    if t.get("count") == 1:
        return (f"Analysed exposure: the materials do not change (one state at t = {g(t.get('start', 0.0))} s), held over "
                f"the whole exposure duration of {dur_t}: the window analysed is 0 s to {dur_t} (H = E × {dur_t}).{moving}")
    if t.get("start") is None or t.get("end") is None:
        return f"Analysed times: not stated in report.json (exposure duration {dur_t})."
    span = float(t["end"]) - float(t["start"])
    how = ("the worst window of that duration within them" if dur is not None and span > float(dur) else
           "the exposure integrated over the whole span")
    return (f"Analysed times: {g(t['start'])} s to {g(t['end'])} s ({t.get('count', 'not stated')} time steps, a span of "
            f"{g(span)} s); exposure duration {dur_t}: {how}.{moving}")


def steps_section(doc: dict, names=(), shown: int = STEPS_OBSERVERS) -> dict:
    """The page's "every number with its steps" section: the direct-beam, spill and lobe
    NOHDs, the FAA distances and the observers (the ``shown`` highest hazard ratios and
    any in ``names``); ``missing`` the names asked for that report.json does not list."""
    ln = _laser_numbers(doc)
    blocks = [] if ln is None else _direct_blocks(doc, ln) + _lobe_blocks(doc, ln)
    faa = [] if ln is None else _faa_blocks(doc, ln)
    rows = list(doc.get("observers") or [])
    ranked = sorted(rows, key=lambda r: -(r.get("hazard_ratio") if isinstance(r.get("hazard_ratio"), (int, float)) else math.inf))
    chosen = ranked[:shown]
    by_name = {str(r.get("name")): r for r in rows}
    chosen += [by_name[n] for n in names if n in by_name and by_name[n] not in chosen]
    static = (doc.get("times_s") or {}).get("count") == 1
    dur = (doc.get("mpe") or {}).get("duration_s")
    tracks = {str(t.get("name")): t for t in doc.get("tracks") or [] if t.get("kind", "track") != "fixed"}
    return {"blocks": blocks, "faa": faa, "observers": [observer_steps(r, static, dur, tracks.get(str(r.get("name"))))
                                                         for r in chosen],
            "missing": [n for n in names if n not in by_name], "absent": "" if ln is not None else
            "report.json lacks the laser's power, beam size, divergence, attenuation or MPE: no steps"}
