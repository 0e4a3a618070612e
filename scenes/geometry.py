"""Triangle meshes of the scene's shapes, terrain, and observer layouts (numpy only).

Shapes are built in their own frame (x = tangent, y = normal x tangent, z = normal) and
placed at ``center_m``. Closed shapes have outward-facing triangles. Mesh files are read
with trimesh, imported only when a scene has one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import brdfmodels

__all__ = ["Mesh", "smooth_corner_normals", "shape_mesh", "terrain_heightfield", "observer_points", "Heightfield",
           "angle_to_sector_rad", "widened_azimuths_rad", "directions_in_sector", "direction_in_sector"]


@dataclass
class Mesh:
    """Vertices (V, 3) [m] and triangles (F, 3), plus what each triangle belongs to.

    ``analytic`` names a shape whose exact normal is known (sphere, cylinder side), with
    its parameters, so hits get exact normals instead of facet normals.
    """

    vertices: np.ndarray
    faces: np.ndarray
    analytic: tuple | None = None

    @property
    def face_normals(self) -> np.ndarray:
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def corner_normals(self) -> np.ndarray:
        """Unit normals (F, 3, 3) at each triangle's three corners: the smooth surface the
        mesh approximates (:func:`smooth_corner_normals`, crease ``CREASE_ANGLE_DEG``),
        computed once and kept."""
        cached = self.__dict__.get("_corner_normals")
        if cached is None:
            cached = smooth_corner_normals(self.vertices, self.faces)
            self.__dict__["_corner_normals"] = cached
        return cached

    def curved_faces(self) -> np.ndarray:
        """Per triangle: True where a corner normal differs from the facet's normal (by more
        than ``FLAT_TOLERANCE_RAD``), i.e. the facet approximates a curved surface."""
        cached = self.__dict__.get("_curved_faces")
        if cached is None:
            cn = self.corner_normals()
            fn = self.face_normals
            cached = np.any(np.linalg.norm(cn - fn[:, None, :], axis=2) > FLAT_TOLERANCE_RAD, axis=1)
            self.__dict__["_curved_faces"] = cached
        return cached


CREASE_ANGLE_DEG = 30.0  # facets meeting at a larger angle keep a sharp edge (trimesh's smooth_shade default)
FLAT_TOLERANCE_RAD = 1e-7  # a facet whose corner normals are this close to its own normal is flat


def smooth_corner_normals(vertices, faces, crease_deg=CREASE_ANGLE_DEG) -> np.ndarray:
    """Per triangle corner: the smooth surface's normal at that vertex, from the triangles
    meeting there whose normal is within ``crease_deg`` of this triangle's (sharper edges
    stay sharp), each weighted as in Max (1999), ``(e1 x e2) / (|e1|^2 |e2|^2)`` with e1, e2
    the triangle's edges from the vertex: exact for vertices on a sphere (a spherical
    mirror's focus is where it should be; trimesh's angle weights put it a few 1e-6 rad
    off, enough to move a 10 m focus by centimetres).

    Max, N., "Weights for computing vertex normals from facet normals", J. Graphics Tools
    4(2):1-6 (1999). Vertices at the same position are merged first (STL files repeat
    them per triangle); a neighbour wound the other way counts with its normal flipped.
    A flat mesh gets its facet normals back exactly (to rounding). Returns unit normals
    (F, 3, 3) [-].
    """
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    scale = max(float(np.ptp(v, axis=0).max()) if len(v) else 1.0, 1e-300)
    _, vid = np.unique(np.round((v - v.min(axis=0)) / scale * 1e9), axis=0, return_inverse=True)
    fv = vid.ravel()[f]  # (F, 3) merged vertex ids
    p = v[f]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    wts = np.empty((len(f), 3))  # Max's weight |e1 x e2| / (|e1|^2 |e2|^2) of each corner
    for k in range(3):
        a = p[:, (k + 1) % 3] - p[:, k]
        b = p[:, (k + 2) % 3] - p[:, k]
        wts[:, k] = np.linalg.norm(np.cross(a, b), axis=1) / np.maximum((a * a).sum(1) * (b * b).sum(1), 1e-300)
    inc_v, inc_f = fv.ravel(), np.repeat(np.arange(len(f)), 3)  # incidences (vertex, face)
    order = np.argsort(inc_v, kind="stable")
    starts = np.searchsorted(inc_v[order], np.arange(fv.max() + 2))
    table = np.full((len(starts) - 1, int(np.diff(starts).max())), -1, np.int64)  # faces around each vertex
    table[inc_v[order], np.arange(len(order)) - starts[inc_v[order]]] = inc_f[order]
    out = np.zeros((len(f), 3, 3))
    cos_c = np.cos(np.radians(crease_deg))
    for k in range(3):
        nb = table[fv[:, k]]  # (F, D) neighbour faces at corner k
        nbc = np.maximum(nb, 0)
        dots = np.einsum("fdj,fj->fd", fn[nbc], fn)
        corner = np.argmax(fv[nbc] == fv[:, k][:, None, None], axis=2)  # the vertex's corner in each neighbour
        w = np.where((nb >= 0) & (np.abs(dots) >= cos_c), wts[nbc, corner] * np.sign(dots), 0.0)
        out[:, k] = np.einsum("fd,fdj->fj", w, fn[nbc])
    norm = np.linalg.norm(out, axis=2, keepdims=True)
    return np.where(norm > 1e-300, out / np.maximum(norm, 1e-300), fn[:, None, :])


def _frame(normal, tangent):
    return brdfmodels.local_frame(normal, tangent)  # rows x, y, z


def _place(local_vertices, frame, center):
    return local_vertices @ frame + np.asarray(center, dtype=float)


def _plate(w, h):
    v = np.array([[-w / 2, -h / 2, 0], [w / 2, -h / 2, 0], [w / 2, h / 2, 0], [-w / 2, h / 2, 0]], float)
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def _disk(d, n=64):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = np.vstack([[0, 0, 0], np.stack([d / 2 * np.cos(a), d / 2 * np.sin(a), np.zeros(n)], 1)])
    f = np.stack([np.zeros(n, int), 1 + np.arange(n), 1 + (np.arange(n) + 1) % n], 1)
    return v, f


def _box(sx, sy, sz):
    v = np.array([[x, y, z] for z in (-sz / 2, sz / 2) for y in (-sy / 2, sy / 2) for x in (-sx / 2, sx / 2)], float)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    f = []
    for a, b, c, d in quads:
        f += [[a, b, c], [a, c, d]]
    return v, np.array(f)


def _sphere(d, n_lat=48, n_lon=96):
    r = d / 2
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([r * np.sin(tt) * np.cos(pp), r * np.sin(tt) * np.sin(pp), r * np.cos(tt)], -1).reshape(-1, 3)
    f = []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d_ = a + n_lon, b + n_lon
            if i > 0:
                f.append([a, c, b])
            if i < n_lat - 1:
                f.append([b, c, d_])
    return v, np.array(f)


def _cylinder(d, h, n=96):
    r = d / 2
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    bottom = np.hstack([ring, np.full((n, 1), -h / 2)])
    top = np.hstack([ring, np.full((n, 1), h / 2)])
    v = np.vstack([bottom, top, [[0, 0, -h / 2], [0, 0, h / 2]]])
    i = np.arange(n)
    j = (i + 1) % n
    side = np.vstack([np.stack([i, j, n + j], 1), np.stack([i, n + j, n + i], 1)])
    cap_b = np.stack([np.full(n, 2 * n), j, i], 1)
    cap_t = np.stack([np.full(n, 2 * n + 1), n + i, n + j], 1)
    return v, np.vstack([side, cap_b, cap_t])


def input_path(name, base_dir=None) -> Path:
    """A file a scene names: absolute as given, else relative to the scene's folder
    ``base_dir`` (when the scene came from a file)."""
    path = Path(name)
    return path if path.is_absolute() or base_dir is None else Path(base_dir) / path


def shape_mesh(spec, base_dir=None) -> Mesh:
    """Mesh of a target or occluder spec (world coordinates, float64)."""
    frame = _frame(spec.normal, spec.tangent)
    s = spec.size_m
    if spec.shape == "plate":
        v, f = _plate(*s)
        return Mesh(_place(v, frame, spec.center_m), f)
    if spec.shape == "disk":
        v, f = _disk(s[0])
        return Mesh(_place(v, frame, spec.center_m), f)
    if spec.shape == "box":
        v, f = _box(*s)
        return Mesh(_place(v, frame, spec.center_m), f)
    if spec.shape == "sphere":
        v, f = _sphere(s[0])
        return Mesh(_place(v, frame, spec.center_m), f, ("sphere", np.asarray(spec.center_m, float), s[0] / 2))
    if spec.shape == "cylinder":
        v, f = _cylinder(*s)
        return Mesh(_place(v, frame, spec.center_m), f, ("cylinder", np.asarray(spec.center_m, float), frame[2], s[0] / 2, s[1] / 2))
    return _mesh_file(spec, frame, base_dir)


MESH_TYPES = ("stl", "obj", "ply", "off")  # self-contained mesh formats a shape file may be


def _mesh_file(spec, frame, base_dir):
    import trimesh  # only for scenes with mesh files

    from brdfmodels.fileio import check_input_file, check_limit

    path = input_path(spec.file, base_dir)
    kind = path.suffix.lower().lstrip(".")
    if kind not in MESH_TYPES:
        raise ValueError(f"file={spec.file!r}: expected a mesh file of type {', '.join(MESH_TYPES)} (by its suffix); "
                         f"formats that refer to other files or URLs (glTF, ...) are refused")
    check_input_file(path, "mesh file")
    try:  # from an open file, with no resolver: the mesh is read alone (an OBJ's mtllib or textures are not followed)
        with open(path, "rb") as fh:
            m = trimesh.load(fh, file_type=kind, force="mesh", process=False)  # processing merged (and dropped) non-finite vertices
    except Exception as exc:  # trimesh raises many kinds; their text may quote the file, so only the kind is named
        raise ValueError(f"file={spec.file!r}: cannot read the mesh as {kind.upper()} ({type(exc).__name__}; "
                         f"a damaged file, or another format?)") from None
    if len(m.faces) == 0:
        raise ValueError(f"file={spec.file!r}: the mesh has no triangles")
    check_limit("MESH_TRIANGLES", len(m.faces), f"file={spec.file!r}: triangles")
    v = np.asarray(m.vertices, float) * spec.scale
    if not np.all(np.isfinite(v)) or np.abs(v).max() > 1e8:
        raise ValueError(f"file={spec.file!r}: vertices must be finite and within 1e8 m")
    return Mesh(_place(v, frame, spec.center_m), np.asarray(m.faces, int))


@dataclass
class Heightfield:
    """Regular grid of ground heights z(x, y) [m] with bilinear interpolation."""

    x0: float
    y0: float
    dx: float
    heights: np.ndarray  # (ny, nx)

    def height_at(self, x, y) -> np.ndarray:
        ny, nx = self.heights.shape
        fx = np.clip((np.asarray(x, float) - self.x0) / self.dx, 0, nx - 1 - 1e-9)
        fy = np.clip((np.asarray(y, float) - self.y0) / self.dx, 0, ny - 1 - 1e-9)
        i, j = fy.astype(np.intp), fx.astype(np.intp)  # fx, fy >= 0: truncation is the floor
        ty, tx = fy - i, fx - j
        h = self.heights.ravel()
        k = i * nx + j  # flat gathers (one index array per corner) are cheaper than 2-D ones
        below = h[k] + tx * (h[k + 1] - h[k])
        above = h[k + nx] + tx * (h[k + nx + 1] - h[k + nx])
        return below + ty * (above - below)

    def contains_xy(self, x, y) -> np.ndarray:
        ny, nx = self.heights.shape
        x, y = np.asarray(x, float), np.asarray(y, float)
        return (x >= self.x0) & (x <= self.x0 + (nx - 1) * self.dx) & (y >= self.y0) & (y <= self.y0 + (ny - 1) * self.dx)

    def mesh(self) -> Mesh:
        ny, nx = self.heights.shape
        xs = self.x0 + self.dx * np.arange(nx)
        ys = self.y0 + self.dx * np.arange(ny)
        xx, yy = np.meshgrid(xs, ys)
        v = np.stack([xx, yy, self.heights], -1).reshape(-1, 3)
        idx = np.arange(ny * nx).reshape(ny, nx)
        a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
        f = np.vstack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])  # upward-facing
        return Mesh(v, f)


def terrain_heightfield(spec, base_dir=None) -> Heightfield:
    """Heightfield of a terrain spec."""
    if spec.kind == "heightmap":
        from brdfmodels.fileio import check_input_file, check_limit

        path = input_path(spec.file, base_dir)
        check_input_file(path, "terrain.file")
        try:
            h = np.load(path, allow_pickle=False, mmap_mode="r")  # the header first: its size is checked before reading
        except (OSError, ValueError) as exc:  # NumPy's text may quote the header: only its kind is named
            raise ValueError(f"terrain.file={spec.file!r}: cannot read the heightmap ({type(exc).__name__}: not a .npy file of "
                             f"plain numbers?)") from None
        if not isinstance(h, np.ndarray):  # an .npz archive
            raise ValueError(f"terrain.file={spec.file!r}: expected a .npy file holding one 2-d array of heights, got an archive")
        check_limit("TERRAIN_NODES", int(h.size), f"terrain.file={spec.file!r}: nodes")
        try:
            h = np.array(h)
        except (OSError, ValueError) as exc:  # a header that promises more than the file holds
            raise ValueError(f"terrain.file={spec.file!r}: cannot read the heightmap ({type(exc).__name__}: the file holds "
                             f"less than its header promises?)") from None
        if h.dtype.kind not in "iuf" or h.ndim != 2 or min(h.shape) < 2 or not np.all(np.isfinite(h)) or np.abs(h).max() > 1e5:
            raise ValueError(f"terrain.file={spec.file!r}: expected a 2-d array of finite heights [m], got shape {h.shape}")
        return Heightfield(spec.origin_m[0], spec.origin_m[1], spec.spacing_m, np.asarray(h, float))
    from brdfmodels.fileio import check_limit

    cx, cy, cz = spec.center_m
    n = int(math.ceil(spec.extent_m / spec.resolution_m))
    check_limit("TERRAIN_NODES", (2 * n + 1) ** 2, "terrain: nodes ((2 extent_m / resolution_m + 1)^2)")
    xs = cx + spec.resolution_m * np.arange(-n, n + 1)
    ys = cy + spec.resolution_m * np.arange(-n, n + 1)
    xx, yy = np.meshgrid(xs, ys)
    if spec.kind == "flat":
        h = np.full(xx.shape, cz)
    else:
        sign = 1.0 if spec.kind == "hill" else -1.0
        h = cz + sign * spec.height_m * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * spec.radius_m**2))
    return Heightfield(xs[0], ys[0], spec.resolution_m, h)


def _bearing_vectors(az, el) -> np.ndarray:
    """Unit vectors (N, 3) of compass bearings az (clockwise from +y) and elevations [rad]."""
    az, el = np.broadcast_arrays(np.asarray(az, float), np.asarray(el, float))
    return np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1).reshape(-1, 3)


def _angle(u, v) -> np.ndarray:
    """Angle [rad] between unit vectors (rows), accurate near 0 and pi."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("...i,...i->...", u, v))


