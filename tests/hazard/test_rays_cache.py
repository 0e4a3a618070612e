"""The per-process cache of ray scenes (hazard.physics.rays.cached_ray_scene)."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from hazard.physics import rays
from hazard.physics.rays import RayScene, cached_ray_scene, clear_ray_cache, ray_cache_info


@pytest.fixture(autouse=True)
def _empty_cache():
    clear_ray_cache()
    yield
    clear_ray_cache()


def _ground(n=8, size_m=10.0, lift_m=0.0):
    """An n x n grid of squares (2 n^2 triangles) at z = lift_m, plus a small box-like
    tent above its centre: (vertices, faces, object id) pairs."""
    xs = np.linspace(-size_m / 2, size_m / 2, n + 1)
    gx, gy = np.meshgrid(xs, xs)
    v = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, lift_m)], 1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n + 1, i.ravel() + n + 2
    f = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    tent = np.array([[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [0.0, 1.0, 2.0]])
    return [(v, f, 0), (tent, np.array([[0, 1, 2]]), 1)]


def _rays(k=200, seed=0):
    rng = np.random.default_rng(seed)
    o = np.column_stack([rng.uniform(-4, 4, (k, 2)), np.full(k, 5.0)])
    d = np.column_stack([rng.normal(scale=0.2, size=(k, 2)), -np.ones(k)])
    return o, d


def test_same_content_gives_the_same_scene_and_the_same_answers():
    meshes = _ground()
    a = cached_ray_scene(meshes)
    copies = [(v.copy(), f.astype(np.int32), np.int64(oid)) for v, f, oid in meshes]  # equal content, other arrays
    b = cached_ray_scene(copies)
    assert b is a and ray_cache_info()["hits"] == 1 and ray_cache_info()["misses"] == 1
    fresh = RayScene(meshes)
    o, d = _rays()
    got, want = a.first_hit(o, d), fresh.first_hit(o, d)
    assert got.hit.any() and (got.obj == 1).any() and (got.obj == 0).any()  # both objects are hit
    np.testing.assert_array_equal(got.obj, want.obj)
    np.testing.assert_array_equal(got.t, want.t)
    ends = o + 10 * d
    np.testing.assert_array_equal(a.occluded(o, ends), fresh.occluded(o, ends))


def test_an_edited_vertex_or_object_id_gives_a_new_scene():
    meshes = _ground()
    a = cached_ray_scene(meshes)
    v = meshes[1][0].copy()
    v[2, 2] += 1e-9  # the smallest edit still changes the content
    b = cached_ray_scene([meshes[0], (v, meshes[1][1], 1)])
    c = cached_ray_scene([meshes[0], (meshes[1][0], meshes[1][1], 7)])
    assert b is not a and c is not a and b is not c and ray_cache_info()["misses"] == 3
    o, d = _rays()
    assert (c.first_hit(o, d).obj == 7).any() and not (a.first_hit(o, d).obj == 7).any()


def test_lifted_ground_is_hit_at_its_new_height():
    # not an equal-bytes accident: a moved mesh is a different scene with different hits
    a = cached_ray_scene(_ground()[:1])
    b = cached_ray_scene(_ground(lift_m=1.0)[:1])
    o = np.array([[0.3, 0.2, 5.0]])
    d = np.array([[0.0, 0.0, -1.0]])
    assert a.first_hit(o, d).t[0] == pytest.approx(5.0) and b.first_hit(o, d).t[0] == pytest.approx(4.0)


def test_the_entry_bound_drops_the_least_recently_used():
    scenes_ = [_ground(lift_m=float(k))[:1] for k in range(rays.RAY_CACHE_ENTRIES + 2)]
    first = cached_ray_scene(scenes_[0])
    for m in scenes_[1:]:
        cached_ray_scene(m)
        cached_ray_scene(scenes_[0])  # keeps the first one the most recently used
    assert ray_cache_info()["entries"] == rays.RAY_CACHE_ENTRIES
    assert cached_ray_scene(scenes_[0]) is first  # never dropped
    misses = ray_cache_info()["misses"]
    cached_ray_scene(scenes_[1])  # the least recently used: dropped, built again
    assert ray_cache_info()["misses"] == misses + 1


def test_the_memory_bound_holds_and_a_scene_above_it_is_not_kept(monkeypatch):
    small = cached_ray_scene(_ground(n=2)[:1])
    budget = 3 * small.nbytes
    monkeypatch.setattr(rays, "RAY_CACHE_MAX_BYTES", budget)
    clear_ray_cache()
    for k in range(6):
        cached_ray_scene(_ground(n=2, lift_m=float(k))[:1])
        assert ray_cache_info()["nbytes"] <= budget
    assert ray_cache_info()["entries"] == 3
    big = _ground(n=20)[:1]
    assert RayScene(big).nbytes > budget
    assert cached_ray_scene(big) is not cached_ray_scene(big)  # built each time, never kept
    assert ray_cache_info()["nbytes"] <= budget


def test_thread_caps_share_the_built_engine():
    meshes = _ground()
    one = cached_ray_scene(meshes, threads=1)
    two = cached_ray_scene(meshes, threads=2)
    assert one.threads == 1 and two.threads == 2 and two is not one and two._impl is one._impl
    assert cached_ray_scene(meshes, threads=1) is one and ray_cache_info()["misses"] == 1
    o, d = _rays()
    np.testing.assert_array_equal(one.first_hit(o, d).t, two.first_hit(o, d).t)


def test_concurrent_callers_wait_for_one_build():
    meshes = _ground(n=40)
    with ThreadPoolExecutor(6) as pool:
        got = list(pool.map(lambda _: cached_ray_scene(meshes), range(12)))
    assert all(g is got[0] for g in got)
    assert ray_cache_info()["misses"] == 1 and ray_cache_info()["hits"] == 11


def test_a_cached_scene_is_read_only_and_keyed_by_backend():
    s = cached_ray_scene(_ground())
    with pytest.raises(ValueError):
        s.vertices[0, 0] = 1.0
    with pytest.raises(ValueError, match="backend='optix'"):
        cached_ray_scene(_ground(), backend="optix")
    pytest.importorskip("rtree")
    assert cached_ray_scene(_ground(), backend="numpy") is not s
