"""Prescribed rigid motion of mesh walls, as piecewise constant-twist segments.

Every motion the rigs need (a cylinder lifted at constant speed, a piston, a tipping body rotating
about its hinge, USD time-sampled transforms) is a sequence of segments during which the wall
translates with a constant velocity ``v`` and rotates with a constant angular velocity ``w`` about a
pivot that travels with it. Within a segment starting at ``t0`` with pose ``P0`` and pivot ``p0``::

    pose(t) = Translate(p0 + v tau) . Rotate(w tau) . Translate(-p0) . P0,      tau = t - t0
    velocity of a wall point y:  v + w x (y - (p0 + v tau))

Poses map the wall's local vertex coordinates to world coordinates. For the convenience forms
(:meth:`WallMotion.linear`, :meth:`WallMotion.rotation`, :meth:`WallMotion.schedule`) the pose at
t = 0 is the identity, so vertices are given where the wall is at t = 0. :meth:`WallMotion.keyframes`
(the form USD time samples take) gives absolute poses: translation interpolated linearly and rotation
by slerp between samples, held before the first and after the last sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from warpdem.errors import InputError


def _vec(value, where, name):
    a = np.asarray(value, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{where}: {name} = {value!r} is not allowed; expected three finite numbers")
    return a


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions in (x, y, z, w) order (Warp's wp.quat layout)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def quat_from_rotvec(r: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of a rotation vector (axis times angle [rad])."""
    angle = float(np.linalg.norm(r))
    if angle == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    s = math.sin(0.5 * angle) / angle
    return np.array([r[0] * s, r[1] * s, r[2] * s, math.cos(0.5 * angle)])


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector(s) v (shape (3,) or (n, 3)) by unit quaternion q (x, y, z, w)."""
    u, w = np.asarray(q[:3]), float(q[3])
    v = np.asarray(v, dtype=np.float64)
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector of unit quaternion q (x, y, z, w), angle in [0, pi]."""
    q = np.asarray(q, dtype=np.float64)
    if q[3] < 0:
        q = -q
    s = float(np.linalg.norm(q[:3]))
    if s < 1e-15:
        return 2.0 * q[:3]
    return q[:3] / s * 2.0 * math.atan2(s, q[3])


@dataclass(frozen=True)
class Segment:
    """Constant twist from ``start`` to ``end`` [s]: velocity [m/s], angular velocity [rad/s] about ``pivot`` [m].

    ``pivot`` is where the rotation axis passes at the segment's start (world frame); it travels with ``velocity``.
    """

    start: float
    end: float
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)
    pivot: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        where = "Segment"
        if not (math.isfinite(self.start) and self.start >= 0.0):
            raise InputError(f"{where}: start = {self.start!r} is not allowed; expected a time >= 0 s")
        if not (self.end > self.start):
            raise InputError(f"{where}: end = {self.end!r} is not allowed; expected a time after start = {self.start}")
        for name in ("velocity", "angular_velocity", "pivot"):
            object.__setattr__(self, name, tuple(_vec(getattr(self, name), where, name)))


