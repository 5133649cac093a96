"""Triangle meshes of the test rigs' walls (host-side NumPy).

Every function returns ``(vertices, triangles)``: vertices [m] shape (V, 3) float64, triangles shape
(F, 3) int64, wound so that the right-hand normal points to the side named in the docstring (the
particle side; :meth:`warpdem.ModelBuilder.coat_wall` glues spheres on that side). The engine's
triangles are two-sided, so the winding matters only for coating and for pictures.
"""

from __future__ import annotations

import math

import numpy as np


def _merge(*parts):
    """Concatenate meshes: (vertices, triangles) pairs -> one pair."""
    verts, tris, base = [], [], 0
    for v, t in parts:
        verts.append(v)
        tris.append(t + base)
        base += len(v)
    return np.concatenate(verts), np.concatenate(tris)


def _segments(radius: float, cell: float, minimum: int = 16) -> int:
    """Segments around a circle of ``radius`` so that an edge is about ``cell`` long (at least ``minimum``)."""
    return int(max(minimum, math.ceil(2 * math.pi * radius / cell)))


def grid_plate(
    size_x: float, size_y: float, cell: float, z: float = 0.0, center=(0.0, 0.0), up: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Rectangle in the plane z = ``z``, split into squares of about ``cell`` [m] (two triangles each), so
    that per-face statistics (impacts) resolve where things happen. Normal +z when ``up`` else -z."""
    nx, ny = max(1, math.ceil(size_x / cell)), max(1, math.ceil(size_y / cell))
    xs = center[0] + np.linspace(-size_x / 2, size_x / 2, nx + 1)
    ys = center[1] + np.linspace(-size_y / 2, size_y / 2, ny + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    v = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 1) + 1, a + 1
    t = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return v, (t if up else t[:, ::-1]).astype(np.int64)


def disc(radius: float, cell: float, z: float = 0.0, up: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Flat disc of ``radius`` [m] at height ``z``: a fan at the centre, then rings about ``cell`` [m] wide with
    the same number of segments; normal +z when ``up`` else -z."""
    rings = max(1, math.ceil(radius / cell))
    n = _segments(radius, cell)
    ang = 2 * math.pi * np.arange(n) / n
    verts = [np.array([[0.0, 0.0, z]])]
    for k in range(1, rings + 1):
        r = radius * k / rings
        verts.append(np.column_stack([r * np.cos(ang), r * np.sin(ang), np.full(n, z)]))
    seg = np.arange(n)
    tris = [np.column_stack([np.zeros(n, dtype=np.int64), 1 + seg, 1 + (seg + 1) % n])]
    for k in range(1, rings):
        a = 1 + (k - 1) * n + seg
        b = 1 + (k - 1) * n + (seg + 1) % n
        tris.append(np.column_stack([a, a + n, b + n]))
        tris.append(np.column_stack([a, b + n, b]))
    t = np.concatenate(tris).astype(np.int64)
    return np.concatenate(verts), (t if up else t[:, ::-1])


def frustum(
    r_bottom: float, r_top: float, z_bottom: float, z_top: float, cell: float, inward: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Open lateral surface of a truncated cone about the z axis (a cylinder when the radii are equal, a
    funnel when ``r_top > r_bottom``), rings about ``cell`` [m] apart. Normals point to the axis when
    ``inward`` (particles inside: funnel, die, lifting cylinder), else away from it."""
    n = _segments(max(r_bottom, r_top), cell)
    slant = math.hypot(r_top - r_bottom, z_top - z_bottom)
    rows = max(1, math.ceil(slant / cell))
    ang = 2 * math.pi * np.arange(n) / n
    verts = []
    for k in range(rows + 1):
        s = k / rows
        r = r_bottom + s * (r_top - r_bottom)
        verts.append(np.column_stack([r * np.cos(ang), r * np.sin(ang), np.full(n, z_bottom + s * (z_top - z_bottom))]))
    tris = []
    for k in range(rows):
        a = k * n + np.arange(n)
        b = k * n + (np.arange(n) + 1) % n
        c, d = b + n, a + n
        tris.append(np.column_stack([a, b, c]))
        tris.append(np.column_stack([a, c, d]))
    t = np.concatenate(tris).astype(np.int64)
    # (a, b, c) walks counter-clockwise seen from outside: its normal points outward
    return np.concatenate(verts), (t[:, ::-1] if inward else t)


def funnel(
    top_diameter: float,
    outlet_diameter: float,
    cone_angle_deg: float,
    stem_length: float,
    outlet_height: float,
    cell: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Laboratory funnel, axis z, outlet (stem end) at height ``outlet_height`` [m]: a stem of
    ``stem_length`` [m] and ``outlet_diameter`` [m], then a cone of included angle ``cone_angle_deg`` opening
    to ``top_diameter`` [m]. Normals inward."""
    r_o, r_t = outlet_diameter / 2, top_diameter / 2
    cone_h = (r_t - r_o) / math.tan(math.radians(cone_angle_deg) / 2)
    z0 = outlet_height
    parts = []
    if stem_length > 0:
        parts.append(frustum(r_o, r_o, z0, z0 + stem_length, cell))
    parts.append(frustum(r_o, r_t, z0 + stem_length, z0 + stem_length + cone_h, cell))
    return _merge(*parts)


def funnel_height(top_diameter: float, outlet_diameter: float, cone_angle_deg: float) -> float:
    """Height of a funnel's cone [m] (see :func:`funnel`)."""
    return (top_diameter - outlet_diameter) / 2 / math.tan(math.radians(cone_angle_deg) / 2)


def open_box(
    length: float, width: float, height: float, cell: float, open_sides=("top",), origin=(0.0, 0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Box x in [0, length], y in [-width/2, width/2], z in [0, height] shifted by ``origin``, without the
    faces named in ``open_sides`` (any of top, bottom, front (x = 0), rear (x = length), left (y < 0),
    right (y > 0)). Normals point into the box."""
    L, W, H = length, width, height
    ox, oy, oz = origin
    parts = []

    def rect(p0, e1, e2, n1, n2):
        """Rectangle p0 + s e1 + t e2 split into n1 x n2 cells; winding e1 x e2."""
        s, t = np.meshgrid(np.linspace(0, 1, n1 + 1), np.linspace(0, 1, n2 + 1), indexing="ij")
        v = np.asarray(p0) + s.ravel()[:, None] * np.asarray(e1) + t.ravel()[:, None] * np.asarray(e2)
        i, j = np.meshgrid(np.arange(n1), np.arange(n2), indexing="ij")
        a = (i * (n2 + 1) + j).ravel()
        b, c, d = a + (n2 + 1), a + (n2 + 1) + 1, a + 1
        return v, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])]).astype(np.int64)

    def cells(x):
        return max(1, math.ceil(x / cell))

    o = np.array([ox, oy - W / 2, oz])
    faces = {
        # (corner, e1, e2) with e1 x e2 pointing into the box
        "bottom": (o, (L, 0, 0), (0, W, 0)),
        "top": (o + (0, 0, H), (0, W, 0), (L, 0, 0)),
        "front": (o, (0, W, 0), (0, 0, H)),
        "rear": (o + (L, 0, 0), (0, 0, H), (0, W, 0)),
        "left": (o, (0, 0, H), (L, 0, 0)),
        "right": (o + (0, W, 0), (L, 0, 0), (0, 0, H)),
    }
    for name, (p0, e1, e2) in faces.items():
        if name in open_sides:
            continue
        parts.append(rect(p0, e1, e2, cells(np.linalg.norm(e1)), cells(np.linalg.norm(e2))))
    return _merge(*parts)


def face_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle [m^2], shape (F,)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
