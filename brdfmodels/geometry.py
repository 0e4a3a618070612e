"""Direction geometry in the surface frame.

Conventions (spec `dynamic-sh-brdf.md` section 1): z is the outward surface normal, x a
tangent fixed to the material (for machined metals, along the grooves), y = z cross x.
``wi`` points from the surface towards the source, ``wo`` from the surface towards the
observer; both are (..., 3) arrays and broadcast against each other.

Halfway/difference coordinates follow Rusinkiewicz, "A New Change of Variables for
Efficient BRDF Representation", Eurographics Rendering Workshop 1998 (spec section 2):
``h = normalize(wi + wo)``; ``d`` is ``wi`` rotated by ``-phi_h`` about z and then by
``-theta_h`` about y.

Singular points are given fixed, documented values so every output is finite and
deterministic:

* ``theta_h = 0`` (mirror direction): ``phi_h`` is undefined; it is set to 0, so ``d`` is
  ``wi`` itself. Basis terms that depend on ``phi_h`` carry ``sin(theta_h)**m`` and vanish
  there, so the BRDF is continuous whatever azimuth is chosen.
* ``theta_d = 0`` (retro-reflection): ``phi_d`` is set to 0 for the same reason.
* ``wi = -wo`` (both on the horizon, opposite): ``h`` is taken as the normal. Such pairs are
  at the horizon, where every model returns 0.
"""

from __future__ import annotations

import numpy as np

from ._checks import directions, finite_array, finite_scalar

__all__ = [
    "half_diff",
    "half_diff_parts",
    "isotropic_half_diff_rad",
    "normalize_sum",
    "half_diff_to_directions",
    "spherical_to_vector",
    "vector_to_spherical",
    "rotate_about_normal",
    "to_material_frame",
    "local_frame",
    "world_to_local",
    "local_to_world",
    "mirror_direction",
]


def normalize_sum(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """normalize(a + b) with the normal (0, 0, 1) where the sum vanishes."""
    h = a + b
    n = np.sqrt(np.einsum("...i,...i->...", h, h))
    tiny = n < 1e-300
    if np.any(tiny):
        h = np.where(tiny[..., None], np.array([0.0, 0.0, 1.0]), h)
        n = np.where(tiny, 1.0, n)
    return h / n[..., None]


def half_diff_parts(wi: np.ndarray, wo: np.ndarray):
    """Core of :func:`half_diff` on already-normalised vectors.

    Returns ``theta_h, cos_phi_h, sin_phi_h, theta_d, cos_phi_d, sin_phi_d`` so that
    callers needing ``cos(m phi)`` avoid the arctan2/cos round trip.
    """
    h = normalize_sum(wi, wo)
    hx, hy, hz = h[..., 0], h[..., 1], h[..., 2]
    sin_th = np.hypot(hx, hy)
    theta_h = np.arctan2(sin_th, hz)
    pole = sin_th <= 0.0
    safe = np.where(pole, 1.0, sin_th)
    cph = np.where(pole, 1.0, hx / safe)
    sph = np.where(pole, 0.0, hy / safe)
    # rotate wi by -phi_h about z
    x1 = cph * wi[..., 0] + sph * wi[..., 1]
    y1 = -sph * wi[..., 0] + cph * wi[..., 1]
    z1 = wi[..., 2]
    # then by -theta_h about y  (cos theta_h = hz, sin theta_h = sin_th)
    dx = hz * x1 - sin_th * z1
    dy = y1
    dz = sin_th * x1 + hz * z1
    sin_td = np.hypot(dx, dy)
    theta_d = np.arctan2(sin_td, dz)
    dpole = sin_td <= 1e-15
    safe_d = np.where(dpole, 1.0, sin_td)
    cpd = np.where(dpole, 1.0, dx / safe_d)
    spd = np.where(dpole, 0.0, dy / safe_d)
    return theta_h, cph, sph, theta_d, cpd, spd


def isotropic_half_diff_rad(wi, wo):
    """(theta_h, theta_d, phi_d folded to [0, pi)) [rad] of normalised direction pairs
    ``wi``, ``wo`` (..., 3), each of shape (...): the coordinates of an isotropic BRDF,
    where reciprocity makes phi_d and phi_d + pi one (tables and scattered samples)."""
    th, _, _, td, cpd, spd = half_diff_parts(wi, wo)
    return th, td, np.mod(np.arctan2(spd, cpd), np.pi)

def half_diff(wi, wo):
    """Halfway/difference angles (Rusinkiewicz 1998) of direction pairs.

    Parameters
    ----------
    wi, wo : array_like, shape (..., 3)
        Directions to the source and to the observer in the surface frame. Normalised on
        entry; they broadcast against each other.

    Returns
    -------
    theta_h, phi_h, theta_d, phi_d : ndarray
        Polar and azimuthal angles [rad] of the half vector and of the difference vector.
        ``theta_h, theta_d`` in [0, pi]; for pairs above the horizon both are in
        [0, pi/2]. ``phi`` in (-pi, pi]. Singular points get ``phi = 0`` (module notes).
    """
    wi = directions("wi", wi)
    wo = directions("wo", wo)
    wi, wo = np.broadcast_arrays(wi, wo)
    th, cph, sph, td, cpd, spd = half_diff_parts(wi, wo)
    return th, np.arctan2(sph, cph), td, np.arctan2(spd, cpd)


def spherical_to_vector(theta, phi) -> np.ndarray:
    """Unit vector(s) from polar angle ``theta`` and azimuth ``phi`` [rad], shape (..., 3)."""
    theta = np.asarray(theta, dtype=float)
    phi = np.asarray(phi, dtype=float)
    st = np.sin(theta)
    return np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), np.cos(theta)), axis=-1)


