"""Ray queries on the scene's triangles: Embree (embreex raw API) or trimesh's numpy engine.

Facts this module is built on (spec `engineering-notes.md`, checked against embreex's
source): Embree takes float32 only, so callers pass local coordinates near the origin
(scenes re-centre them); finite segments exist only in the raw API (``dists`` is tfar in
units of |dir|, and is overwritten in place, so a fresh array is passed every call);
tnear is fixed at 0, so rays leaving a surface start a small distance off it; the query
releases the GIL, so two threads over chunks nearly double throughput; the scene is
built once and reused.

Both backends share one interface and are tested against each other.

Building the Embree scene of a large terrain takes seconds (1e6 triangles: 1.2-1.5 s on
the 2-core development machine), and a study's scenarios usually share the geometry:
:func:`cached_ray_scene` returns a scene from a small per-process LRU cache keyed by the
content of the meshes (``RAY_CACHE_ENTRIES`` scenes, at most ``RAY_CACHE_MAX_BYTES`` in
all; a larger scene is built and not kept).
"""

from __future__ import annotations

import copy
import hashlib
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from brdfmodels.parallel import default_threads

__all__ = ["RayScene", "Hits", "BACKENDS", "cached_ray_scene", "ray_cache_info", "clear_ray_cache", "CONVEX_SHAPES", "own_object"]

BACKENDS = ("embree", "numpy")
_CHUNK = 65536
RAY_CACHE_ENTRIES = 4  # scenes kept by cached_ray_scene (least recently used dropped first)
RAY_CACHE_MAX_BYTES = 1 << 30  # memory the cached scenes may hold in all [bytes]; larger scenes are not kept
ENGINE_BYTES_PER_TRIANGLE = 64  # the ray engine's copy and BVH [bytes per triangle] (Embree measured: ~50)
# target shapes whose own surface never shadows their reflection: a point of a convex
# surface sees an observer exactly when the observer is above its tangent plane, which
# the BRDF (zero below the horizon) and the mirror law already say
CONVEX_SHAPES = ("plate", "disk", "box", "sphere", "cylinder")


def own_object(target) -> int | None:
    """The ray-scene object id of ``target`` (its index: targets come first) when it is
    convex (:data:`CONVEX_SHAPES`): lines of sight leaving it pass through its own
    triangles (``RayScene.occluded(..., transparent=)``); None for meshes and the
    terrain, whose own relief can shadow their reflection."""
    return target.index if getattr(target.spec, "shape", None) in CONVEX_SHAPES else None


def _unit_normals(v) -> np.ndarray:
    """Unit normals of triangles ``v`` (N, 3 vertices, 3)."""
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@dataclass
class Hits:
    """First hits of N rays: ``hit`` mask, distance ``t`` [m], ``face`` and ``obj`` index
    (-1 where nothing was hit) and the hit ``point`` (N, 3) in float64."""

    hit: np.ndarray
    t: np.ndarray
    face: np.ndarray
    obj: np.ndarray
    point: np.ndarray


