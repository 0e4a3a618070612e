"""The ``hazard`` command line.

``main(argv) -> int`` so tests and scripts call it directly. Results go to stdout (text,
or JSON with ``--json``); errors are one line on stderr with exit code 2.

Verbs:
  hazard run SCENE -o OUTDIR   analyse a scene; write report.json and observers.csv; print the
                               answer (hazardous observers, NOHDs, what was skipped) first
  hazard compare SCENE         static vs dynamic: NOHD per target, changed verdicts
  hazard validate SCENE        check a scene file (or a study file) as run, risk and study would
  hazard models                registered BRDF models
  hazard schema [--markdown]   JSON schema of scene files (or the reference table of every key;
                               --report: the JSON schema of report.json)
  hazard study STUDY.toml -o OUTDIR  sweeps / Monte Carlo on Dask (resumable)
  hazard convergence SCENE     error vs run time of each accuracy knob, recommendation
  hazard render SCENE -o OUTDIR   keep-out renders (PNG), VTK for ParaView, lobe animation
  hazard report OUTDIR [--pdf]  the report for the review board: OUTDIR/report.html (self-contained)
                               and OUTDIR/map.html (interactive plan view, offline)
  hazard fit screen TEST.toml [...] -o BRDF.json   witness-screen tests -> fitted BRDF
  hazard fit sh SAMPLES.csv -o BRDF.json          spherical-harmonic fit (static or per state)
  hazard fit ts5 SAMPLES.csv -o BRDF.json         five-parameter model (nlopt)
  hazard fit abg SAMPLES.csv -o BRDF.json         ABg scatter lobe (nlopt), with parameter uncertainties
  hazard fit oxidation SERIES.csv -o OX.json      oxidation law from a reflectance series
  hazard mpe   --wavelength-nm L --duration-s T [--standard S] [--skin] [--json]
  hazard nohd  --power-w P (--mpe-w-m2 M | --wavelength-nm L --duration-s T) ...
  hazard --version             the version (one source: hazard.__version__, read by pyproject.toml)

SCENE is a TOML file or the name of a bundled example (``hazard validate plate``).
Exit codes: 0 done, 1 internal error, 2 bad input, 3 hazard found (only with --fail-on-hazard
[observers|zones|any]: at the listed observers (default), in zones not contained, either),
4 some scenarios of a study or chunks of risk draws failed (study, risk; a summary on stderr).
Every error is one line on stderr naming the input; ``--debug`` (anywhere on the command
line) shows the traceback instead.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path


from hazard.physics import mpe as _mpe
from hazard.physics import nohd as _nohd
from hazard.cli_units import add_quantity_option

__all__ = ["main", "build_parser"]

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_ERROR = 2
EXIT_HAZARD = 3
EXIT_FAILED = 4  # hazard study / risk: some scenarios or draw chunks failed (the summary names them)
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: the reader of stdout went away (the outputs are written first)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser that raises instead of exiting, so main() returns the code."""

    def error(self, message):
        raise _UsageError(f"{self.prog}: {message}")


class _UsageError(Exception):
    pass


def _add_mpe_args(p, *, required):
    add_quantity_option(p, "--wavelength-nm", "nm", "laser wavelength [nm], 180 nm to 1 mm", required=required)
    add_quantity_option(p, "--duration-s", "s", "exposure duration (or pulse duration) [s], 1e-13 to 3e4", required=required)
    p.add_argument("--standard", default=_mpe.DEFAULT_STANDARD, help=f"one of {sorted(_mpe.STANDARDS)} (default {_mpe.DEFAULT_STANDARD})")
    add_quantity_option(p, "--angular-subtense-rad", "rad", "apparent source size [rad] (0: point source)", default=0.0)


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 1")
    return value


def _nonnegative_int(text):
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 0")
    return value


def _add_dask_args(p, what: str, json_help: str) -> None:
    """Where a Dask job runs and how it resumes (hazard study, hazard risk)."""
    p.add_argument("--scheduler", help="address of an existing Dask scheduler (default: an embedded LocalCluster)")
    p.add_argument("--workers", type=_positive_int, default=2, help="worker processes of the embedded cluster (default 2)")
    p.add_argument("--serial", action="store_true", help="run in this process without Dask (identical results)")
    p.add_argument("--force", action="store_true", help=f"start over if the folder holds another {what}")
    p.add_argument("--json", action="store_true", help=json_help)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--keep-going", action="store_true", help=f"after a failed {'scenario' if what == 'study' else 'chunk of draws'}, "
                   "run the rest anyway (default: stop at the first); either way a failure exits 4 with a summary")


def _add_run_args(p):
    p.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    p.add_argument("--fail-on-hazard", nargs="?", const="observers", default=None, choices=("observers", "zones", "any"),
                   metavar="{observers,zones,any}",
                   help="exit with code 3 on a hazard: 'observers' (the default when no value is given) a listed observer, "
                        "track or flight zone at or above its limit (report.json hazard_at_observers); 'zones' a danger "
                        "zone, mirror beam or keep-out lobe not contained or beyond the range boundary (hazard_zones); "
                        "'any' either. Write a value as --fail-on-hazard=zones; a bare --fail-on-hazard goes after the scene")
    p.add_argument("--backend", default="embree", choices=["embree", "numpy"], help="ray engine (default embree)")
    p.add_argument("--threads", type=_positive_int, default=None,
                   help="threads for the map, BRDF evaluations and ray queries (default: every CPU this process may use)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr (stage lines, and bars on a terminal)")


_PROVENANCE = ("Every step ends with its provenance label: [C] read in the cited public source, [D] derived here from "
               "[C] rows, [M] general knowledge not verified against a source (a governing row labelled [M], or a [C] row "
               "marked UNVERIFIED, adds a WARNING to the result). The sources are public implementations of the standards, not their text: "
               "'[C] OLBtools Z136 (A), akufcsak table_a1 (I)' = read in OLBtools' ANSI Z136.1-2014 module (A) and in "
               "akufcsak/laser_safety's IEC 60825-1:2014 Table A.1 (I), which agree; Laser-Studio = its decoded 2007 table. "
               "Tables, formulas and sources: docs/laser-safety.md.")


