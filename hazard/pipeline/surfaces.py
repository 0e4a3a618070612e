"""The surfaces observer groups sample, for the ``crossings`` stage.

A line of observers samples a polyline; a grid samples a parallelogram (flat, or draped
over the terrain at eye height); a shell samples an upper hemisphere. An eye may stand
anywhere on that surface, so a beam that passes between the points must still be found
(issue 13 item 7). Each surface here maps any point to a point of the surface
(:meth:`project`) such that a point already on the surface maps to itself: the curve
``project(o + t d)`` along a beam's axis then passes through every point where the axis
meets the surface, and its other points are the surface points nearest the axis (the
eye's point below an axis above a draped grid). Searching a beam's irradiance along that
curve finds the crossing without searching the surface in two dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Polyline", "Plane", "Draped", "Hemisphere", "observer_surfaces"]


@dataclass(frozen=True)
class Polyline:
    """A line of observers: its points in order (n, 3) [m], searched along the line itself."""

    points_m: np.ndarray

    def at(self, t) -> np.ndarray:
        """Points at polyline parameters t in [0, n - 1] (segment index + fraction)."""
        seg = self.points_m[1:] - self.points_m[:-1]
        t = np.clip(np.asarray(t, float), 0.0, len(seg))
        i = np.minimum(t.astype(int), len(seg) - 1)
        return self.points_m[i] + (t - i)[:, None] * seg[i]


@dataclass(frozen=True)
class Plane:
    """A flat grid: the parallelogram ``origin + a u + b v``, a, b in [0, 1] (local m)."""

    origin_m: np.ndarray
    u_m: np.ndarray
    v_m: np.ndarray

    def _ab(self, p):
        g = np.array([[self.u_m @ self.u_m, self.u_m @ self.v_m], [self.u_m @ self.v_m, self.v_m @ self.v_m]])
        rel = p - self.origin_m
        ab = np.linalg.solve(g, np.stack([rel @ self.u_m, rel @ self.v_m]))
        return np.clip(ab, 0.0, 1.0)

    def project(self, p) -> np.ndarray:
        """The foot of the perpendicular from p (N, 3) on the plane, clamped to the
        parallelogram (in its a, b coordinates)."""
        a, b = self._ab(np.asarray(p, float))
        return self.origin_m + a[:, None] * self.u_m + b[:, None] * self.v_m

    def corners(self) -> np.ndarray:
        o, u, v = self.origin_m, self.u_m, self.v_m
        return np.array([o, o + u, o + v, o + u + v])


@dataclass(frozen=True)
class Draped:
    """A grid at ``eye_height_m`` above the terrain: its horizontal parallelogram (the
    grid's u, v in x, y) and heights ``terrain(x, y) + eye_height_m``."""

    plane: Plane  # z components ignored
    terrain: object
    eye_height_m: float

    def project(self, p) -> np.ndarray:
        """The eye point vertically below (or above) p, clamped to the grid's extent."""
        flat = Plane(self.plane.origin_m * [1, 1, 0], self.plane.u_m * [1, 1, 0], self.plane.v_m * [1, 1, 0])
        q = flat.project(np.asarray(p, float) * [1, 1, 0])
        q[:, 2] = self.terrain.height_at(q[:, 0], q[:, 1]) + self.eye_height_m
        return q

    def corners(self) -> np.ndarray:
        c = self.plane.corners()
        h = self.terrain.heights
        lo, hi = float(h.min()) + self.eye_height_m, float(h.max()) + self.eye_height_m
        return np.vstack([c * [1, 1, 0] + [0, 0, lo], c * [1, 1, 0] + [0, 0, hi]])


@dataclass(frozen=True)
class Hemisphere:
    """A shell: the upper hemisphere of radius ``radius_m`` about ``center_m`` (local)."""

    center_m: np.ndarray
    radius_m: float

    def project(self, p) -> np.ndarray:
        """The radial projection of p on the sphere; below the equator, onto the equator."""
        rel = np.asarray(p, float) - self.center_m
        rel[:, 2] = np.maximum(rel[:, 2], 0.0)
        n = np.linalg.norm(rel, axis=1)
        flat = n <= 1e-12 * self.radius_m
        rel[flat] = [0.0, 0.0, 1.0]
        n[flat] = 1.0
        return self.center_m + rel * (self.radius_m / n)[:, None]

    def corners(self) -> np.ndarray:
        r = self.radius_m
        return self.center_m + np.array([[-r, -r, 0.0], [r, r, r]])


def _grid_surface(spec, offset_m, terrain, points_fn):
    """A grid's surface, or its points (``points_fn()``) as a polyline when it is one row
    or column (or its u and v are parallel)."""
    nu, nv = spec.counts
    o, u, v = (np.asarray(x, float) for x in (spec.origin_m, spec.u_m, spec.v_m))
    plane = Plane(o - offset_m, u, v)
    uv = (u[:2], v[:2]) if spec.eye_height_m is not None else (u, v)
    area = np.linalg.norm(np.cross(uv[0], uv[1])) if spec.eye_height_m is None else abs(uv[0][0] * uv[1][1] - uv[0][1] * uv[1][0])
    if nu == 1 or nv == 1 or area <= 1e-12 * np.dot(uv[0], uv[0]) ** 0.5 * np.dot(uv[1], uv[1]) ** 0.5:
        return Polyline(points_fn())
    if spec.eye_height_m is not None:
        return Draped(plane, terrain, float(spec.eye_height_m))
    return plane


def observer_surfaces(scene):
    """(group index, group name, surface) of every observer group that samples a line or
    a surface with at least two points; and the names of the groups left out with why."""
    obs, out, left = scene.observers, [], []
    for g, spec in enumerate(scene.spec.observers):
        rows = obs.group_rows(g)
        if spec.layout == "points" or len(rows) < 2:
            continue
        if spec.layout == "line":
            out.append((g, spec.name, Polyline(obs.take(rows))))
        elif spec.layout == "grid":
            out.append((g, spec.name, _grid_surface(spec, scene.offset_m, scene.terrain, lambda rows=rows: obs.take(rows))))
        elif spec.eye_height_m is None:
            out.append((g, spec.name, Hemisphere(np.asarray(spec.center_m, float) - scene.offset_m, float(spec.radius_m))))
        else:
            left.append(f"{spec.name} (a shell draped over the terrain is not searched between its points)")
    return out, left