class RayScene:
    """Triangles of several objects, queried for first hits and segment occlusion.

    Parameters
    ----------
    meshes : sequence of (vertices (V, 3), faces (F, 3), object_id)
        Local coordinates [m]; ``object_id`` labels which object each triangle belongs to.
    backend : {"embree", "numpy"}
    threads : int, optional
        Worker threads for large Embree batches (default, and cap: the
        :func:`brdfmodels.parallel.default_threads` of the calling thread).
    """

    def __init__(self, meshes, backend="embree", threads=None):
        if backend not in BACKENDS:
            raise ValueError(f"backend={backend!r}: expected one of {list(BACKENDS)}")
        verts, faces, objs = [], [], []
        base = 0
        for v, f, oid in meshes:
            v = np.asarray(v, float)
            f = np.asarray(f, np.int64)
            verts.append(v)
            faces.append(f + base)
            objs.append(np.full(len(f), oid))
            base += len(v)
        self.vertices = np.vstack(verts) if verts else np.empty((0, 3))
        self.faces = np.vstack(faces) if faces else np.empty((0, 3), np.int64)
        self.face_object = np.concatenate(objs) if objs else np.empty(0, int)
        self.backend = backend
        self.threads = None if threads is None else max(1, int(threads))
        self.scale_m = float(np.ptp(self.vertices, axis=0).max()) if len(self.vertices) else 1.0
        pad = 1e-3 * self.scale_m + 1e-9  # far beyond float32's rounding of a start near the box
        self._box = (self.vertices.min(axis=0) - pad, self.vertices.max(axis=0) + pad) if len(self.vertices) else None
        self._kept = {}  # arrays made on first use, shared with the views (with_threads)
        self._impl = None
        if len(self.faces):
            self._impl = _EmbreeImpl(self.vertices, self.faces) if backend == "embree" else _NumpyImpl(self.vertices, self.faces)

    @property
    def n_triangles(self) -> int:
        return int(len(self.faces))

    @property
    def nbytes(self) -> int:
        """Memory held by the scene [bytes]: its arrays plus ``ENGINE_BYTES_PER_TRIANGLE``
        per triangle for the ray engine (an estimate: the engine's memory is not exposed)."""
        arrays = self.vertices.nbytes + self.faces.nbytes + self.face_object.nbytes
        arrays += sum(a.nbytes for a in self._kept.values() if isinstance(a, np.ndarray))  # made on first use
        return int(arrays + ENGINE_BYTES_PER_TRIANGLE * self.n_triangles)

    def with_threads(self, threads):
        """This scene with another thread cap: itself if the cap is the same, else a
        shallow copy sharing the built engine (queries from several threads are safe)."""
        threads = None if threads is None else max(1, int(threads))
        if threads == self.threads:
            return self
        view = copy.copy(self)
        view.threads = threads
        return view

    def face_normals(self, faces) -> np.ndarray:
        """Unit normals (N, 3) of triangles ``faces`` (``(v1 - v0) x (v2 - v0)``, normalised)."""
        return self._face_arrays(faces)[0]

    def _face_arrays(self, faces):
        """Unit normals and first vertices of triangles ``faces``. Once a quarter of the
        triangles' worth has been asked for (over all calls), every triangle's are made
        and kept for the scene and its views (row by row the same numbers)."""
        kept = self._kept
        if "normals" not in kept:
            kept["asked"] = kept.get("asked", 0) + len(faces)  # the views share the count (a race only delays it)
            if 4 * kept["asked"] < self.n_triangles:
                return _unit_normals(self.vertices[self.faces[faces]]), self.vertices[self.faces[faces, 0]]
            kept["first_vertex"] = self.vertices[self.faces[:, 0]]
            kept["normals"] = _unit_normals(self.vertices[self.faces])
        return kept["normals"][faces], kept["first_vertex"][faces]

    def first_hit(self, origins, directions) -> Hits:
        """Nearest hit along each ray (directions need not be unit length; ``t`` is in m)."""
        o = np.asarray(origins, float)
        d = np.asarray(directions, float)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        n = len(o)
        if self._impl is None or n == 0:
            return Hits(np.zeros(n, bool), np.full(n, np.inf), np.full(n, -1), np.full(n, -1), np.full((n, 3), np.nan))
        face, t, obj = self._first(o, d)
        hit = face >= 0
        point = np.where(hit[:, None], o + d * np.where(hit, t, 0.0)[:, None], np.nan)
        return Hits(hit, t, face, obj, point)

    def _ahead(self, o, d) -> tuple[np.ndarray, np.ndarray]:
        """Where each ray (unit ``d``) may start with nothing skipped, and how far [m] ahead
        of ``o`` that is: just before the box of every triangle (padded by 1e-3 of the
        scene's size); ``o`` itself (0) for a start inside it or a ray that misses it. Embree rounds a start and direction
        to float32: from a laser 186 m away that is ~1e-5 m across the beam at the target
        (its ulp, and the direction's 6e-8 over the range), so rays passing that close
        outside a cylinder's cap seen edge-on were hits (0.017 W of a 546 W spot more than
        the exact surface's, beyond the stated bound); started at the box, the error is
        the box's own float32 rounding."""
        lo, hi = self._box
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = (lo - o) / d, (hi - o) / d
            enter = np.nanmax(np.minimum(a, b), axis=1)
            leave = np.nanmin(np.maximum(a, b), axis=1)
        t0 = np.where((enter > 0) & (enter <= leave) & np.isfinite(enter), enter, 0.0)
        return o + t0[:, None] * d, t0

    def _first(self, o, d):
        """Face (-1: none), distance [m] (inf: none) and object (-1: none) of the nearest
        hit along unit directions ``d`` from ``o``, ``t`` refined in float64 against the
        hit triangle's plane (Embree works in float32; each ray starts at the box of the
        triangles, :meth:`_ahead`)."""
        start, t0 = self._ahead(o, d)
        face, t = self._map(lambda a, b: self._impl.first(start[a:b], d[a:b]), len(o), 2)
        t = t + t0
        hit = face >= 0
        ref = np.flatnonzero(hit)
        if len(ref):
            t_ref, good = self._plane_t(o, d, face, ref)
            t_ref[~good] = t[ref[~good]]
            t = t.copy()
            t[ref] = t_ref
        return face, np.where(hit, t, np.inf), np.where(hit, self.face_object[np.maximum(face, 0)], -1)

    def _plane_t(self, o, d, face, ref):
        """Distance [m] in float64 from ``o`` along ``d`` to the plane of each hit
        triangle (rows ``ref``), and where it is defined (the ray not parallel to it)."""
        nrm, v0 = self._face_arrays(face[ref])
        den = np.einsum("ij,ij->i", d[ref], nrm)
        good = np.abs(den) > 1e-12
        t_ref = np.empty(len(ref))
        t_ref[good] = np.einsum("ij,ij->i", v0[good] - o[ref][good], nrm[good]) / den[good]
        return t_ref, good

    def _first_other(self, o, d, own):
        """As :meth:`_first`, for a caller that discards the hits of object ``own``: only
        the faces are asked of the engine, and ``t`` is made on the other objects' hits
        (inf on ``own``'s; Embree's own ``t`` asked again only where a ray is parallel to
        its triangle's plane; each ray starts at the box of the triangles, :meth:`_ahead`)."""
        start, t0 = self._ahead(o, d)
        (face,) = self._map(lambda a, b: (self._impl.first_face(start[a:b], d[a:b]),), len(o), 1)
        hit = face >= 0
        obj = np.where(hit, self.face_object[np.maximum(face, 0)], -1)
        ref = np.flatnonzero(hit & (obj != own))
        t = np.full(len(o), np.inf)
        if len(ref):
            t_ref, good = self._plane_t(o, d, face, ref)
            if not good.all():
                bad = ref[~good]
                t_ref[~good] = self._impl.first(start[bad], d[bad])[1] + t0[bad]
            t[ref] = t_ref
        return face, t, obj

    def behind_plane(self, obj: int, point_m, normal) -> bool:
        """True when every triangle of object ``obj`` lies behind the plane through
        ``point_m`` with unit ``normal``, by more than the engine's float32 rounding of
        the points (a relative 2**-23 of the largest coordinate, four times over) and
        of its own test (the same of the distances): then no segment from ``point_m`` to
        a point in front of that plane crosses them (it lies in front of the plane)."""
        key = ("object_vertices", int(obj))
        v = self._kept.get(key)
        if v is None:
            v = self.vertices[np.unique(self.faces[self.face_object == obj])]
            self._kept[key] = v  # the views share it (a race only makes it twice)
        if not len(v):
            return True
        p = np.asarray(point_m, float)
        rel = v - p
        eps = float(np.finfo(np.float32).eps)
        tol = 4.0 * eps * max(float(np.abs(v).max()), float(np.abs(p).max())) + 8.0 * eps * float(np.abs(rel).max())
        return float(np.max(rel @ np.asarray(normal, float))) < -tol

    def off_surface(self, point_m, normal) -> np.ndarray:
        """A segment start just off a surface (tnear is 0, so a ray leaving a surface
        must not begin on it): ``point + normal * 1e-6 * max(scene size, 1 m)``."""
        return np.asarray(point_m, float) + np.asarray(normal, float) * 1e-6 * max(self.scale_m, 1.0)

    def occluded(self, starts, ends, *, end_clearance_m=None, transparent=None) -> np.ndarray:
        """True where the open segment start -> end crosses a triangle.

        ``end_clearance_m`` shortens each segment at its end (observers standing on a
        surface must not be blocked by it); the default is 1e-6 of the scene size.
        Callers start segments a little off the surface they leave (tnear is 0).
        ``transparent``: an object id whose triangles do not block (the convex object the
        segments leave: its own shadowing is its BRDF's business, and a start inside its
        tessellation, e.g. a curved spot's centroid, must not block every observer);
        an occluded segment is then traced back from its end, and only a first hit on
        another object, within the segment, blocks it.
        """
        s = np.asarray(starts, float)
        e = np.asarray(ends, float)
        n = len(s)
        if self._impl is None or n == 0:
            return np.zeros(n, bool)
        clear = 1e-6 * self.scale_m if end_clearance_m is None else float(end_clearance_m)
        vec = e - s
        length = np.linalg.norm(vec, axis=1)
        frac = np.clip(1.0 - clear / np.maximum(length, 1e-300), 0.0, 1.0)
        (occ,) = self._map(lambda a, b: (self._impl.occluded(s[a:b], vec[a:b], frac[a:b]),), n, 1)
        if transparent is not None and occ.any():
            idx = np.flatnonzero(occ)
            occ[idx] = self._blocked_from_end(s[idx], e[idx], length[idx], clear, transparent)
        return occ

    def _blocked_from_end(self, s, e, length, clear, own) -> np.ndarray:
        """Segments s -> e blocked by an object other than ``own``: the first hit seen from
        the end (moved ``clear`` towards the start) lies within the segment and is not
        ``own``. With ``own`` convex and the start on or inside it, whatever lies between
        ``own`` and the end is seen from the end before ``own``."""
        back = (s - e) / np.maximum(length, 1e-300)[:, None]
        start = e + back * np.minimum(clear, 0.5 * length)[:, None]
        # only whether a hit of another object lies within the segment: Embree's t is
        # refined on those hits only, and no hit points are made
        face, t, obj = self._first_other(start, back / np.linalg.norm(back, axis=1, keepdims=True), own)
        return (face >= 0) & (t < length - clear) & (obj != own)

    def _map(self, fn, n, n_out):
        threads = default_threads() if self.threads is None else min(self.threads, default_threads())  # 1 inside a block
        if self.backend != "embree" or threads == 1 or n <= 2 * _CHUNK:
            return fn(0, n)
        bounds = [(a, min(a + _CHUNK, n)) for a in range(0, n, _CHUNK)]
        with ThreadPoolExecutor(threads) as pool:
            parts = list(pool.map(lambda ab: fn(*ab), bounds))
        return tuple(np.concatenate([p[i] for p in parts]) for i in range(n_out))