def vector_to_spherical(v):
    """Polar angle and azimuth [rad] of direction(s) ``v`` (..., 3); azimuth 0 on the axis."""
    v = directions("v", v)
    theta = np.arctan2(np.hypot(v[..., 0], v[..., 1]), v[..., 2])
    phi = np.arctan2(v[..., 1], v[..., 0])
    return theta, phi


def half_diff_to_directions(theta_h, phi_h, theta_d, phi_d):
    """Inverse of :func:`half_diff`: directions ``(wi, wo)`` from the four angles [rad].

    ``wi = R_z(phi_h) R_y(theta_h) d`` and ``wo`` is ``wi`` reflected about ``h``.
    """
    h = spherical_to_vector(theta_h, phi_h)
    d = spherical_to_vector(theta_d, phi_d)
    th = np.asarray(theta_h, dtype=float)
    ph = np.asarray(phi_h, dtype=float)
    ct, st = np.cos(th), np.sin(th)
    cp, sp = np.cos(ph), np.sin(ph)
    # R_y(theta_h)
    x1 = ct * d[..., 0] + st * d[..., 2]
    y1 = d[..., 1]
    z1 = -st * d[..., 0] + ct * d[..., 2]
    # R_z(phi_h)
    wi = np.stack([cp * x1 - sp * y1, sp * x1 + cp * y1, z1], axis=-1)
    h, wi = np.broadcast_arrays(h, wi)
    wo = 2.0 * np.einsum("...i,...i->...", wi, h)[..., None] * h - wi
    return wi, wo


def rotate_about_normal(v, angle_rad) -> np.ndarray:
    """Rotate direction(s) ``v`` (..., 3) by ``angle_rad`` (counter-clockwise) about z."""
    v = np.asarray(v, dtype=float)
    a = np.asarray(angle_rad, dtype=float)
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]], axis=-1)


def to_material_frame(v, groove_angle_rad) -> np.ndarray:
    """Express surface-frame direction(s) in the material frame of a grooved sample.

    The material's x axis (grooves) lies at ``groove_angle_rad`` counter-clockwise from
    the surface frame's x axis, so material coordinates are ``v`` rotated by ``-angle``.
    """
    finite_scalar("groove_angle_rad", groove_angle_rad)
    return rotate_about_normal(v, -float(groove_angle_rad))


def local_frame(normal, tangent) -> np.ndarray:
    """Orthonormal surface frame from a normal and a (not necessarily orthogonal) tangent.

    Returns
    -------
    ndarray, shape (3, 3)
        Rows are the frame axes x (tangent, made orthogonal to the normal), y = z x x, z.

    Raises
    ------
    ValueError
        If the tangent is parallel to the normal.
    """
    z = directions("normal", normal)
    t = finite_array("tangent", tangent)
    if z.shape != (3,) or t.shape != (3,):
        raise ValueError(f"normal and tangent: expected 3-vectors, got shapes {z.shape} and {t.shape}")
    x = t - np.dot(t, z) * z
    nx = np.linalg.norm(x)
    if not nx > 1e-9 * max(np.linalg.norm(t), 1e-300):
        raise ValueError(f"tangent={t.tolist()!r} is parallel to normal={z.tolist()!r}: expected a tangent not along the normal")
    x /= nx
    y = np.cross(z, x)
    return np.stack([x, y, z])


def world_to_local(v, frame) -> np.ndarray:
    """World direction(s) (..., 3) into a frame from :func:`local_frame`."""
    return np.asarray(v, dtype=float) @ np.asarray(frame).T


def local_to_world(v, frame) -> np.ndarray:
    """Frame direction(s) (..., 3) back to world coordinates."""
    return np.asarray(v, dtype=float) @ np.asarray(frame)


def mirror_direction(wi) -> np.ndarray:
    """Specular (mirror) direction of ``wi`` about the surface normal z."""
    wi = directions("wi", wi)
    return wi * np.array([-1.0, -1.0, 1.0])
