"""3-D renders of keep-out zones (pyvista, off-screen), VTK files for ParaView, animations.

Imported only when a render is asked for (``hazard render``, ``hazard.render``): pyvista
and VTK are heavy. What a render shows, in the scene's local coordinates (the float64
offset to the file's coordinates is printed in the title):

* targets, occluders and terrain (terrain coloured by the hazardous ground footprint:
  dynamic-only cells orange, cells hazardous in both analyses red; a cell is drawn
  hazardous if any of its corners is - conservative at the terrain's resolution, while
  the reported area counts nodes x spacing^2);
* the laser beam up to each spot, and mirror beams up to their hazard distance;
* the static (blue) and dynamic (orange, translucent) hazard lobes: the surface at the
  NOHD in every reflection direction;
* observers coloured by log10(hazard ratio) with a scale bar;
* the maximum NOHD of each target, static and dynamic, annotated.

The VTK multiblock (``keepout.vtm``) carries the same meshes with unit-suffixed arrays:
``nohd_m`` on lobes, ``hazard_ratio`` and ``peak_irradiance_w_m2`` on observers,
``hazardous_static``/``hazardous_dynamic`` on the terrain.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

import pyvista as pv

from .beam import perp_basis as _perp_basis
from .keepout import _range_fn
from .progress import terminal_bar

__all__ = ["keepout", "lobe_grid", "animate_lobe"]

pv.OFF_SCREEN = True
STATIC_COLOUR = "#1f77b4"
DYNAMIC_COLOUR = "#ff7f0e"


def lobe_grid(spot, mpe_w_m2, mu, states=None, resolution_deg=3.0) -> pv.StructuredGrid:
    """The hazard lobe of a spot as a surface: centroid + NOHD(w) w.

    The grid's pole is the mirror direction (where finite lobes peak), with rings at 0.1,
    0.3 and 1 deg around it, so a sharp specular tip is drawn at its full length;
    directions below the surface have NOHD 0."""
    fn = _range_fn(spot, mpe_w_m2, mu, 1.0, states)
    wi = -spot.mean_incoming @ spot.mean_frame.T  # incidence in the material frame
    m = wi * np.array([-1.0, -1.0, 1.0])
    e1, e2 = _perp_basis(m)
    th = np.unique(np.concatenate([[0.0, 0.1, 0.3, 1.0], np.arange(resolution_deg, 180.0 + 1e-9, resolution_deg)]))
    th = np.radians(th)
    ph = np.radians(np.arange(-180.0, 180.0 + 1e-9, resolution_deg))
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    w = np.cos(tt)[..., None] * m + np.sin(tt)[..., None] * (np.cos(pp)[..., None] * e1 + np.sin(pp)[..., None] * e2)
    r = np.where(w[..., 2] > 0, fn(w.reshape(-1, 3)).reshape(tt.shape), 0.0)
    world = w @ spot.mean_frame  # material frame -> scene frame
    pts = spot.centroid + r[..., None] * world
    grid = pv.StructuredGrid(pts[..., 0], pts[..., 1], pts[..., 2])
    grid["nohd_m"] = r.ravel(order="F")
    return grid


def _mesh(vertices, faces):
    f = np.hstack([np.full((len(faces), 1), 3), faces]).ravel()
    return pv.PolyData(np.asarray(vertices, float), f)


def _scene_blocks(result, lobe_resolution_deg):
    scene = result.scene
    blocks = pv.MultiBlock()
    for t in scene.targets:
        blocks[f"target_{t.name}"] = _mesh(t.mesh.vertices, t.mesh.faces)
    for i, m in enumerate(scene.occluders):
        blocks[f"occluder_{i}"] = _mesh(m.vertices, m.faces)
    if scene.terrain is not None:
        tm = scene.terrain.mesh()
        terr = _mesh(tm.vertices, tm.faces)
        if result.footprint_static is not None:
            terr["hazardous_static"] = result.footprint_static.mask.ravel().astype(np.uint8)
            terr["hazardous_dynamic"] = result.footprint_dynamic.mask.ravel().astype(np.uint8)
        blocks["terrain"] = terr
    for sp in result.spots:
        k = sp.target.index
        states = result.states.get(k)
        blocks[f"lobe_static_{sp.target.name}"] = lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m,
                                                            None if states is None else states[:1], lobe_resolution_deg)
        if states is not None:
            blocks[f"lobe_dynamic_{sp.target.name}"] = lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, np.unique(states), lobe_resolution_deg)
        blocks[f"beam_{sp.target.name}"] = pv.Line(scene.laser_position_m, sp.centroid)
    if len(result.observers):
        obs = pv.PolyData(scene.observers.positions_m)
        obs["hazard_ratio"] = result.hazard_ratio
        obs["peak_irradiance_w_m2"] = result.observers.peak_irradiance_w_m2
        obs["static_irradiance_w_m2"] = result.observers.static_irradiance_w_m2
        blocks["observers"] = obs
    return blocks


def _bounds_union(meshes):
    b = np.array([m.bounds for m in meshes], float).reshape(len(meshes), 3, 2)
    return np.array([b[:, :, 0].min(0), b[:, :, 1].max(0)]).T  # (3, 2)


def _expand(bounds, factor, minimum):
    c = bounds.mean(1)
    half = np.maximum((bounds[:, 1] - bounds[:, 0]) / 2 * factor, minimum)
    return np.stack([c - half, c + half], 1)


def _draw(result, blocks, bounds, window_size, title):
    scene = result.scene
    p = pv.Plotter(off_screen=True, window_size=list(window_size))
    p.set_background("white")
    box = pv.Box(bounds.ravel())
    labelled = set()

    def label(text):
        if text in labelled:
            return None
        labelled.add(text)
        return text

    extent = float(np.max(bounds[:, 1] - bounds[:, 0]))
    tube = max(scene.spec.laser.beam_diameter_m, 2e-3 * extent)
    for name in blocks.keys():
        mesh = blocks[name]
        if name.startswith("target_"):
            p.add_mesh(mesh, color="#555555")
        elif name.startswith("occluder_"):
            p.add_mesh(mesh, color="#8c6d31", opacity=0.8, label=label("occluder"))
        elif name == "terrain":
            m = mesh.clip_box(box, invert=False) if extent < np.ptp(np.array(mesh.bounds).reshape(3, 2), axis=1).max() else mesh
            if m.n_points == 0:
                continue
            if "hazardous_static" in m.array_names:
                # categorical per cell, conservative: a cell is hazardous if any corner is
                lvl_pt = m["hazardous_static"].astype(float) + m["hazardous_dynamic"].astype(float)
                faces = m.faces.reshape(-1, 4)[:, 1:] if m.faces.size else np.empty((0, 3), int)
                m.cell_data["footprint_level"] = lvl_pt[faces].max(axis=1) if len(faces) else np.empty(0)
                p.add_mesh(m, scalars="footprint_level", preference="cell", cmap=["#cfe3c3", "#ff9f40", "#d62728"], clim=[0, 2],
                           n_colors=3, show_scalar_bar=False, opacity=0.9,
                           label=label("ground at eye height (red: hazardous, orange: dynamic only)"))
            else:
                p.add_mesh(m, color="#cfe3c3", opacity=0.9)
        elif name.startswith("lobe_static_"):
            p.add_mesh(mesh, color=STATIC_COLOUR, opacity=0.85, label=label("static hazard lobe"))
        elif name.startswith("lobe_dynamic_"):
            p.add_mesh(mesh, color=DYNAMIC_COLOUR, opacity=0.35, label=label("dynamic hazard lobe"))
        elif name.startswith("beam_"):
            p.add_mesh(mesh.tube(radius=tube), color="#d62728", label=label("laser beam"))
        elif name == "observers":
            mesh["log10_hazard_ratio"] = np.log10(np.maximum(mesh["hazard_ratio"], 1e-6))
            p.add_mesh(mesh, scalars="log10_hazard_ratio", cmap="RdYlGn_r", clim=[-3, 1], point_size=9, render_points_as_spheres=True,
                       scalar_bar_args={"title": "log10 hazard ratio (peak / MPE)", "color": "black"})
    for sp, tr in zip(result.spots, result.targets):
        if tr.specular_nohd_dynamic_m:
            length = min(tr.specular_nohd_dynamic_m, 0.8 * extent)
            end = sp.centroid + np.asarray(tr.specular_direction) * length
            shown = "" if length >= tr.specular_nohd_dynamic_m else f" (drawn to {length:.3g} of {tr.specular_nohd_dynamic_m:.4g} m)"
            p.add_mesh(pv.Line(sp.centroid, end).tube(radius=tube), color="#9467bd", label=label("mirror beam, to its NOHD" + shown))
    labels, points = [], []
    for sp, tr in zip(result.spots, result.targets):
        d = tr.to_dict()
        labels.append(f"{tr.name}: NOHD static {d['nohd_static_m']:.3g} m, dynamic {d['nohd_dynamic_m']:.3g} m")
        points.append(sp.centroid + tr.dynamic_lobe.max_direction_world * tr.dynamic_lobe.max_range_m)
    if points:
        p.add_point_labels(np.array(points), labels, font_size=12, text_color="black", shape_opacity=0.6, always_visible=True)
    p.add_text(f"{title}\nMPE {result.mpe_w_m2:.4g} W/m^2; local origin at {scene.offset_m.tolist()} m", font_size=10, color="black")
    if labelled:
        p.add_legend(bcolor="white", face="rectangle", size=(0.3, 0.12), loc="upper right")
    p.show_axes()
    p.camera_position = "iso"
    p.reset_camera(bounds=bounds.ravel())
    return p


def keepout(result, outdir, *, lobe_resolution_deg=3.0, window_size=(1280, 900), vtk=True, force=False) -> dict:
    """Render the keep-out zones of an analysis (off-screen) to ``outdir/keepout.png`` -
    framed on the hazard lobes - and ``outdir/overview.png`` - the whole scene with every
    observer -, plus ``outdir/keepout.vtm`` for ParaView. Returns the paths written."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    png = out / "keepout.png"
    if png.exists() and not force:
        raise FileExistsError(f"{png} exists: pass --force to overwrite")
    blocks = _scene_blocks(result, lobe_resolution_deg)
    lobes = [blocks[k] for k in blocks.keys() if k.startswith("lobe_")]
    targets = [blocks[k] for k in blocks.keys() if k.startswith("target_")]
    focus = _expand(_bounds_union(lobes + targets), 1.3, 0.05 * max(1e-3, max(float(np.max(np.ptp(np.array(m.bounds).reshape(3, 2), axis=1))) for m in lobes + targets)))
    everything = [blocks[k] for k in blocks.keys() if not k.startswith("terrain")]
    if "terrain" in blocks.keys():
        everything.append(blocks["terrain"])
    whole = _expand(_bounds_union(everything), 1.05, 1e-3)
    paths = {}
    for name, bounds, title in (("keepout.png", focus, f"{result.scene.name}: keep-out zones (close view)"),
                                ("overview.png", whole, f"{result.scene.name}: overview")):
        p = _draw(result, blocks, bounds, window_size, title)
        tmp = out / f".{name}.tmp.png"
        p.screenshot(str(tmp))
        p.close()
        os.replace(tmp, out / name)
        paths[name.split(".")[0]] = out / name
    paths["png"] = paths["keepout"]
    if vtk:
        vtm = out / "keepout.vtm"
        blocks.save(str(vtm))
        paths["vtm"] = vtm
    return paths