_CACHE: OrderedDict = OrderedDict()  # key -> RayScene, least recently used first
_CACHE_LOCK = threading.Lock()  # guards _CACHE, _BUILDING and _STATS
_BUILDING: dict = {}  # key -> lock held while that scene is built (one build per key at a time)
_STATS = {"hits": 0, "misses": 0}


def _mesh_key(meshes, backend) -> tuple:
    """Content key of a ray scene: SHA-256 of every mesh's vertices (float64), faces
    (int64), their shapes and object id, in order, and the backend."""
    h = hashlib.sha256()
    for v, f, oid in meshes:
        v = np.ascontiguousarray(v, float)
        f = np.ascontiguousarray(f, np.int64)
        h.update(np.array([*v.shape, *f.shape], np.int64).tobytes())
        h.update(repr(np.asarray(oid).item()).encode())
        h.update(v.reshape(-1).view(np.uint8))
        h.update(f.reshape(-1).view(np.uint8))
    return backend, h.hexdigest()


def _cache_put(key, scene) -> None:
    """Keep ``scene`` unless it alone exceeds the budget; drop the least recently used
    scenes beyond ``RAY_CACHE_ENTRIES`` or ``RAY_CACHE_MAX_BYTES`` (caller holds the lock)."""
    if scene.nbytes > RAY_CACHE_MAX_BYTES or RAY_CACHE_ENTRIES < 1:
        return
    _CACHE[key] = scene
    while len(_CACHE) > RAY_CACHE_ENTRIES or sum(s.nbytes for s in _CACHE.values()) > RAY_CACHE_MAX_BYTES:
        _CACHE.popitem(last=False)