def angle_to_sector_rad(u, sector) -> np.ndarray:
    """Angle [rad] on the sphere from unit directions u (N, 3) to the nearest direction of
    ``sector`` (bearings [A0, A1] clockwise from +y, elevations [E0, E1], [deg]); 0
    inside. Exact: the least angle to its edges, the two meridian arcs (the foot of u on
    each arc's great circle, or the arc's ends) and the two circles of elevation (at u's
    bearing when it lies in [A0, A1], else at their ends, the arcs' ends)."""
    u = np.asarray(u, float).reshape(-1, 3)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    az = np.arctan2(u[:, 0], u[:, 1])
    el = np.arctan2(u[:, 2], np.hypot(u[:, 0], u[:, 1]))
    e0, e1 = (math.radians(x) for x in sector.elevation_deg)
    a0, a1 = (math.radians(x) for x in sector.azimuth_deg)
    full = a1 - a0 >= 2 * np.pi
    in_az = np.ones(len(u), bool) if full else (az - a0) % (2 * np.pi) <= (a1 - a0) + 1e-15
    inside = in_az & (el >= e0) & (el <= e1)
    best = np.full(len(u), np.inf)
    for e in (e0, e1):  # circles of elevation: along u's meridian when u's bearing is in the sector
        best = np.where(in_az, np.minimum(best, np.abs(el - e)), best)
    if not full:
        for a in (a0, a1):  # meridian arcs: the foot of u on the great circle, clamped; and the ends
            h = np.array([math.sin(a), math.cos(a), 0.0])
            foot = np.clip(np.arctan2(u[:, 2], u @ h), e0, e1)
            for e in (foot, e0, e1):
                best = np.minimum(best, _angle(u, _bearing_vectors(a, e)))
    return np.where(inside, 0.0, best)