def animate_lobe(result, outdir, *, max_frames=30, lobe_resolution_deg=4.0, window_size=(800, 600)) -> dict:
    """The dynamic lobe over the history: a GIF if imageio is installed, else PNG frames."""
    out = Path(outdir)
    frames_dir = out / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    dyn = [sp for sp in result.spots if sp.target.index in result.states]
    if not dyn:
        raise ValueError("animate_lobe: the scene has no dynamic material (nothing changes over time)")
    idx = np.unique(np.linspace(0, len(result.times_s) - 1, min(max_frames, len(result.times_s))).astype(int))
    # fixed camera: fit the envelope of all frames
    env = [lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, np.unique(result.states[sp.target.index]), lobe_resolution_deg) for sp in dyn]
    bounds = pv.MultiBlock(env).bounds
    paths = []
    with terminal_bar(len(idx), "lobe animation frames", unit="frame", leave=True) as bar:  # terminals only
        for n, i in enumerate(idx):
            p = pv.Plotter(off_screen=True, window_size=list(window_size))
            p.set_background("white")
            for sp in result.spots:
                p.add_mesh(_mesh(sp.target.mesh.vertices, sp.target.mesh.faces), color="#555555")
                st = result.states.get(sp.target.index)
                g = lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, None if st is None else st[i:i + 1], lobe_resolution_deg)
                p.add_mesh(g, scalars="nohd_m", cmap="viridis", clim=[0, max(e["nohd_m"].max() for e in env)],
                           scalar_bar_args={"title": "NOHD [m]", "color": "black"})
            p.add_text(f"t = {result.times_s[i]:.3g} s", font_size=12, color="black")
            p.show_bounds(bounds=bounds, color="black", font_size=8)
            p.camera_position = "iso"
            p.reset_camera(bounds=bounds)
            f = frames_dir / f"frame_{n:03d}.png"
            p.screenshot(str(f))
            p.close()
            paths.append(f)
            bar.update()
    result_paths = {"frames": paths}
    try:
        import imageio.v2 as imageio
    except ImportError:
        return result_paths
    gif = out / "lobe.gif"
    tmp = out / ".lobe.gif.tmp.gif"
    imageio.mimsave(tmp, [imageio.imread(f) for f in paths], duration=0.15)
    os.replace(tmp, gif)
    result_paths["gif"] = gif
    return result_paths