@dataclass(frozen=True)
class WallMotion:
    """Prescribed motion of one wall: ordered, non-overlapping segments, or absolute keyframes.

    Between and after segments the wall holds its pose. Build with the class methods.
    """

    segments: tuple = ()
    keyframe_times: tuple = ()
    keyframe_translations: tuple = ()
    keyframe_rotations: tuple = ()
    """Unit quaternions (x, y, z, w) per keyframe."""

    def __post_init__(self):
        last = 0.0
        for k, s in enumerate(self.segments):
            if not isinstance(s, Segment):
                raise InputError(f"WallMotion: segments[{k}] = {s!r} is not allowed; expected a Segment")
            if s.start < last - 1e-12:
                raise InputError(
                    f"WallMotion: segments[{k}].start = {s.start} is not allowed; expected segments in "
                    f"time order without overlap (previous ends at {last})"
                )
            last = s.end
        if self.keyframe_times:
            t = np.asarray(self.keyframe_times, dtype=np.float64)
            if self.segments:
                raise InputError("WallMotion: give segments or keyframes, not both")
            if np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
                raise InputError(f"WallMotion: keyframe_times = {list(t)} is not allowed; expected increasing times")
            if len(self.keyframe_translations) != len(t) or len(self.keyframe_rotations) != len(t):
                raise InputError("WallMotion: keyframe_translations and keyframe_rotations need one entry per time")

    @staticmethod
    def static() -> WallMotion:
        return WallMotion()

    @staticmethod
    def linear(velocity, start: float = 0.0, end: float = math.inf) -> WallMotion:
        """Translation at constant ``velocity`` [m/s] from ``start`` to ``end`` [s]."""
        return WallMotion((Segment(start, end, velocity=velocity),))

    @staticmethod
    def rotation(angular_velocity, pivot, start: float = 0.0, end: float = math.inf) -> WallMotion:
        """Rotation at constant ``angular_velocity`` [rad/s, vector along the axis] about the axis through ``pivot`` [m]."""
        return WallMotion((Segment(start, end, angular_velocity=angular_velocity, pivot=pivot),))

    @staticmethod
    def schedule(segments) -> WallMotion:
        """A piecewise schedule of :class:`Segment` (or dicts of its fields)."""
        segs = tuple(s if isinstance(s, Segment) else Segment(**s) for s in segments)
        return WallMotion(segs)

    @staticmethod
    def keyframes(times, translations, rotations=None) -> WallMotion:
        """Absolute poses at ``times`` [s]: translations (n, 3) [m], rotations (n, 4) quaternions (x, y, z, w)."""
        t = tuple(float(x) for x in np.asarray(times, dtype=np.float64).reshape(-1))
        tr = np.asarray(translations, dtype=np.float64).reshape(len(t), 3)
        rot = (
            np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
            if rotations is None
            else np.asarray(rotations, dtype=np.float64).reshape(len(t), 4)
        )
        norms = np.linalg.norm(rot, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            raise InputError(f"WallMotion.keyframes: rotations have norms {norms.tolist()}; expected unit quaternions")
        rot = rot / norms[:, None]
        return WallMotion(
            keyframe_times=t, keyframe_translations=tuple(map(tuple, tr)), keyframe_rotations=tuple(map(tuple, rot))
        )

    # compile ---------------------------------------------------------------------------------
    def table(self) -> list[tuple]:
        """Contiguous segments covering [0, inf): (t0, t1, v, w, pivot, pose0 translation, pose0 rotation)."""
        rows = []
        if self.keyframe_times:
            t = np.asarray(self.keyframe_times)
            tr = np.asarray(self.keyframe_translations)
            rot = np.asarray(self.keyframe_rotations)
            if t[0] > 0:
                rows.append((0.0, t[0], np.zeros(3), np.zeros(3), tr[0], tr[0], rot[0]))
            for k in range(len(t) - 1):
                dt = t[k + 1] - t[k]
                rel = quat_mul(rot[k + 1], rot[k] * np.array([-1, -1, -1, 1]))
                w = quat_to_rotvec(rel) / dt
                rows.append((t[k], t[k + 1], (tr[k + 1] - tr[k]) / dt, w, tr[k], tr[k], rot[k]))
            rows.append((t[-1], math.inf, np.zeros(3), np.zeros(3), tr[-1], tr[-1], rot[-1]))
            return [r for r in rows if r[1] > 0.0]
        pos = np.zeros(3)
        quat = np.array([0.0, 0.0, 0.0, 1.0])
        now = 0.0
        for s in self.segments:
            if s.start > now:
                rows.append((now, s.start, np.zeros(3), np.zeros(3), pos.copy(), pos.copy(), quat.copy()))
            v, w, p0 = np.array(s.velocity), np.array(s.angular_velocity), np.array(s.pivot)
            rows.append((s.start, s.end, v, w, p0, pos.copy(), quat.copy()))
            if math.isinf(s.end):
                return rows
            pos, quat = _advance(pos, quat, v, w, p0, s.end - s.start)
            now = s.end
        rows.append((now, math.inf, np.zeros(3), np.zeros(3), pos.copy(), pos.copy(), quat.copy()))
        return rows

    def pose(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """(translation [m], rotation quaternion (x, y, z, w)) at ``time`` [s], evaluated on the host (float64)."""
        for t0, t1, v, w, p0, pos, quat in self.table():
            if time < t1 or math.isinf(t1):
                return _advance(pos, quat, v, w, p0, max(time - t0, 0.0))
        raise AssertionError("unreachable: the table ends with an open segment")


def _advance(pos, quat, v, w, p0, tau):
    dq = quat_from_rotvec(np.asarray(w) * tau)
    new_pos = p0 + v * tau + quat_rotate(dq, pos - p0)
    return new_pos, quat_mul(dq, quat)


@dataclass
class MotionTable:
    """All walls' segments flattened for the device: segment ``s`` of wall ``k`` is row ``start[k] + s``."""

    start: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int32))
    t0: np.ndarray = field(default_factory=lambda: np.zeros(0))
    t1: np.ndarray = field(default_factory=lambda: np.zeros(0))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pivot: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pose_translation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pose_rotation: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))

    @staticmethod
    def build(motions: list[WallMotion]) -> MotionTable:
        rows, start = [], [0]
        for m in motions:
            rows.extend(m.table())
            start.append(len(rows))
        big = 1e30  # stands for an open end on the device

        def col(k, width=None):
            vals = [r[k] for r in rows]
            if width is None:
                return np.array([min(float(x), big) for x in vals], dtype=np.float64)
            return np.array(vals, dtype=np.float64).reshape(-1, width)

        return MotionTable(
            np.array(start, dtype=np.int32), col(0), col(1), col(2, 3), col(3, 3), col(4, 3), col(5, 3), col(6, 4)
        )
