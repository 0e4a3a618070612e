"""Where rays first meet a backstop (terrain or an occluder, not a target): shared by the
laser surface danger zone (:mod:`hazard.pipeline.sdz`), the pointing checks
(:mod:`hazard.pipeline.pointing`) and the mirror beams' reach
(:mod:`hazard.pipeline.mirror_reach`). Below all three (imports none of them)."""

from __future__ import annotations

import numpy as np

__all__ = ["first_backstop_rays"]


def first_backstop_rays(origins, dirs, ray_scene, n_targets, max_passes=64) -> np.ndarray:
    """Distance [m] along each direction ``dirs`` (N, 3; normalised here) from its own origin
    ``origins`` (N, 3) [m] to the first terrain or occluder hit (inf: none, or no
    ``ray_scene``), through the targets (the first ``n_targets`` objects: a ray that meets
    one goes on from just past it, at most ``max_passes`` times)."""
    dirs = np.asarray(dirs, float)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    out = np.full(len(dirs), np.inf)
    if ray_scene is None:
        return out
    rows = np.arange(len(dirs))
    start = np.array(origins, float)
    gone = np.zeros(len(dirs))
    step = 1e-6 * max(getattr(ray_scene, "scale_m", 1.0), 1.0)
    for _ in range(max_passes):
        hits = ray_scene.first_hit(start[rows], dirs[rows])
        stop = hits.hit & (hits.obj >= n_targets)
        out[rows[stop]] = gone[rows[stop]] + hits.t[stop]
        through = hits.hit & (hits.obj < n_targets)
        if not through.any():
            return out
        r = rows[through]
        gone[r] += hits.t[through] + step
        start[r] = start[r] + dirs[r] * (hits.t[through] + step)[:, None]
        rows = r
    return out  # rays still passing targets after max_passes stay unstopped (inf): conservative