def widened_azimuths_rad(sector, buffer_rad, elevation_rad) -> tuple[np.ndarray, np.ndarray]:
    """Per elevation el [rad]: the bearings [lo, hi] [rad] of the directions at el within
    the angle ``buffer_rad`` = b of ``sector`` on the sphere (hi - lo >= 2 pi: the whole
    circle; hi < lo: none). Beyond each meridian arc (bearing A, elevations [E0, E1]) the
    row reaches A + delta (the angle to the sector grows with delta along a row), delta
    the largest of
      - the band: sin(delta) = sin(b) / cos(el), where its foot on the arc's great circle,
        atan2(sin el, cos el cos delta), lies in [E0, E1] (near the pole also for rows
        below E0);
      - the caps about the corners (A, E): cos(delta) = (cos b - sin el sin E) / (cos el cos E)
        (the whole circle where that is <= -1, as near the pole);
    and rows with el in [E0 - b, E1 + b] hold [A0, A1] (the circles of elevation). The
    widest row of a cap is at el = asin(sin E / cos b), where sin(delta) = sin b / cos E:
    widening the bearings by b, as a flat map would, is short by about b (1 / cos E - 1)."""
    el = np.clip(np.asarray(elevation_rad, float), -np.pi / 2, np.pi / 2)
    e0, e1 = (math.radians(x) for x in sector.elevation_deg)
    a0, a1 = (math.radians(x) for x in sector.azimuth_deg)
    b = float(buffer_rad)
    in_band = (el >= e0 - b - 1e-15) & (el <= e1 + b + 1e-15)
    ext = np.where(in_band, 0.0, -np.inf)
    cos_el = np.maximum(np.cos(el), 1e-300)
    ratio = math.sin(b) / cos_el
    d_band = np.arcsin(np.minimum(ratio, 1.0))
    foot = np.arctan2(np.sin(el), cos_el * np.cos(d_band))
    band = in_band & (ratio <= 1.0) & (foot >= e0) & (foot <= e1)  # the foot, not the row, on the arc
    ext = np.where(band, np.maximum(ext, d_band), ext)
    for e in (e0, e1):
        c = (math.cos(b) - np.sin(el) * math.sin(e)) / np.maximum(cos_el * math.cos(e), 1e-300)
        ext = np.where(c <= 1.0, np.maximum(ext, np.arccos(np.clip(c, -1.0, 1.0))), ext)
    whole = (ext >= np.pi) | (np.isfinite(ext) & (a1 - a0 + 2 * ext >= 2 * np.pi))
    lo, hi = a0 - ext, a1 + ext
    return np.where(whole, a0, lo), np.where(whole, a0 + 2 * np.pi, hi)


