"""Analytic signed distances between capsules and spheres.

Every collision geom of our robot models is a capsule or a sphere, and a sphere is a capsule of
zero length. So one function, the distance between two line segments, decides every collision:
`distance = |closest points| - radius_a - radius_b`, negative when the geoms overlap.

MJX contacts are disabled in our models (a collision ends the episode, so contact forces are never
needed) and these checks run on the geom poses that `mjx.step` computes anyway. The pairs to check
are the explicit `<contact><pair>` entries of the robot's MJCF; `tests/test_collision.py` checks the
verdicts against MuJoCo's own `mj_collision` on the same pairs.
"""

from __future__ import annotations

import jax.numpy as jnp

_EPS = 1e-12


def closest_segment_params(p0, d0, q0, d1):
    """Parameters (s, t) in [0, 1] of the closest points p0 + s d0 and q0 + t d1 of two segments.

    Segments are given by a start point and a direction (end - start); degenerate segments
    (points) are allowed. Follows the clamped closed form of Ericson, Real-Time Collision
    Detection, sec. 5.1.9, written without branches so it vectorises. Works on `[..., 3]` arrays.
    """
    r = p0 - q0
    a = jnp.sum(d0 * d0, axis=-1)
    e = jnp.sum(d1 * d1, axis=-1)
    b = jnp.sum(d0 * d1, axis=-1)
    c = jnp.sum(d0 * r, axis=-1)
    f = jnp.sum(d1 * r, axis=-1)
    a_ok, e_ok = a > _EPS, e > _EPS
    safe_a = jnp.where(a_ok, a, 1.0)
    safe_e = jnp.where(e_ok, e, 1.0)
    denom = a * e - b * b
    # Non-parallel segments: closest point of the infinite lines, clamped to segment 0.
    s = jnp.where(denom > _EPS * a * e, jnp.clip((b * f - c * e) / jnp.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    # Closest point on segment 1 to that point, then re-clamp s if t was clamped.
    t = (b * s + f) / safe_e
    s = jnp.where(t < 0.0, jnp.clip(-c / safe_a, 0.0, 1.0), jnp.where(t > 1.0, jnp.clip((b - c) / safe_a, 0.0, 1.0), s))
    t = jnp.clip(t, 0.0, 1.0)
    # Degenerate cases: segment 0 a point, segment 1 a point, or both.
    s = jnp.where(a_ok, s, 0.0)
    t = jnp.where(a_ok, t, jnp.clip(f / safe_e, 0.0, 1.0))
    s = jnp.where(a_ok & ~e_ok, jnp.clip(-c / safe_a, 0.0, 1.0), s)
    t = jnp.where(e_ok, t, 0.0)
    return s, t


def segment_distance(p0, p1, q0, q1):
    """Euclidean distance between segments [p0, p1] and [q0, q1] (`[..., 3]` arrays)."""
    d0, d1 = p1 - p0, q1 - q0
    s, t = closest_segment_params(p0, d0, q0, d1)
    gap = (p0 + s[..., None] * d0) - (q0 + t[..., None] * d1)
    return jnp.sqrt(jnp.sum(gap * gap, axis=-1) + _EPS)


def point_segment_distance(x, p0, p1):
    """Euclidean distance from points `x` to segments [p0, p1] (`[..., 3]` arrays)."""
    d = p1 - p0
    dd = jnp.sum(d * d, axis=-1)
    t = jnp.clip(jnp.sum((x - p0) * d, axis=-1) / jnp.where(dd > _EPS, dd, 1.0), 0.0, 1.0)
    gap = x - (p0 + t[..., None] * d)
    return jnp.sqrt(jnp.sum(gap * gap, axis=-1) + _EPS)


def capsule_segments(geom_xpos, geom_xmat, half_length):
    """World-frame end points of capsule axes (MuJoCo capsules lie along their local z axis).

    `geom_xpos` `[..., n, 3]`, `geom_xmat` `[..., n, 3, 3]` (MuJoCo's row-major rotation, so the
    local z axis is the last column), `half_length` `[n]` (0 for spheres).
    """
    axis = geom_xmat[..., :, 2] * half_length[:, None]
    return geom_xpos - axis, geom_xpos + axis


def pair_distances(geom_xpos, geom_xmat, radius, half_length, pair_a, pair_b):
    """Signed distances of the geom pairs (`pair_a[k]`, `pair_b[k]`); negative means overlap."""
    start, end = capsule_segments(geom_xpos, geom_xmat, half_length)
    dist = segment_distance(start[..., pair_a, :], end[..., pair_a, :], start[..., pair_b, :], end[..., pair_b, :])
    return dist - radius[pair_a] - radius[pair_b]


def sphere_distances(center, sphere_radius, geom_xpos, geom_xmat, radius, half_length, geoms):
    """Signed distances between one sphere and each of the capsule/sphere geoms `geoms`."""
    start, end = capsule_segments(geom_xpos[..., geoms, :], geom_xmat[..., geoms, :, :], half_length[geoms])
    return point_segment_distance(center[..., None, :], start, end) - radius[geoms] - sphere_radius