def _version_line() -> str:
    from hazard import __version__

    return f"hazard (laser-hazard) {__version__}"


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="hazard", description="Laser reflection hazard analysis.",
                     epilog="Errors are one line on stderr (exit 2: bad input, 1: internal error, 4: scenarios or risk draws failed); "
                            "--debug shows the traceback. Input limits: HAZARD_MAX_<NAME> environment variables (see README).")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error (may also follow the verb)")
    parser.add_argument("--version", action="version", version=_version_line(), help="print the version and exit")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("run", help="analyse a scene and write report.json and observers.csv")
    p.add_argument("scene", help="scene TOML file, or a bundled example's name")
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--verbose", action="store_true", help="after the answer, print the stage log (every stage, ran or skipped, with its run time)")
    p.add_argument("--plot", action="store_true", help="also write the pictures: plan.png and elevation.png (danger zone, beams, lobe outlines, "
                   "range rings, observers by verdict), nohd_time_<target>.png and exposure_<observer>.png")
    p.add_argument("--report", action="store_true", help="also write report.html, the report for the review board "
                   "(after the pictures of --plot; see hazard report)")
    _add_run_args(p)

    p = sub.add_parser("compare", help="static vs dynamic reflectance: NOHD per target and observer verdicts")
    p.add_argument("scene", help="scene TOML file, or a bundled example's name")
    _add_run_args(p)

    p = sub.add_parser("validate", help="check a scene (or study) file as run, risk and study would, and print what it contains")
    p.add_argument("scene", help="scene or study TOML file, or a bundled example's name")
    p.add_argument("--json", action="store_true", help="print JSON")

    p = sub.add_parser("models", help="list the registered BRDF models (--materials: the material library)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--materials", action="store_true", help="list the material library (scenes: material = { library = NAME })")

    p = sub.add_parser("schema", help="print the JSON schema of scene files (--markdown: the reference table of every key)")
    p.add_argument("-o", "--output", help="write to this file instead of stdout")
    p.add_argument("--markdown", action="store_true", help="print the scene reference as Markdown (key path, type, unit, "
                   "default, description), as kept in docs/scene-reference.md")
    p.add_argument("--report", action="store_true", help="print the JSON schema of report.json instead (hazard.outputs.report_schema)")

    p = sub.add_parser("study", help="scenario study: sweeps and Monte Carlo over a base scene, on Dask")
    p.add_argument("study", help="study TOML, or a bundled example study's name (power_sweep, montecarlo_binoculars, plate_power)")
    p.add_argument("-o", "--output", required=True, help="output folder (a restarted study resumes there)")
    _add_dask_args(p, "study", "print the summary as JSON")

    p = sub.add_parser("risk", help="probabilistic risk: the chance each observer's exposure exceeds the MPE over the scene's "
                                    "[uncertainty] (risk.json, risk.csv, probability map), on Dask")
    p.add_argument("scene", help="scene TOML file with an [uncertainty] table, or a bundled example's name")
    p.add_argument("-o", "--output", required=True, help="output folder (a restarted run resumes there)")
    p.add_argument("--draws", type=_positive_int, help="simulated operations (default: [uncertainty] draws)")
    p.add_argument("--seed", type=_nonnegative_int, help="random seed (default: [uncertainty] seed); the same seed gives the same results")
    p.add_argument("--sampling", choices=("auto", "plain", "importance"), help="override [uncertainty] sampling")
    p.add_argument("--sensitivity-draws", type=_nonnegative_int, help="base draws of the Sobol indices (0: none)")
    _add_dask_args(p, "risk analysis", "print risk.json's observers as JSON")

    p = sub.add_parser("report", help="the report for the review board: one self-contained HTML file (and a PDF) "
                                      "and map.html, an interactive offline plan view, from an output folder of hazard run")
    p.add_argument("out_dir", metavar="OUT_DIR", help="output folder of hazard run (holding report.json; its pictures are embedded)")
    p.add_argument("--pdf", action="store_true", help="also print report.pdf with headless Chromium")
    p.add_argument("--observer", action="append", default=[], metavar="NAME",
                   help="also show this observer's irradiance with its steps (besides the ten highest; repeatable)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")

    p = sub.add_parser("render", help="3-D renders of the keep-out zones (PNG), a VTK multiblock and a lobe animation")
    p.add_argument("scene", help="scene TOML file, or a bundled example's name")
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="overwrite existing renders")
    p.add_argument("--no-animation", action="store_true", help="skip the animation of the dynamic lobe")
    p.add_argument("--resolution-deg", type=float, default=3.0, help="lobe surface resolution [deg]")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")

    p = sub.add_parser("convergence", help="error against run time for each accuracy knob of a scene")
    p.add_argument("scene", help="scene TOML file, or a bundled example's name")
    p.add_argument("--tolerance", type=float, default=0.01, help="relative error allowed for the recommendation (default 0.01)")
    p.add_argument("--knob", action="append", help="only this knob (repeatable)")
    p.add_argument("--plot", help="write a log-log plot (PNG) here")
    p.add_argument("--json", action="store_true")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")

    p = sub.add_parser("fit", help="fit BRDF models and histories to measurements")
    fsub = p.add_subparsers(dest="fit_kind", metavar="KIND", parser_class=_Parser)
    fsub.required = True
    for kind, helptext in (("screen", "reduce witness-screen tests (TOML) and fit an SH BRDF"),
                           ("sh", "fit an SH BRDF to a samples table (CSV)")):
        q = fsub.add_parser(kind, help=helptext)
        q.add_argument("inputs", nargs="+", help="test descriptions (TOML)" if kind == "screen" else "samples table (.csv or .parquet)")
        q.add_argument("-o", "--output", required=True, help="model file to write (JSON)")
        q.add_argument("--basis", default="8,4,2,0", help="lh_max,mh_max,ld_max,md_max (default 8,4,2,0: 37 harmonics)")
        q.add_argument("--fanout", type=float, default=0.6, help="fan-out exponent s_e (default 0.6)")
        q.add_argument("--smoothing", type=float, default=0.0, help="Tikhonov smoothness strength of the SH fit (default 0: "
                                                                    "none; --report's choice prints it)")
        q.add_argument("--state", help="fit one model per state: time_s, temperature_k or a state column of the samples; "
                                       "two names (extinction,melt_fraction) fit a two-state model")
        q.add_argument("--states", help="comma-separated state values to group the samples at (with --state); for two "
                                        "states the two lists separated by ';', e.g. '0.311,0.8,1.5;0,0.5,1'")
        q.add_argument("--envelope", choices=["paper", "sh"], help="also write a conservative envelope bounding every sample")
        q.add_argument("--envelope-output", help="envelope model file (JSON)")
        q.add_argument("--samples-output", help="write the reduced samples table (.csv, or .parquet with pyarrow)" if kind == "screen" else argparse.SUPPRESS)
        q.add_argument("--report", action="store_true", help="print the leave-one-test-out error-vs-cost table over basis orders")
        q.add_argument("--force", action="store_true", help="overwrite existing outputs")
        q.add_argument("--json", action="store_true", help="print the fit report as JSON")
        q.add_argument("--quiet", action="store_true", help="no progress bars")
        if kind == "sh":
            _fit_wavelength_option(q)
    q = _nlopt_fit_parser(fsub, "ts5", "fit the five-parameter Torrance-Sparrow model to a samples table (CSV)", 20000)
    q.add_argument("--report", action="store_true", help="print the algorithm comparison table")
    _nlopt_fit_parser(fsub, "abg", "fit an ABg scatter lobe A / (B + |beta - beta0|^g) to a samples table (CSV)", 4000)
    q = fsub.add_parser("oxidation", help="fit the oxidation law to a series CSV (time_s, temperature_k, reflectance)")
    q.add_argument("inputs", nargs=1, help="series CSV with columns time_s, temperature_k, reflectance")
    q.add_argument("-o", "--output", required=True, help="result file to write (JSON)")
    q.add_argument("--force", action="store_true")
    q.add_argument("--json", action="store_true")

    p = sub.add_parser("mpe", help="maximum permissible exposure with every step", epilog=_PROVENANCE)
    _add_mpe_args(p, required=True)
    p.add_argument("--skin", action="store_true", help="skin MPE instead of ocular")
    add_quantity_option(p, "--prf-hz", "Hz", "pulse repetition frequency [Hz]: --duration-s is then the pulse duration")
    add_quantity_option(p, "--exposure-duration-s", "s", "duration of the pulse train [s] (with --prf-hz)")
    p.add_argument("--explain", action="store_true", help="also say which rule governed and why (the candidate limits compared)")
    p.add_argument("--exposures-per-day", type=_positive_int, help=(
        "180-400 nm: this many such exposures (or trains) within 24 h; their doses add up and the sum is held to "
        "the MPE of their total duration (hazard.physics.mpe.uv_24h_mpe, [M])"))
    p.add_argument("--json", action="store_true", help="print JSON")

    p = sub.add_parser("nohd", help="nominal ocular hazard distance with every step", epilog=_PROVENANCE)
    p.add_argument("--kind", default="direct", choices=["direct", "diffuse", "specular"], help="direct beam, Lambertian or mirror reflection")
    add_quantity_option(p, "--power-w", "W", "laser power [W] (pulse energy [J], a bare number, with a J/m^2 MPE)", required=True)
    add_quantity_option(p, "--mpe-w-m2", "W/m^2", "MPE [W/m^2]; otherwise computed from --wavelength-nm and --duration-s")
    _add_mpe_args(p, required=False)
    add_quantity_option(p, "--beam-diameter-m", "m", "beam diameter at the aperture, 1/e [m] (direct, specular)")
    add_quantity_option(p, "--divergence-rad", "rad", "full-angle divergence, 1/e [rad] (direct, specular)")
    p.add_argument("--reflectance", type=float, help="reflectance of the surface (diffuse, specular)")
    add_quantity_option(p, "--viewing-angle-deg", "deg", "viewing angle from the surface normal [deg] (diffuse)", default=0.0)
    add_quantity_option(p, "--range-to-reflector-m", "m", "laser to mirror [m] (specular)", default=0.0)
    att = p.add_mutually_exclusive_group()
    add_quantity_option(att, "--attenuation-per-m", "1/m", "atmospheric attenuation [1/m]", default=0.0)
    add_quantity_option(att, "--visibility-km", "km", "meteorological visibility [km] (Kruse model)")
    p.add_argument("--optical-gain", type=float, help="collecting gain of viewing optics (>= 1)")
    p.add_argument("--magnification", type=float, help="viewing optics magnification (with --objective-diameter-m)")
    add_quantity_option(p, "--objective-diameter-m", "m", "viewing optics objective diameter [m]")
    p.add_argument("--transmission", type=float, default=1.0, help="viewing optics transmission")
    p.add_argument("--json", action="store_true", help="print JSON")
    return parser