def _cache_get(key):
    """The cached scene of ``key`` (marked most recently used) or None (caller holds the lock)."""
    scene = _CACHE.get(key)
    if scene is not None:
        _CACHE.move_to_end(key)
        _STATS["hits"] += 1
    return scene


def cached_ray_scene(meshes, backend="embree", threads=None) -> RayScene:
    """A :class:`RayScene` of ``meshes`` from the per-process cache, built on a miss.

    Parameters
    ----------
    meshes : sequence of (vertices (V, 3), faces (F, 3), object_id)
        As for :class:`RayScene`: local coordinates [m].
    backend : {"embree", "numpy"}
    threads : int, optional
        Thread cap of the returned scene (as for :class:`RayScene`).

    Returns
    -------
    RayScene
        The cached scene for the same content and backend: the same object for the same
        thread cap, a view sharing its engine for another (:meth:`RayScene.with_threads`).

    Notes
    -----
    The key is a SHA-256 of every mesh's vertices, faces, shapes and object id, in
    order, and the backend, so any edit gives a new scene. The cache keeps
    ``RAY_CACHE_ENTRIES`` scenes and ``RAY_CACHE_MAX_BYTES`` (:attr:`RayScene.nbytes`)
    at most, per process (each worker of a study has its own); a scene above the byte
    budget is built and not kept. It is thread-safe: concurrent callers with the same
    meshes wait for one build instead of building side by side. A cached scene's arrays
    are read-only (it is shared between analyses).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {list(BACKENDS)}")
    meshes = list(meshes)
    key = _mesh_key(meshes, backend)
    with _CACHE_LOCK:
        scene = _cache_get(key)
        building = _BUILDING.setdefault(key, threading.Lock()) if scene is None else None
    if scene is None:
        try:
            with building:
                scene = _build_once(key, meshes, backend, threads)
        finally:
            with _CACHE_LOCK:
                if _BUILDING.get(key) is building:
                    del _BUILDING[key]
    return scene.with_threads(threads)


def _build_once(key, meshes, backend, threads) -> RayScene:
    """Build and cache the scene of ``key`` unless a caller that held the build lock
    before has just cached it (the caller holds the key's build lock)."""
    with _CACHE_LOCK:
        scene = _cache_get(key)
    if scene is not None:
        return scene
    scene = RayScene(meshes, backend=backend, threads=threads)
    for a in (scene.vertices, scene.faces, scene.face_object):
        a.flags.writeable = False  # shared between analyses
    with _CACHE_LOCK:
        _STATS["misses"] += 1
        _cache_put(key, scene)
    return scene


def ray_cache_info() -> dict:
    """The cache's state: ``entries``, ``nbytes`` [bytes], ``hits`` and ``misses`` so far,
    and its bounds ``max_entries`` and ``max_bytes`` [bytes]."""
    with _CACHE_LOCK:
        return {"entries": len(_CACHE), "nbytes": int(sum(s.nbytes for s in _CACHE.values())), **_STATS,
                "max_entries": RAY_CACHE_ENTRIES, "max_bytes": RAY_CACHE_MAX_BYTES}


def clear_ray_cache() -> None:
    """Drop every cached scene and reset the hit and miss counts."""
    with _CACHE_LOCK:
        _CACHE.clear()
        _STATS.update(hits=0, misses=0)


class _EmbreeImpl:
    def __init__(self, vertices, faces):
        from embreex import mesh_construction, rtcore_scene

        self.scene = rtcore_scene.EmbreeScene()
        self.mesh = mesh_construction.TriangleMesh(self.scene, vertices.astype(np.float32), faces.astype(np.int32))

    def first(self, o, d):
        out = self.scene.run(o.astype(np.float32), d.astype(np.float32), output=True)
        face = out["primID"].astype(np.int64)
        return face, out["tfar"].astype(float)

    def first_face(self, o, d):
        return self.scene.run(o.astype(np.float32), d.astype(np.float32), query="INTERSECT").astype(np.int64)

    def occluded(self, s, vec, frac):
        # dists is tfar in units of |dir|; a fresh float32 array each call (Embree writes it)
        res = self.scene.run(s.astype(np.float32), vec.astype(np.float32), dists=frac.astype(np.float32), query="OCCLUDED")
        return res == 0


class _NumpyImpl:
    def __init__(self, vertices, faces):
        import importlib.util

        import trimesh

        if importlib.util.find_spec("rtree") is None:  # trimesh's ray_triangle needs it
            raise ValueError("--backend numpy needs the rtree package: pip install 'laser-hazard[numpy-backend]' "
                             "(or use the default embree backend)")

        self.mesh = trimesh.Trimesh(vertices, faces, process=False)
        self.engine = trimesh.ray.ray_triangle.RayMeshIntersector(self.mesh)

    def first(self, o, d):
        tri, ray, loc = self.engine.intersects_id(o, d, multiple_hits=True, return_locations=True)
        n = len(o)
        face = np.full(n, -1, np.int64)
        t = np.full(n, np.inf)
        if len(tri):
            dist = np.einsum("ij,ij->i", loc - o[ray], d[ray])
            ok = dist > 0
            order = np.lexsort((dist[ok], ray[ok]))
            r, f, dd = ray[ok][order], tri[ok][order], dist[ok][order]
            if not len(r):  # every hit behind its ray's origin
                return face, t
            first = np.r_[True, r[1:] != r[:-1]]
            face[r[first]] = f[first]
            t[r[first]] = dd[first]
        return face, t

    def first_face(self, o, d):
        return self.first(o, d)[0]

    def occluded(self, s, vec, frac):
        length = np.linalg.norm(vec, axis=1)
        d = vec / np.maximum(length, 1e-300)[:, None]
        tri, ray, loc = self.engine.intersects_id(s, d, multiple_hits=True, return_locations=True)
        occ = np.zeros(len(s), bool)
        if len(tri):
            dist = np.einsum("ij,ij->i", loc - s[ray], d[ray])
            block = (dist > 0) & (dist < length[ray] * frac[ray])
            occ[ray[block]] = True
        return occ
