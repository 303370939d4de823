"""Transforms along a tf chain: path search, composition (against 4x4 matrix products from scipy's Rotation) and
moving links brought to one set of stamps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from gyrodenoise.data.tf_chain import Step, compose, coverage, find_path, invert, path_frames, resample


def _matrix(rot: Rotation, t: np.ndarray) -> np.ndarray:
    """(N, 4, 4) homogeneous transforms (N = 1 for a single rotation)."""
    r = rot.as_matrix().reshape(-1, 3, 3)
    m = np.zeros((len(r), 4, 4))
    m[:, :3, :3], m[:, :3, 3], m[:, 3, 3] = r, np.asarray(t).reshape(-1, 3), 1.0
    return m


@pytest.mark.parametrize("seed", range(5))
def test_compose_matches_matrix_products(seed):
    rng = np.random.default_rng(seed)
    n, k = 7, 4
    links, inverted, expected = [], [], np.eye(4)[None].repeat(n, 0)
    for i in range(k):
        static = bool(rng.integers(2)) and i != 1  # at least one link of n samples
        m = 1 if static else n
        rot = Rotation.random(m, random_state=rng.integers(1 << 31))
        t = rng.normal(size=(m, 3))
        inv = bool(rng.integers(2))
        links.append((rot[0], t[0]) if static else (rot, t))
        inverted.append(inv)
        mat = _matrix(rot, t)
        expected = expected @ (np.linalg.inv(mat) if inv else mat)
    rot, trans = compose(links, inverted)
    np.testing.assert_allclose(rot.as_matrix(), expected[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(trans, expected[:, :3, 3], atol=1e-12)


def test_compose_of_a_link_and_its_inverse_is_identity():
    rot, t = Rotation.random(5, random_state=1), np.random.default_rng(1).normal(size=(5, 3))
    r, p = compose([(rot, t), (rot, t)], [False, True])
    assert r.magnitude().max() < 1e-12 and np.abs(p).max() < 1e-12
    ri, ti = invert(rot, t)
    np.testing.assert_allclose((rot * ri).magnitude(), 0.0, atol=1e-12)
    np.testing.assert_allclose(rot.apply(ti) + t, 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="2 links but 1 inverted"):
        compose([(rot, t), (rot, t)], [False])


def test_find_path_uses_links_either_way():
    pairs = [("map", "odom"), ("odom", "base_link"), ("imu", "base_link"), ("base_link", "camera")]
    path = find_path(pairs, "map", "imu")
    assert path == [Step("map", "odom"), Step("odom", "base_link"), Step("imu", "base_link", inverted=True)]
    assert path_frames(path, "map") == ["map", "odom", "base_link", "imu"]
    back = find_path(pairs, "camera", "odom")
    assert back == [Step("base_link", "camera", inverted=True), Step("odom", "base_link", inverted=True)]
    assert find_path(pairs, "map", "elsewhere") is None and find_path(pairs, "nowhere", "map") is None
    assert find_path(pairs, "map", "map") == []
    assert str(path[0]) == "map -> odom" and path[2].pair == ("imu", "base_link")


def test_coverage_outside_and_gaps():
    t = np.array([0, 10, 20, 30, 100, 110, 120], dtype=np.int64)  # a gap from 30 to 100 (median period 10)
    at = np.array([-1, 0, 5, 30, 31, 99, 100, 105, 120, 121], dtype=np.int64)
    outside, in_gap = coverage(t, at)
    assert outside.tolist() == [True, False, False, False, False, False, False, False, False, True]
    assert in_gap.tolist() == [False, False, False, False, True, True, False, False, False, False]
    one_out, one_gap = coverage(np.array([50]), np.array([49, 50, 51]))
    assert one_out.tolist() == [True, False, True] and not one_gap.any()


def test_resample_is_slerp_and_linear():
    t = np.array([1_000, 2_000, 4_000], dtype=np.int64)
    rot = Rotation.random(3, random_state=3)
    trans = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [3.0, 2.0, 1.0]])
    at = np.array([1_000, 1_500, 3_000, 4_000], dtype=np.int64)
    r, p = resample(t, rot, trans, at)
    ref = Slerp([1.0, 2.0, 4.0], rot)([1.0, 1.5, 3.0, 4.0])
    assert (r * ref.inv()).magnitude().max() < 1e-12
    np.testing.assert_allclose(p, [[0, 0, 0], [0.5, 1, 1.5], [2, 2, 2], [3, 2, 1]], atol=1e-12)
    assert (r[0] * rot[0].inv()).magnitude() < 1e-12 and (r[3] * rot[2].inv()).magnitude() < 1e-12
    with pytest.raises(ValueError, match="outside the link"):
        resample(t, rot, trans, np.array([999]))
    r1, p1 = resample(t[:1], rot[:1], trans[:1], np.array([1_000, 1_000]))
    assert len(r1) == 2 and p1.shape == (2, 3)