def _cmd_mpe(args, out, err=None):
    if args.prf_hz is not None:
        if args.exposure_duration_s is None:
            raise ValueError("--exposure-duration-s: required with --prf-hz (the duration of the pulse train)")
        if args.skin:
            raise ValueError("--skin: the repetitive-pulse rules are implemented for ocular exposure only")
        res = _mpe.repetitive_pulse_mpe(
            args.wavelength_nm, args.duration_s, args.prf_hz, args.exposure_duration_s,
            standard=args.standard, angular_subtense_rad=args.angular_subtense_rad,
        )
    elif args.skin:
        res = _mpe.skin_mpe(args.wavelength_nm, args.duration_s, standard=args.standard)
    else:
        res = _mpe.ocular_mpe(args.wavelength_nm, args.duration_s, standard=args.standard, angular_subtense_rad=args.angular_subtense_rad)
    doc = res.to_dict()
    if args.explain:
        doc["explanation"] = res.explain().splitlines()
    day = ""
    if args.exposures_per_day is not None:
        each_s = args.duration_s if args.prf_hz is None else args.exposure_duration_s
        uv = _mpe.uv_24h_mpe(args.wavelength_nm, [each_s] * args.exposures_per_day, standard=args.standard,
                             kind="skin" if args.skin else "ocular")
        doc["uv_24h"] = {**uv.to_dict(), "exposures": args.exposures_per_day,
                         "per_exposure_radiant_exposure_j_m2": uv.radiant_exposure_j_m2 / args.exposures_per_day}
        day = (f"\n{uv}\n  per exposure: {uv.radiant_exposure_j_m2:.6g} / {args.exposures_per_day} = "
               f"{uv.radiant_exposure_j_m2 / args.exposures_per_day:.6g} J/m^2 (also each exposure's own MPE above)")
    out.write((json.dumps(doc, indent=1) if args.json else str(res) + ("\n" + res.explain() if args.explain else "") + day) + "\n")
    return EXIT_OK


def _require(args, *names):
    for n in names:
        if getattr(args, n) is None:
            raise ValueError(f"--{n.replace('_', '-')}: required for --kind {args.kind}")


def _cmd_nohd(args, out, err=None):
    doc = {}
    lines = []
    if args.mpe_w_m2 is not None:
        mpe_w_m2 = args.mpe_w_m2
    else:
        if args.wavelength_nm is None or args.duration_s is None:
            raise ValueError("--mpe-w-m2: give it, or --wavelength-nm and --duration-s to compute it")
        m = _mpe.ocular_mpe(args.wavelength_nm, args.duration_s, standard=args.standard, angular_subtense_rad=args.angular_subtense_rad)
        mpe_w_m2 = m.irradiance_w_m2
        doc["mpe"] = m.to_dict()
        lines += list(m.steps) + [""]
    mu = args.attenuation_per_m
    if args.visibility_km is not None:
        if args.wavelength_nm is None:
            raise ValueError("--visibility-km: needs --wavelength-nm for the Kruse model")
        mu = _nohd.attenuation_from_visibility(args.visibility_km, args.wavelength_nm)
        lines.append(f"Atmosphere: visibility {args.visibility_km:g} km at {args.wavelength_nm:g} nm (Kruse) -> mu = {mu:.6g} 1/m")
    gain = 1.0 if args.optical_gain is None else args.optical_gain
    if args.magnification is not None or args.objective_diameter_m is not None:
        if args.optical_gain is not None:
            raise ValueError("--optical-gain: give either it or --magnification/--objective-diameter-m, not both")
        if args.magnification is None or args.objective_diameter_m is None:
            raise ValueError("--magnification and --objective-diameter-m: give both for viewing optics")
        gain = _nohd.optical_gain(args.magnification, args.objective_diameter_m, args.transmission)
        lines.append(
            f"Optics: {args.magnification:g}x, {1e3 * args.objective_diameter_m:g} mm, tau {args.transmission:g} -> K = {gain:.6g}"
        )
    if args.kind == "direct":
        _require(args, "beam_diameter_m", "divergence_rad")
        res = _nohd.nohd_direct(args.power_w, mpe_w_m2, args.beam_diameter_m, args.divergence_rad, attenuation_per_m=mu, optical_gain=gain)
    elif args.kind == "specular":
        _require(args, "beam_diameter_m", "divergence_rad", "reflectance")
        res = _nohd.nohd_specular(
            args.power_w, mpe_w_m2, args.beam_diameter_m, args.divergence_rad, args.reflectance,
            attenuation_per_m=mu, optical_gain=gain, range_to_reflector_m=args.range_to_reflector_m,
        )
    else:
        _require(args, "reflectance")
        res = _nohd.nohd_diffuse(
            args.power_w, mpe_w_m2, args.reflectance, viewing_angle_rad=math.radians(args.viewing_angle_deg),
            attenuation_per_m=mu, optical_gain=gain,
        )
    doc["nohd"] = res.to_dict()
    lines += list(res.steps)
    out.write((json.dumps(doc, indent=1) if args.json else "\n".join(lines)) + "\n")
    return EXIT_OK