def directions_in_sector(directions, sector, buffer_rad=0.0, tolerance_deg=0.0) -> np.ndarray:
    """Per direction (N, 3): whether it points within ``sector`` (compass bearings
    clockwise from +y and elevations, [deg]) widened by ``buffer_rad`` (and
    ``tolerance_deg``, for rounding): within that angle of it on the sphere
    (:func:`angle_to_sector_rad`)."""
    return angle_to_sector_rad(directions, sector) <= buffer_rad + math.radians(tolerance_deg)


def direction_in_sector(direction, sector, buffer_rad=0.0) -> bool:
    """Whether ``direction`` (3,) points within ``sector`` widened by ``buffer_rad``
    (:func:`directions_in_sector` of one direction)."""
    return bool(directions_in_sector(direction, sector, buffer_rad)[0])


def observer_points(spec) -> np.ndarray:
    """Observer positions (N, 3) [m] of one observer group (before eye-height placement)."""
    if spec.layout == "points":
        return np.asarray(spec.points_m, float).reshape(-1, 3)
    if spec.layout == "line":
        t = np.linspace(0.0, 1.0, spec.count) if spec.count > 1 else np.zeros(1)
        a, b = np.asarray(spec.start_m, float), np.asarray(spec.end_m, float)
        return a + t[:, None] * (b - a)
    if spec.layout == "grid":
        nu, nv = spec.counts
        o, u, v = (np.asarray(x, float) for x in (spec.origin_m, spec.u_m, spec.v_m))
        iu = np.arange(nu) / max(nu - 1, 1)
        iv = np.arange(nv) / max(nv - 1, 1)
        return (o + iv[:, None, None] * v + iu[None, :, None] * u).reshape(-1, 3)  # row-major, tile order
    # shell: Fibonacci points on the upper hemisphere
    k = np.arange(spec.count) + 0.5
    z = 1.0 - k / spec.count
    phi = np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z * z)
    return np.asarray(spec.center_m, float) + spec.radius_m * np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