def _scene_path(name) -> Path:
    """The scene file a SCENE argument names: a path, or a bundled example's name."""
    import scenes

    path = Path(name)
    if not path.exists() and name in scenes.examples():
        path = scenes.example_path(name)
    return path


def _scene_source(name) -> str | None:
    """A digest of the scene file's bytes, kept in the output folder's manifest so that
    files made from another scene are never mixed in silently (None: unreadable; the
    scene's load then names the problem)."""
    import hashlib

    try:
        return "sha256:" + hashlib.sha256(_scene_path(name).read_bytes()).hexdigest()
    except OSError:
        return None


def _load_scene(name, err=None):
    import scenes

    scene = scenes.load(_scene_path(name))
    if err is not None:
        for w in scene.warnings:
            err.write(f"hazard: warning: {scene.source}: {w}\n")
    return scene


def _needs(module, extra):
    """Before any work: an optional dependency is importable, else a one-line error
    naming the extra that installs it."""
    import importlib.util

    if importlib.util.find_spec(module) is None:
        raise ValueError(f"{module} is not installed: pip install 'laser-hazard[{extra}]' (or [all])")


def _check_outdir(outdir, names, force):
    """Before any work: the output folder is (or can be made) a writable folder, and its
    outputs do not exist unless ``force``."""
    import os

    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"-o {outdir}: exists and is not a folder")
    if out.is_dir():
        if not force:
            for n in names:
                if (out / n).exists():
                    raise ValueError(f"{out / n} exists: pass --force to overwrite")
        probe = out
    else:
        probe = out.parent if str(out.parent) else Path(".")
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if not probe.is_dir():
            raise ValueError(f"-o {outdir}: {probe} is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ValueError(f"-o {outdir}: {probe} is not writable")


def _stage_lines(args, err):
    """The stage-by-stage progress lines on stderr (``hazard: beam...``), None with --quiet."""
    return None if args.quiet else (lambda msg: err.write(f"hazard: {msg}\n"))


def _analyse(args, err):
    """Load and analyse ``args.scene``: stage lines and (on a terminal) bars on ``err``."""
    from hazard.pipeline.analysis import analyze
    from hazard.progress import progress_to

    if getattr(args, "backend", "embree") == "numpy":  # before any work, whatever the scene needs (issue 30)
        _needs("rtree", "numpy-backend")
    scene = _load_scene(args.scene, err)
    with progress_to(None if args.quiet else err):
        return analyze(scene, backend=args.backend, progress=_stage_lines(args, err), threads=getattr(args, "threads", None))


def _finish(args, result, v=None):
    """EXIT_HAZARD when ``--fail-on-hazard WHICH`` finds its kind of hazard (:func:`hazard.pipeline.verdict.fails`;
    ``v``: the run's verdict when the caller has it)."""
    from hazard.pipeline.verdict import fails, verdict

    return EXIT_HAZARD if (args.fail_on_hazard and fails(verdict(result) if v is None else v, args.fail_on_hazard)) else EXIT_OK


def _cmd_run(args, out, err):
    from brdfmodels.output_sets import output_unit

    from hazard.outputs.report import csv_started, json_safe, report_dict, summary_text, write_set
    from hazard.pipeline.verdict import verdict

    from hazard.pictures.figures import FIXED_NAMES

    from hazard.outputs.map_outputs import MAP_NAMES, map_files

    names = ("report.json", "observers.csv") + MAP_NAMES
    _check_outdir(args.output, names + (FIXED_NAMES if args.plot else ()), args.force)
    if args.plot:
        _needs("matplotlib", "render")
    with output_unit(args.output, command="run", overwrite=args.force, force=args.force,  # all outputs as one unit
                     claims=names + FIXED_NAMES, source=_scene_source(args.scene)) as unit:
        err.write("".join(f"hazard: {n}\n" for n in unit.notes))  # a crash of an earlier run recovered: said
        result = _analyse(args, err)
        v = verdict(result)  # once: report.json, the printed answer and --fail-on-hazard
        extra = {}
        if args.plot:
            from hazard.pictures.figures import kept_render_entries, run_figures

            extra = run_figures(result, progress=None if args.quiet else (lambda name: err.write(f"hazard: drawing {name}...\n")),
                                rendered=kept_render_entries(unit))  # hazard render's 3-D pictures kept beside: still listed
        if not args.quiet:
            err.write("hazard: map outputs...\n")
        with csv_started(result, unit.stage) as csv:  # observers.csv written on a worker thread meanwhile
            maps, section = map_files(result)
            names = write_set(result, unit.stage, extra={**extra, **maps}, sections={"map_outputs": section.to_dict()},
                              verdict_doc=v, csv=csv)
        if args.report:  # the review page embeds the pictures just written (and those of hazard render, carried over)
            unit.carry()
            names += [p.name for p in _write_review(unit.stage, args, err)]
    paths = [Path(args.output) / n for n in names]
    if args.json:
        out.write(json.dumps({**report_dict(result, verdict_doc=v), "map_outputs": json_safe(section.to_dict())}, indent=1) + "\n")
        err.write(_kept_lines(unit))
    else:
        out.write(summary_text(result, verbose=args.verbose, verdict_doc=v) + "\n")
        out.write("".join(f"wrote {p}\n" for p in paths) + _kept_lines(unit))
    return _finish(args, result, v)


def _kept_lines(unit) -> str:
    """What stayed in the output folder that this run did not write, and the files hazard
    did not write that a new output replaced: said, never silently left or lost."""
    lines = [f"kept {unit.given / n} (" + (f"written by hazard {o} before this run: make it again if the scene changed)"
                                           if o else "not written by hazard: left as it was)") for n, o in unit.kept.items()]
    lines += [f"replaced {unit.given / n} (not written by hazard: a new output has its name)" for n in unit.replaced_foreign]
    lines += [f"removed {unit.given / n} (written by hazard {unit.owners[n]} from another scene)" for n in unit.dropped_stale]
    return "".join(line + "\n" for line in lines)


def _state_span(name, span) -> str:
    """``state extinction in [a, b]``, or both states of a two-state history."""
    if isinstance(name, str):
        return f"state {name} in [{span[0]:.4g}, {span[1]:.4g}]"
    return "states " + ", ".join(f"{n} in [{lo:.4g}, {hi:.4g}]" for n, (lo, hi) in zip(name, span))


def _cmd_compare(args, out, err):
    result = _analyse(args, err)
    rows = []
    for t in result.targets:
        d = t.to_dict()
        rows.append({"target": t.name, "state": t.state_name, "state_range": t.state_range,
                     "nohd_static_m": d["nohd_static_m"], "nohd_dynamic_m": d["nohd_dynamic_m"],
                     "keepout_volume_static_m3": d["keepout_static"]["volume_m3"],
                     "keepout_volume_dynamic_m3": d["keepout_dynamic"]["volume_m3"],
                     "specular_nohd_static_m": t.specular_nohd_static_m, "specular_nohd_dynamic_m": t.specular_nohd_dynamic_m})
    changed = result.verdict_changes()
    if args.json:
        doc = {"targets": rows, "verdict_changes": changed,
               "observers": [{"name": n, "static_irradiance_w_m2": float(s_), "peak_irradiance_w_m2": float(p_)}
                             for n, s_, p_ in zip(result.observers.labels, result.observers.static_irradiance_w_m2,
                                                  result.observers.peak_irradiance_w_m2)]}
        out.write(json.dumps(doc, indent=1) + "\n")
    else:
        out.write(f"Static vs dynamic reflectance, scene {result.scene.name!r} (MPE {result.mpe_w_m2:.6g} W/m^2)\n")
        for r in rows:
            line = f"  {r['target']}: NOHD static {r['nohd_static_m']:.4g} m -> dynamic {r['nohd_dynamic_m']:.4g} m; " \
                   f"keep-out volume {r['keepout_volume_static_m3']:.4g} -> {r['keepout_volume_dynamic_m3']:.4g} m^3"
            if r["state"]:
                line += f" ({_state_span(r['state'], r['state_range'])})"
            out.write(line + "\n")
            if r["specular_nohd_static_m"] is not None:
                out.write(f"    mirror lobe beyond the target: {r['specular_nohd_static_m']:.4g} m -> {r['specular_nohd_dynamic_m']:.4g} m\n")
        out.write(f"  observers whose verdict changes: {', '.join(changed) if changed else 'none'}\n")
    return _finish(args, result)


def _as_study(name):
    """The study ``name`` names (a study TOML: a ``scene`` key and no ``[laser]``, or a
    bundled study), validated as ``hazard study`` would before work; None if it is not one."""
    import scenes

    from hazard.drivers.study import examples, load_study

    path = Path(name)
    if not path.exists():
        return load_study(name) if name in examples() and name not in scenes.examples() else None
    from brdfmodels.fileio import read_toml

    try:
        d = read_toml(path)
    except ValueError:
        return None
    return load_study(path) if isinstance(d, dict) and "scene" in d and "laser" not in d else None


def _validate_study(study, args, out):
    import scenes

    from hazard.drivers.study import base_data, scenarios

    base, base_dir = base_data(study)  # its warnings, as the run's answers would put them above their verdicts
    warned = list(scenes.from_data(base, source=f"scene={study.scene!r}", base_dir=base_dir).warnings)
    info = {"study": study.name, "scene": study.scene, "kind": study.kind, "scenarios": len(scenarios(study)), "warnings": warned}
    out.write((json.dumps(info, indent=1) if args.json else
               f"{args.scene}: valid study {study.name!r}: {info['scenarios']} scenario(s) over scene {study.scene!r}"
               + (f"\n  CHECK FIRST: {len(warned)} warning(s) of the base scene that can change a verdict:\n"
                  + "\n".join(f"    warning: {w}" for w in warned) if warned else "")) + "\n")
    return EXIT_OK


def _cmd_validate(args, out, err):
    import scenes

    try:
        scene = _load_scene(args.scene, err)
    except scenes.SceneError:  # a study file? then the checks of hazard study
        study = _as_study(args.scene)
        if study is None:
            raise
        return _validate_study(study, args, out)
    info = {
        "scene": scene.name,
        "source": scene.source,
        "sha256": scene.text_sha256,
        "targets": [{"name": t.name, "shape": t.spec.shape, "material": t.material.name, "dynamic": t.material.is_dynamic}
                    for t in scene.targets],
        "occluders": len(scene.occluders),
        "terrain": scene.terrain is not None,
        "observer_points": len(scene.observers),
        "offset_m": scene.offset_m.tolist(),
        "warnings": list(scene.warnings),
    }
    from scenes.summary import summary_lines

    info.update({"units_as_written": scene.units_as_written, "beam_conventions": scene.beam_conventions,
                 "summary": summary_lines(scene)})
    if args.json:
        out.write(json.dumps(info, indent=1) + "\n")
    else:
        out.write(f"{scene.source}: valid scene {scene.name!r}: {len(scene.targets)} target(s), {len(scene.occluders)} occluder(s), "
                  f"{'terrain, ' if scene.terrain is not None else ''}{len(scene.observers)} observer point(s); "
                  f"local origin {scene.offset_m.tolist()} m\n" + "".join(f"  {line}\n" for line in info["summary"]))
        if info["warnings"]:  # the slips a run would put above its verdict, visible before the run (issue 31)
            out.write(f"  CHECK FIRST: {len(info['warnings'])} warning(s) that can change a verdict:\n"
                      + "".join(f"    warning: {w}\n" for w in info["warnings"]))
    return EXIT_OK


def _cmd_models(args, out, err):
    import brdfmodels

    if args.materials:
        from brdfmodels.library import LIBRARY

        rows = {k: {"kind": e.kind, "params": e.params, "source": e.source, "wavelength_nm": e.wavelength_nm, "note": e.note}
                for k, e in sorted(LIBRARY.items())}
        if args.json:
            out.write(json.dumps(rows, indent=1) + "\n")
        else:
            for k, e in rows.items():
                at = f" at {e['wavelength_nm']:g} nm" if e["wavelength_nm"] else ""
                out.write(f"{k}: {e['kind']} {e['params']}{at}\n    source: {e['source']}" + (f"\n    {e['note']}" if e["note"] else "") + "\n")
        return EXIT_OK
    names = brdfmodels.available_models()
    out.write((json.dumps(names) if args.json else "\n".join(names)) + "\n")
    return EXIT_OK


def _cmd_schema(args, out, err):
    import scenes

    if args.report and args.markdown:
        err.write("hazard schema: --report and --markdown: choose one (--report prints report.json's JSON schema)\n")
        return EXIT_ERROR
    if args.report:
        from hazard.outputs.report_schema import report_schema

        text = json.dumps(report_schema(), indent=1)
    elif args.markdown:
        from scenes.reference import schema_markdown

        text = schema_markdown()
    else:
        text = json.dumps(scenes.json_schema(), indent=1)
    if args.output:
        from hazard.outputs.report import atomic_write_text

        atomic_write_text(Path(args.output), text)
    else:
        out.write(text.rstrip("\n") + "\n")
    return EXIT_OK


def _check_new(path, force):
    if Path(path).exists() and not force:
        raise ValueError(f"{path} exists: pass --force to overwrite")


def _basis_arg(text):
    import brdfmodels

    try:
        parts = [int(x) for x in text.split(",")]
    except ValueError:
        raise ValueError(f"--basis={text!r}: expected four integers lh_max,mh_max,ld_max,md_max") from None
    if len(parts) != 4:
        raise ValueError(f"--basis={text!r}: expected four integers lh_max,mh_max,ld_max,md_max")
    return brdfmodels.SHBasis(*parts)


def _print_report(out, title, rows, as_json, extra=None):
    from brdfmodels.accuracy import format_table

    if as_json:
        out.write(json.dumps({"report": title, "rows": rows, **(extra or {})}, indent=1, default=str) + "\n")
    else:
        out.write(format_table(rows, title) + "\n")
        for k, v in (extra or {}).items():
            out.write(f"  {k}: {v}\n")


def _nlopt_fit_parser(fsub, name, helptext, maxeval):
    """A ``hazard fit`` subcommand of a parametric nlopt fit (ts5, abg): input table,
    output, global method, seed, budget, and the output switches."""
    q = fsub.add_parser(name, help=helptext)
    q.add_argument("inputs", nargs=1, help="samples table (CSV)")
    q.add_argument("-o", "--output", required=True, help="model file to write (JSON)")
    q.add_argument("--method", default="crs2", help="global nlopt method: crs2 (default), esch, isres, direct-l, mlsl")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--maxeval", type=int, default=maxeval, help="global-stage budget")
    q.add_argument("--force", action="store_true")
    q.add_argument("--json", action="store_true")
    q.add_argument("--quiet", action="store_true", help="no progress bars")
    _fit_wavelength_option(q)
    return q


def _fit_wavelength_option(q):
    add_quantity_option(q, "--wavelength-nm", "nm", "the laser's wavelength [nm]: a measured file's rows (CSV wavelength_nm "
                        "column) or value columns (ASTM 532nm, 1064nm) there, the two nearest interpolated with a note; "
                        "needed when the file holds several wavelengths")


def _state_nodes_args(state_text, states_text):
    """``--state`` and ``--states`` as fit_dynamic_sh takes them: one name and its nodes,
    or two names and a node list for each (``--states 'a,b;c,d'``)."""
    names = [n.strip() for n in state_text.split(",")]
    if len(names) > 2 or not all(names):
        raise ValueError(f"--state={state_text!r}: expected a state name, or two separated by a comma")
    if not states_text:
        raise ValueError("--states: give the state values to group at, e.g. --states 0,5,10 (two states: '0,1;0,0.5,1')")
    parts = states_text.split(";")
    if len(parts) != len(names):
        raise ValueError(f"--states={states_text!r}: expected {len(names)} node list(s) separated by ';' for --state={state_text!r}")
    try:
        nodes = [[float(x) for x in p.split(",")] for p in parts]
    except ValueError:
        raise ValueError(f"--states={states_text!r}: expected numbers separated by commas") from None
    return (names[0], nodes[0]) if len(names) == 1 else (names, nodes)


def _cmd_fit(args, out, err):
    """``hazard fit``: its 1-3 files (model, envelope, samples; separate paths) are written
    as one unit (:func:`brdfmodels.output_sets.output_files`): on any error none is created or replaced."""
    import io

    from brdfmodels.output_sets import output_files

    from hazard.progress import progress_to

    finals = [args.output] + [p for p in (getattr(args, "envelope_output", None), getattr(args, "samples_output", None)) if p]
    for p in finals:
        _check_new(p, args.force)
    text = io.StringIO()  # stdout is written once the files are in place: no "wrote" for a file never switched in
    with progress_to(None if getattr(args, "quiet", False) else err), output_files(finals) as files:  # bars on a terminal only
        args.stage = files.stage
        for line in files.recovered:
            print(f"hazard: note: {line}", file=err)
        if args.fit_kind == "oxidation":
            code = _fit_oxidation(args, text)
        else:
            samples = _fit_samples(args)
            for note in samples.info.get("notes", ()):  # a wavelength interpolated between two measured ones
                print(f"hazard: note: {note}", file=err)
            if getattr(args, "wavelength_nm", None) is not None and not samples.info.get("by_wavelength"):
                print(f"hazard: note: {Path(args.inputs[0]).name} names no wavelength (no wavelength_nm column or columns "
                      f"named by wavelength): --wavelength-nm {args.wavelength_nm:g} is not checked against it; its values "
                      f"are fitted as measured", file=err)
            fit = {"ts5": _fit_ts5, "abg": _fit_abg}.get(args.fit_kind, _fit_sh)
            code = fit(args, text, samples)
    out.write(text.getvalue())
    return code


def _fit_oxidation(args, out):
    from brdfmodels import fitting
    from brdfmodels.fileio import atomic_write_text

    from brdfmodels.io import read_csv_columns

    data = read_csv_columns(args.inputs[0], ["time_s", "temperature_k", "reflectance"], "oxidation series")
    r = fitting.fit_oxidation(data["time_s"], data["temperature_k"], data["reflectance"])
    doc = {**r.model.to_dict(), "reflectance0": r.reflectance0, "reference_temperature_k": r.reference_temperature_k,
           "rate_at_reference_per_s": r.rate_at_reference_per_s, "ci95": {k: list(map(float, v)) for k, v in r.ci95.items()},
           "correlation_t0_log_d0": r.correlation_t0_log_d0, "condition_number": r.condition_number, "residual_rms": r.residual_rms}
    atomic_write_text(args.stage(args.output), json.dumps(doc, indent=1))
    if args.json:
        out.write(json.dumps(doc, indent=1) + "\n")
    else:
        out.write(f"oxidation fit: {r.model}; R0 = {r.reflectance0:.4g}\n")
        for k, (lo, hi) in r.ci95.items():
            out.write(f"  95 % CI {k}: [{lo:.5g}, {hi:.5g}]\n")
        out.write(f"  fitted as k_ref at T_ref = {r.reference_temperature_k:.1f} K; corr(T0, ln d0) = {r.correlation_t0_log_d0:.4f}\n")
        out.write(f"  wrote {args.output}\n")
    return EXIT_OK


def _fit_samples(args):
    """The samples to fit: witness-screen tests reduced (a bar per test), or a table."""
    from brdfmodels import screen

    from hazard.progress import terminal_bar

    if args.fit_kind != "screen":
        from brdfmodels.io import read_samples

        return read_samples(args.inputs[0], wavelength_nm=args.wavelength_nm)  # own CSV/Parquet, .bsdf, ASTM, angle CSV
    parts = []
    with terminal_bar(len(args.inputs), "reducing screen tests", unit="test", leave=True) as bar:
        for p in args.inputs:
            parts.append(screen.reduce_test(screen.load_test(p)))
            bar.update()
    samples = screen.Samples.concatenate(parts)
    if args.samples_output:
        samples.write(args.stage(args.samples_output))
    return samples


def _fit_ts5(args, out, samples):
    import brdfmodels
    from brdfmodels import fitting

    from hazard.progress import progress_callback

    if args.report:
        rows = fitting.compare_ts5_methods(samples.wi, samples.wo, samples.brdf_per_sr,
                                           progress=progress_callback("five-parameter methods", unit="fit"))
        _print_report(out, "five-parameter fit: error vs evaluations vs seconds", rows, args.json)
    r = fitting.fit_ts5(samples.wi, samples.wo, samples.brdf_per_sr, method=args.method, seed=args.seed, maxeval=args.maxeval,
                        progress=progress_callback("five-parameter fit", unit="eval"))
    brdfmodels.save(r.model, args.stage(args.output))
    _print_report(out, "five-parameter fit", [r.summary()], args.json, {"wrote": str(args.output)})
    return EXIT_OK


def _fit_abg(args, out, samples):
    import brdfmodels
    from brdfmodels.fit_scatter import fit_abg

    r = fit_abg(samples.wi, samples.wo, samples.brdf_per_sr, method=args.method, seed=args.seed, maxeval=args.maxeval,
                weights=samples.weight)
    brdfmodels.save(r.model, args.stage(args.output))
    d = r.details
    extra = {"A": f"{d['p_a']:.6g} +- {d['stderr_a']:.3g} (1 sigma, from the Jacobian at the optimum)",
             "B": f"{d['p_b']:.6g} +- {d['stderr_b']:.3g}", "g": f"{d['p_g']:.6g} +- {d['stderr_g']:.3g}",
             "at a bound of the search box": ", ".join(d["at_bound"]) or "none", "wrote": str(args.output)}
    _print_report(out, "ABg fit (log residuals)", [r.summary()], args.json, extra)
    return EXIT_OK


def _fit_sh(args, out, samples):
    import brdfmodels
    from brdfmodels import fitting

    from hazard.progress import progress_callback

    basis = _basis_arg(args.basis)
    if args.report:
        from brdfmodels import validation

        state, nodes = _state_nodes_args(args.state, args.states) if args.state else (None, None)
        one = isinstance(state, str)  # folds within each state group (two states: pooled, as before)
        best, table = validation.choose_sh_basis(samples, state=state if one else None, states=nodes if one else None,
                                                 progress=progress_callback("leave-one-test-out settings", unit="setting"))
        if not args.json:  # the per-fold errors are in --json; the text table keeps one line per setting
            table = [{k: v for k, v in r.items() if k != "fold_log_rms"} for r in table]
        _print_report(out, "leave-one-test-out (scored by the worst fold): basis orders and fan-out", table, args.json, {"best": best})
    if args.state:
        state, nodes = _state_nodes_args(args.state, args.states)
        res = fitting.fit_dynamic_sh(samples, basis, nodes, state=state, fanout=args.fanout, smoothing=args.smoothing,
                                     progress=progress_callback("SH fit per state", unit="state"))
        model = res.model
        rows = [{"state": k, **v.summary()} for k, v in res.fits.items()]
    else:
        r = fitting.fit_sh(samples.wi, samples.wo, samples.brdf_per_sr, basis, fanout=args.fanout, weights=samples.weight,
                             smoothing=args.smoothing)
        model = r.model
        rows = [r.summary()]
    extra = {"wrote": str(args.output)}
    env = None
    if args.envelope:  # computed before either file is written: a failed envelope leaves no new model beside an old envelope
        if not args.envelope_output:
            raise ValueError("--envelope-output: required with --envelope")
        env = fitting.envelope_paper(model, samples) if args.envelope == "paper" else fitting.envelope_sh(samples, basis, fanout=args.fanout)
        extra.update({"envelope": env.summary(), "envelope_file": str(args.envelope_output)})
    brdfmodels.save(model, args.stage(args.output))
    if env is not None:
        brdfmodels.save(env.model, args.stage(args.envelope_output))
    _print_report(out, "spherical-harmonic fit", rows, args.json, extra)
    return EXIT_OK


def _cmd_study(args, out, err):
    from hazard.drivers.study import load_study, progress_bar, run_study

    study = load_study(args.study)
    res = run_study(study, args.output, scheduler=args.scheduler, serial=args.serial, n_workers=args.workers, force=args.force,
                    progress=None if args.quiet else progress_bar(err), keep_going=args.keep_going)
    if args.json:
        out.write(json.dumps(res.summary, indent=1) + "\n")
    else:
        out.write(f"study {study.name!r}: {res.summary['scenarios']} scenarios ({res.ran} run now, {res.skipped} already done), "
                  f"{res.failed} failed\n")
        for col, st in res.summary["statistics"].items():
            out.write(f"  {col:28s} p50 {st['p50']:.4g}  p95 {st['p95']:.4g}  max {st['max']:.4g}\n")
        for f in res.summary["failures"][:5]:
            out.write(f"  failed scenario {f['id']}: {f['error']}\n")
        out.write(f"  wrote {res.outdir / 'results.csv'}, {res.outdir / 'summary.json'}\n")
    if not res.ok:
        s = res.summary
        stop = f", {s['not_run']} not run (stopped at the first failure; --keep-going runs the rest)" if s["not_run"] else ""
        kinds = "; ".join(_one_line(e, 300) for e in s["failure_kinds"].values())
        err.write(f"hazard study: error: {s['failed']} of {s['scenarios']} scenarios failed{stop}; first of each kind: {kinds}\n")
        return EXIT_FAILED
    return EXIT_OK


def _risk_listing(doc, out, shown=20, unresolved_shown=5):
    """hazard risk's lines: the resolved points (an exceedance seen) by the estimate first,
    then the unresolved (zero hits, only an upper bound) by their bound; the rest counted."""
    from hazard.outputs.risk_page import split_rows

    resolved, unresolved = split_rows(doc["observers"])
    out.write(f"  resolved (at least one exceedance in the draws; highest estimate first): {len(resolved)} point(s)\n")
    for r in resolved[:shown]:
        drv = r["sensitivity"]["driver"] if r["sensitivity"] else None
        out.write(f"    {r['name']}: {r['statement']}" + (f"; driven by {drv}" if drv else "") + "\n")
    if len(resolved) > shown:
        out.write(f"    ... {len(resolved) - shown} more resolved point(s) in risk.csv\n")
    if unresolved:
        hi = unresolved[0]["probability_ci_high"]
        out.write(f"  unresolved (no exceedance in the draws: only the 95 % upper bound is known, the highest {hi:.2g}): "
                  f"{len(unresolved)} point(s)\n")
        for r in unresolved[:unresolved_shown]:
            out.write(f"    {r['name']}: {r['statement']}\n")
        if len(unresolved) > unresolved_shown:
            out.write(f"    ... {len(unresolved) - unresolved_shown} more unresolved point(s) in risk.csv\n")


def _cmd_risk(args, out, err):
    from hazard.progress import progress_callback
    from hazard.drivers.risk import run_risk

    from hazard.drivers.risk.run import ChunksFailed

    scene = _load_scene(args.scene, err)
    try:
        res = run_risk(scene, args.output, draws=args.draws, seed=args.seed, sampling=args.sampling, sensitivity_draws=args.sensitivity_draws,
                       serial=args.serial, workers=args.workers, scheduler=args.scheduler, force=args.force, keep_going=args.keep_going,
                       progress=None if args.quiet else progress_callback("risk chunks", unit="chunk", leave=True, stream=err))
    except ChunksFailed as exc:
        err.write(f"hazard risk: error: {_one_line(exc, 900)}\n")
        return EXIT_FAILED
    doc = res.doc
    if args.json:
        out.write(json.dumps(doc["observers"], indent=1) + "\n")
        return EXIT_OK
    out.write(f"risk {scene.name!r}: {doc['draws']:,} draws ({doc['sampling']} sampling), MPE {doc['mpe_w_m2']:.4g} W/m^2; "
              f"{doc['run']['ran']} chunk(s) run now, {doc['run']['reused']} reused\n")
    _risk_listing(doc, out)
    for n in doc["notes"]:
        out.write(f"  note: {n}\n")
    out.write(f"  wrote {', '.join(str(res.outdir / f) for f in doc['files'])}\n")
    return EXIT_OK


def _cmd_render(args, out, err):
    from brdfmodels.output_sets import output_unit

    from hazard.pictures import render
    from hazard.progress import progress_to

    with output_unit(args.output, command="render", overwrite=args.force, force=args.force,  # all renders as one unit
                     source=_scene_source(args.scene)) as unit:
        err.write("".join(f"hazard: {n}\n" for n in unit.notes))
        result = _analyse(argparse.Namespace(scene=args.scene, backend="embree", quiet=args.quiet), err)
        with progress_to(None if args.quiet else err):  # bars on a terminal only
            paths = render.keepout(result, unit.stage, lobe_resolution_deg=args.resolution_deg, force=args.force)
            lines = [f"  wrote {unit.final(p)}" for k, p in paths.items() if k not in ("png", "layout", "figures")]
            from hazard.pictures.figures import run_figures, write_figures

            if not args.no_animation and result.states:  # before the 2-D pictures: figures.json lists the GIF too
                anim = render.animate_lobe(result, unit.stage)
                lines.append(f"  wrote {unit.final(anim.get('gif', anim['frames'][0].parent))}")
                paths["figures"].update(anim.get("figures", {}))
            say = None if args.quiet else (lambda name: err.write(f"hazard: drawing {name}...\n"))
            lines += [f"  wrote {unit.final(p)}" for p in write_figures(run_figures(result, progress=say, rendered=paths["figures"]),
                                                                         unit.stage)]
    out.write(f"renders of {result.scene.name!r}\n" + "\n".join(lines) + "\n")
    return EXIT_OK


def _cmd_convergence(args, out, err):
    from hazard.drivers import convergence as conv
    from hazard.progress import progress_stream, progress_to
    from hazard.outputs.report import json_safe

    with progress_to(None if args.quiet else err):
        # a bar of the runs on a terminal; elsewhere one line per run (as the stage lines of run)
        lines = None if progress_stream() is not None else _stage_lines(args, err)
        rep = conv.convergence(args.scene, knobs=args.knob, tolerance=args.tolerance, progress=lines)
    if args.plot:
        conv.plot(rep, args.plot)
    if args.json:  # a relative error against a zero reference is inf: written "inf" as in report.json
        doc = json_safe({"rows": rep.rows, "recommended": rep.recommended, "tolerance": rep.tolerance})
        out.write(json.dumps(doc, indent=1) + "\n")
    else:
        from brdfmodels.accuracy import format_table

        out.write(format_table(rep.rows, "convergence (rel_error_*: relative error against the finest run of each knob, unitless)") + "\n")
        out.write(f"recommended within {rep.tolerance:g}: " + ", ".join(f"{k} = {v}" for k, v in rep.recommended.items()) + "\n")
    return EXIT_OK


def _write_review(out_dir, args, err, pdf=False) -> list:
    """map.html (hazard.outputs.map_page) then hazard.outputs.review.write_review, with the stage lines of
    the other verbs on ``err``; a PdfError carries both pages in ``written``."""
    from hazard.outputs.map_page import write_map_page
    from hazard.outputs.review import PdfError, write_review

    say = _stage_lines(args, err)
    page = write_map_page(out_dir, progress=say)
    try:
        return [page, *write_review(out_dir, pdf=pdf, progress=say, observers=getattr(args, "observer", None) or ())]
    except PdfError as exc:
        exc.written = [page, exc.html]
        raise


def _cmd_report(args, out, err):
    from brdfmodels.output_sets import output_unit, read_sources

    from hazard.outputs.review import PdfError, read_report

    read_report(args.out_dir)  # a clear line naming the folder before anything is staged
    failed = None
    with output_unit(args.out_dir, command="report", overwrite=True, force=True,  # the run's files are kept
                     source=read_sources(Path(args.out_dir)).get("run")) as unit:  # the page is of the run's scene
        err.write("".join(f"hazard: {n}\n" for n in unit.notes))
        unit.carry()  # the page reads report.json and the pictures in the folder
        try:
            paths = _write_review(unit.stage, args, err, pdf=args.pdf)
        except PdfError as exc:  # the HTML is written (and switched in); the PDF is not
            failed, paths = exc, exc.written
    paths = [unit.final(p) for p in paths]
    if failed is not None:
        out.write("".join(f"wrote {p}\n" for p in paths))
        err.write(f"hazard report: error: {_one_line(str(failed).replace(str(unit.stage), str(unit.given)))}\n")
        return EXIT_INTERNAL
    out.write("".join(f"wrote {p}\n" for p in paths))
    return EXIT_OK


_COMMANDS = {"risk": _cmd_risk, "report": _cmd_report, "render": _cmd_render, "convergence": _cmd_convergence, "study": _cmd_study, "fit": _cmd_fit, "mpe": _cmd_mpe, "nohd": _cmd_nohd, "run": _cmd_run, "compare": _cmd_compare, "validate": _cmd_validate,
             "models": _cmd_models, "schema": _cmd_schema}


def _input_of(args) -> str:
    """The input a command works on, for error lines."""
    for key in ("scene", "study"):
        if getattr(args, key, None):
            return str(getattr(args, key))
    if getattr(args, "inputs", None):
        return ", ".join(map(str, args.inputs))
    return ""


def _one_line(text, limit=600) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def main(argv=None, *, stdout=None, stderr=None) -> int:
    """Run the command line; returns the exit code (0 ok, 1 internal error, 2 bad input,
    3 hazard with --fail-on-hazard). One error boundary: every exception becomes one line
    on stderr naming the input; ``--debug`` shows the traceback instead."""
    out = stdout or sys.stdout
    err = stderr or sys.stderr
    as_command = argv is None  # the console script / python -m hazard: dependency noise handled (hazard._noise)
    argv = [str(a) for a in (sys.argv[1:] if argv is None else argv)]
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    if argv[:1] == ["--version"]:  # to the given stdout (argparse's version action writes to sys.stdout)
        out.write(_version_line() + "\n")
        return EXIT_OK
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        err.write(f"{exc}\n")
        return EXIT_ERROR
    except SystemExit as exc:  # --help
        return int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_ERROR
    from hazard._cli_env import headless
    from hazard.outputs.report import OutputExistsError

    where = _input_of(args)
    try:
        with headless():  # the CLI's process draws headless; the library itself changes no global state
            if not as_command:
                return _COMMANDS[args.verb](args, out, err)
            from hazard._noise import quiet_dependencies

            with quiet_dependencies(err, args.verb, serial=bool(getattr(args, "serial", False))):
                return _COMMANDS[args.verb](args, out, err)
    except (ValueError, OutputExistsError) as exc:  # bad input (SceneError is a ValueError)
        if debug:
            raise
        msg = _one_line(exc)
        if where and where not in msg:
            msg = f"{where}: {msg}"
        err.write(f"hazard {args.verb}: error: {msg}\n")
        return EXIT_ERROR
    except KeyboardInterrupt:
        if debug:
            raise
        err.write(f"hazard {args.verb}: interrupted\n")
        return 130
    except BrokenPipeError:  # the reader went away (hazard run ... | head): stop quietly, as after SIGPIPE
        if out is sys.stdout:
            try:
                sys.stdout = open(os.devnull, "w")  # Python's own flush at exit must not fail again
            except OSError:
                pass
        return EXIT_BROKEN_PIPE
    except (Exception, RecursionError, MemoryError) as exc:  # anything else: still one line
        if debug:
            raise
        if isinstance(exc, ImportError):
            what = f"a dependency is missing: {_one_line(exc)}"
        elif isinstance(exc, MemoryError):
            what = "out of memory (lower the observer count, beam_samples or the keep-out resolution)"
        elif isinstance(exc, OSError):
            what = f"{exc.strerror or type(exc).__name__}{': ' + str(exc.filename) if exc.filename else ''}"
        else:
            what = f"{type(exc).__name__}: {_one_line(exc, 300)}"
        err.write(f"hazard {args.verb}: internal error{' on ' + where if where else ''}: {what} (run again with --debug for the traceback)\n")
        return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
