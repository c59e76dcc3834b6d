"""Stereo renderer of a ``World``: a numba ray caster producing a rectified pair plus true depth.

The scene is the room (a box seen from inside) and a list of oriented boxes: the obstacles
(yaw 0), the target (yawed, its picture on the face its yaw points to, or on all four sides) and the posters (5 mm thin
boxes, picture on the front). Each pixel casts one ray, keeps the nearest hit and samples the hit
face's texture with trilinear, anisotropic mip-mapping driven by the exact screen-space derivatives
of the face coordinates, so distant and slanted textures do not alias (aliasing breaks both SIFT and
block matching). Shading is view-independent (ambient + Lambert from two ceiling lights with a mild
distance falloff), so the left and right images agree photometrically, as block matching expects.

Before casting, every box is projected into the view and binned into 16 x 16 pixel tiles, so a
ray only tests the few boxes that can cover its tile. The pair is rectified by construction: both
cameras share the intrinsics and the orientation given by ``HeadMount.camera_in_world``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from onboard.sim import textures
from onboard.sim.world import check_fits
from shared.world import World
from shared.geometry import HeadMount, Intrinsics, Pose2D, RigidTransform

TILE_PX = 16
ROW_BLOCK = 8  # rows a thread renders together (see _cast)
MAX_ANISO = 4  # taps along the long axis of a pixel's footprint on a slanted surface
POSTER_THICKNESS_M = 0.01  # straddles its plane, so a poster on a wall stands 5 mm proud of it
_AMBIENT = 0.5
_LIGHT_GAIN = 0.5
_LIGHT_FALLOFF = 0.04  # 1 / (1 + k d^2): mild, the room is small
_PICTURE_FACE = 1  # face index 2 * axis + (normal > 0): the local +x face carries the picture
_VERTICAL_FACES = (0, 1, 2, 3)  # ±x, ±y: a picture on each reads left to right from outside


@dataclass(frozen=True)
class StereoFrame:
    left: np.ndarray  # (H, W, 3) uint8 RGB
    right: np.ndarray  # (H, W, 3) uint8 RGB
    depth_m: np.ndarray  # (H, W) float32 z-depth along the left camera's optical axis


class _Scene:
    """The world as flat arrays for the kernels: materials, textures, the room and the boxes."""

    def __init__(self, world: World) -> None:
        self.world = world
        self._atlas = textures.TextureAtlas()
        self._materials: dict[tuple[str, str], int] = {}
        self._mat_rows: list[tuple[float, ...]] = []  # texture, is picture, tile u, v, tint r, g, b
        self._boxes: list[tuple[np.ndarray, np.ndarray, float, list[int]]] = []
        room = world.room
        wall = self._texture(room.texture or textures.default_texture("wall"))
        floor = self._texture(room.floor_texture or textures.default_texture("floor"))
        ceiling = self._texture(room.ceiling_texture or textures.default_texture("ceiling"))
        self.room_mat = np.array([wall, wall, wall, wall, ceiling, floor], dtype=np.int64)
        self._add_boxes()
        self.room = np.array(room.size_m, dtype=np.float64)
        self.box_c = np.array([b[0] for b in self._boxes], dtype=np.float64)
        self.box_h = np.array([b[1] for b in self._boxes], dtype=np.float64)
        yaws = np.array([b[2] for b in self._boxes])
        self.box_cs = np.stack([np.cos(yaws), np.sin(yaws)], axis=1)
        self.box_mat = np.array([b[3] for b in self._boxes], dtype=np.int64)
        rng = np.random.default_rng(7)  # texture offsets per face: no two faces look identical
        self.room_off, self.box_off = rng.random((6, 2)), rng.random((len(self._boxes), 6, 2))
        rows = np.array(self._mat_rows, dtype=np.float64)
        self.mat_tex, self.mat_pic = rows[:, 0].astype(np.int64), rows[:, 1].astype(np.int64)
        self.mat_tile, self.mat_tint = rows[:, 2:4].copy(), rows[:, 4:7].copy()
        self.atlas, self.levels, self.tex_levels = self._atlas.arrays()
        lx, ly, lz = self.room
        self.lights = np.array([[lx / 3, ly / 2, lz - 0.3], [2 * lx / 3, ly / 2, lz - 0.3]])

    def kernel_args(self) -> tuple[np.ndarray, ...]:
        """The arrays ``_cast`` takes after the per-view ones, in its order."""
        return (self.room, self.room_mat, self.room_off, self.box_c, self.box_h, self.box_cs,
                self.box_mat, self.box_off, self.mat_tex, self.mat_pic, self.mat_tile, self.mat_tint,
                self.atlas, self.levels, self.tex_levels, self.lights)

    def _texture(self, name: str) -> int:
        key = ("texture", name)
        if key not in self._materials:
            image = textures.texture_image(name)
            if any(n & (n - 1) for n in image.shape[:2]):
                raise ValueError(f"texture {name!r} must be a power of two on each side to repeat")
            info = textures.texture_info(name)
            self._mat_rows.append((self._atlas.add(image), 0, *info.tile_m, *info.tint))
            self._materials[key] = len(self._mat_rows) - 1
        return self._materials[key]

    def _picture(self, name: str) -> int:
        key = ("picture", name)
        if key not in self._materials:
            image = textures.load_picture(name, self.world.base_dir)
            self._mat_rows.append((self._atlas.add(image), 1, 1.0, 1.0, 1.0, 1.0, 1.0))
            self._materials[key] = len(self._mat_rows) - 1
        return self._materials[key]

    def _add_boxes(self) -> None:
        """Obstacles, then the target, then the posters, each with a material per face."""
        for box in self.world.obstacles:
            mat = self._texture(box.texture or textures.default_texture("obstacle", box.kind))
            lo, hi = np.array(box.min_m), np.array(box.max_m)
            self._boxes.append(((lo + hi) / 2, (hi - lo) / 2, 0.0, [mat] * 6))
        t = self.world.target
        faces = [self._texture(textures.default_texture("target"))] * 6
        for face in (_PICTURE_FACE,) if t.sides == 1 else _VERTICAL_FACES:
            faces[face] = self._picture(t.picture)
        self._boxes.append((t.center_m(), np.array(t.size_m) / 2, math.radians(t.yaw_deg), faces))
        for p in self.world.posters:
            faces = [self._texture(textures.default_texture("poster"))] * 6
            faces[_PICTURE_FACE] = self._picture(p.picture)
            half = np.array([POSTER_THICKNESS_M, *p.size_m]) / 2
            self._boxes.append((np.array(p.center_m), half, math.radians(p.yaw_deg), faces))


# ----------------------------------------------------------------------------- kernels


@numba.njit(cache=True)
def _projected_bounds(cam, fx, fy, cx, cy):
    """Pixel bounds (u0, u1, v0, v1) of a box given by its corners ``cam`` (8, 3) in camera
    coordinates (corner k has bit a set for +half on axis a), clipped to the near plane and
    widened by a pixel; u0 > u1 when nothing lies in front of the camera."""
    near = 1e-3
    u0, u1, v0, v1 = np.inf, -np.inf, np.inf, -np.inf
    for k in range(8):
        for bit in (0, 1, 2, 4):  # 0: corner k; else where its edge to corner k | bit meets `near`
            k2 = k | bit
            if bit == 0 and cam[k, 2] >= near:
                p = cam[k]
            elif bit != 0 and k2 != k and (cam[k, 2] < near) != (cam[k2, 2] < near):
                p = cam[k] + (near - cam[k, 2]) / (cam[k2, 2] - cam[k, 2]) * (cam[k2] - cam[k])
            else:
                continue
            u, v = fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy
            u0, u1, v0, v1 = min(u0, u), max(u1, u), min(v0, v), max(v1, v)
    return u0 - 1.0, u1 + 1.0, v0 - 1.0, v1 + 1.0


@numba.njit(cache=True)
def _bin_boxes(origin, rot, intr, width, height, box_c, box_h, box_cs):
    """The camera origin in each box's frame (n, 3), and per TILE_PX-square tile the boxes whose
    projection may cover it: tile t's are ``items[start[t]:start[t + 1]]``."""
    n = box_c.shape[0]
    ntx, nty = -(-width // TILE_PX), -(-height // TILE_PX)
    box_o = np.empty((n, 3))
    cover = np.zeros((nty, ntx, n), np.bool_)
    cam = np.empty((8, 3))
    for b in range(n):
        c, s = box_cs[b, 0], box_cs[b, 1]
        rel = origin - box_c[b]
        box_o[b, 0], box_o[b, 1], box_o[b, 2] = c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1], rel[2]
        for k in range(8):
            lx, ly = box_h[b, 0] * ((k & 1) * 2 - 1), box_h[b, 1] * ((k >> 1 & 1) * 2 - 1)
            w = (c * lx - s * ly - rel[0], s * lx + c * ly - rel[1], box_h[b, 2] * ((k >> 2 & 1) * 2 - 1) - rel[2])
            for a in range(3):  # camera coordinates: rot^T (corner - origin)
                cam[k, a] = rot[0, a] * w[0] + rot[1, a] * w[1] + rot[2, a] * w[2]
        u0, u1, v0, v1 = _projected_bounds(cam, intr[0], intr[1], intr[2], intr[3])
        if u1 >= 0.0 and v1 >= 0.0 and u0 <= width - 1 and v0 <= height - 1 and u0 <= u1:
            tx0, tx1 = max(0, int(u0) // TILE_PX), min(ntx - 1, int(min(u1, width)) // TILE_PX)
            ty0, ty1 = max(0, int(v0) // TILE_PX), min(nty - 1, int(min(v1, height)) // TILE_PX)
            cover[ty0 : ty1 + 1, tx0 : tx1 + 1, b] = True
    start = np.zeros(ntx * nty + 1, np.int64)
    start[1:] = np.cumsum(cover.reshape(-1, n).sum(axis=1))
    return box_o, start, np.nonzero(cover.ravel())[0] % n


@numba.njit(cache=True, fastmath=True, inline="always")
def _wrap(i, n, repeat):
    if repeat:  # tiled textures are powers of two on every mip level: a mask is a cheap modulo
        return i & (n - 1)
    return min(max(i, 0), n - 1)


@numba.njit(cache=True, fastmath=True, inline="always")
def _bilinear(atlas, lvl, level, s, t, repeat):
    """Bilinear sample (r, g, b) at normalised (s, t) of one mip level."""
    off, w, h = lvl[level, 0], lvl[level, 1], lvl[level, 2]
    x, y = s * w - 0.5, t * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    ax, ay = x - x0, y - y0
    ix0, iy0 = int(x0), int(y0)
    xa, xb = _wrap(ix0, w, repeat), _wrap(ix0 + 1, w, repeat)
    ya, yb = _wrap(iy0, h, repeat), _wrap(iy0 + 1, h, repeat)
    w00, w01, w10, w11 = (1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay
    t00, t01 = atlas[off + ya * w + xa], atlas[off + ya * w + xb]
    t10, t11 = atlas[off + yb * w + xa], atlas[off + yb * w + xb]
    r = w00 * (t00 & 255) + w01 * (t01 & 255) + w10 * (t10 & 255) + w11 * (t11 & 255)
    g = (w00 * ((t00 >> 8) & 255) + w01 * ((t01 >> 8) & 255)
         + w10 * ((t10 >> 8) & 255) + w11 * ((t11 >> 8) & 255))
    b = w00 * (t00 >> 16) + w01 * (t01 >> 16) + w10 * (t10 >> 16) + w11 * (t11 >> 16)
    return r, g, b


@numba.njit(cache=True, fastmath=True, inline="always")
def _half_log2(x, fbuf, ibuf):
    """0.5 * log2(x) for x >= 1, to about 0.005: exponent bits plus a quadratic in the mantissa
    (``fbuf`` and ``ibuf`` are one float64 seen as float and as int64); libm's log2 was a tenth
    of the frame time."""
    fbuf[0] = x
    bits = ibuf[0]
    ibuf[0] = (bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000
    m = fbuf[0]  # mantissa in [1, 2)
    return 0.5 * (((bits >> 52) & 0x7FF) - 1023 + (-0.34484843 * m + 2.02466578) * m - 1.67487759)


@numba.njit(cache=True, fastmath=True, inline="always")
def _sample(atlas, lvl, first, count, s, t, dsx, dtx, dsy, dty, picture, fbuf, ibuf):
    """Trilinear anisotropic texture lookup (r, g, b); (ds, dt)/(dx, dy) are per-pixel derivatives.

    Tiled textures repeat. Pictures clamp at their edges and are sampled more finely (twice the
    taps along both footprint axes, one mip level sharper): they are what SIFT must recognise
    from afar, and they cover few pixels, so the extra cost is small."""
    w0, h0 = lvl[first, 1], lvl[first, 2]
    ax, ay, bx, by = dsx * w0, dtx * h0, dsy * w0, dty * h0
    la2, lb2 = ax * ax + ay * ay, bx * bx + by * by
    if la2 >= lb2:
        major2, minor2, ms, mt, ns, nt = la2, lb2, dsx, dtx, dsy, dty
    else:
        major2, minor2, ms, mt, ns, nt = lb2, la2, dsy, dty, dsx, dtx
    if major2 <= 1.0:  # magnified: the footprint is within a texel of the base level
        return _bilinear(atlas, lvl, first, s, t, not picture)
    # Taps along the long axis: round(major / minor), only while the footprint spans > 1 texel
    # per tap; squared lengths avoid square roots and divisions.
    na, nb = 1, 1
    while na < MAX_ANISO and major2 > (na + 0.5) ** 2 * minor2 and major2 > na * na:
        na += 1
    if picture:
        na, nb = 2 * na, 2
    lod2 = max(major2 / (na * na), minor2 / (nb * nb))
    lod = min(max(_half_log2(lod2, fbuf, ibuf) if lod2 > 1.0 else 0.0, 0.0), count - 1.0)
    l0 = int(lod)
    frac = lod - l0
    l1 = min(l0 + 1, count - 1)
    r, g, b = 0.0, 0.0, 0.0
    for qa in range(na):
        fa = (qa + 0.5) / na - 0.5
        for qb in range(nb):
            fb = (qb + 0.5) / nb - 0.5 if nb > 1 else 0.0
            ts, tt = s + fa * ms + fb * ns, t + fa * mt + fb * nt
            r0, g0, b0 = _bilinear(atlas, lvl, first + l0, ts, tt, not picture)
            r1, g1, b1 = _bilinear(atlas, lvl, first + l1, ts, tt, not picture)
            r += r0 + frac * (r1 - r0)
            g += g0 + frac * (g1 - g0)
            b += b0 + frac * (b1 - b0)
    n = na * nb
    return r / n, g / n, b / n


@numba.njit(cache=True, fastmath=True, inline="always")
def _room_exit(origin, room, dx, dy, dz):
    """(t, axis) where a ray from inside the room leaves it."""
    best, axis = np.inf, 2
    for a, d in enumerate((dx, dy, dz)):
        if d > 1e-12:
            t = (room[a] - origin[a]) / d
        elif d < -1e-12:
            t = -origin[a] / d
        else:
            continue
        if t < best:
            best, axis = t, a
    return best, axis


@numba.njit(cache=True, fastmath=True, inline="always")
def _box_entry(o, h, c, s, dx, dy, dz):
    """(t, axis) where a ray enters an oriented box (slab test in the box frame; ``o`` is the ray
    origin in that frame, ``h`` the half extents), t = inf if it misses or starts inside."""
    tmin, tmax, axis = -np.inf, np.inf, 0
    for a, d in enumerate((c * dx + s * dy, -s * dx + c * dy, dz)):
        if abs(d) < 1e-12:
            if abs(o[a]) > h[a]:
                return np.inf, 0
            continue
        inv = 1.0 / d
        t1, t2 = (-h[a] - o[a]) * inv, (h[a] - o[a]) * inv
        if t1 > t2:
            t1, t2 = t2, t1
        if t1 > tmin:
            tmin, axis = t1, a
        tmax = min(tmax, t2)
    if 1e-6 < tmin <= tmax:
        return tmin, axis
    return np.inf, 0


@numba.njit(cache=True, fastmath=True, inline="always")
def _face_coords(axis, p, d, ex, ey, sx, sy, half):
    """Coordinates on the hit face, in the hit object's frame: (u, v) in metres (vertical faces: u
    to the viewer's right, v downwards), the face size, their exact derivatives per pixel step in
    x and y (``ex``, ``ey`` are the camera axes, ``sx``, ``sy`` = depth / focal length) and the
    face's normal sign along ``axis``."""
    sign = -1.0 if d[axis] > 0 else 1.0  # the visible face's normal opposes the ray
    kx, ky = ex[axis] / d[axis], ey[axis] / d[axis]
    if axis == 0:
        a, b, ua, fw, fh = 1, 2, sign, 2 * half[1], 2 * half[2]
        u = sign * p[1] + half[1]
    elif axis == 1:
        a, b, ua, fw, fh = 0, 2, -sign, 2 * half[0], 2 * half[2]
        u = -sign * p[0] + half[0]
    else:
        a, b, ua, fw, fh = 0, 1, 1.0, 2 * half[0], 2 * half[1]
        u = p[0] + half[0]
    vb = 1.0 if axis == 2 else -1.0  # horizontal faces: v along y; vertical: down
    v = p[1] + half[1] if axis == 2 else half[2] - p[2]
    # The hit point moves on the face plane by s (e - d (e_axis / d_axis)) per pixel step.
    dux, duy = ua * sx * (ex[a] - d[a] * kx), ua * sy * (ey[a] - d[a] * ky)
    dvx, dvy = vb * sx * (ex[b] - d[b] * kx), vb * sy * (ey[b] - d[b] * ky)
    return u, v, fw, fh, dux, dvx, duy, dvy, sign


@numba.njit(parallel=True, cache=True, fastmath=True)
def _cast(origin, rot, intr, block_stride, box_o, tile_start, tile_items, room, room_mat, room_off,
          box_c, box_h, box_cs, box_mat, box_off, mat_tex, mat_pic, mat_tile, mat_tint, atlas, lvl,
          tex_lv, lights, rgb, depth):
    """Render one view into ``rgb`` and ``depth``; see ``_Scene`` for the scene arrays."""
    height, width = depth.shape
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    ntx = (width + TILE_PX - 1) // TILE_PX
    room_half = room / 2.0
    room_o = origin - room_half  # the camera in the room's centred frame
    nblocks = (height + ROW_BLOCK - 1) // ROW_BLOCK
    for k in numba.prange(nblocks * ROW_BLOCK):
        # prange hands each thread one contiguous range of iterations. Mapping them to blocks of
        # rows taken with a stride spreads the costly rows (slanted floor) over all threads, while
        # rows within a block stay adjacent and share cached texels.
        j = ((k // ROW_BLOCK) * block_stride) % nblocks * ROW_BLOCK + k % ROW_BLOCK
        if j >= height:
            continue
        fbuf = np.empty(1)
        ibuf = fbuf.view(np.int64)
        yn = (j - cy) / fy
        for i in range(width):
            xn = (i - cx) / fx
            # The ray in the world, scaled so that its camera z is 1: t along it is the depth.
            dx = rot[0, 0] * xn + rot[0, 1] * yn + rot[0, 2]
            dy = rot[1, 0] * xn + rot[1, 1] * yn + rot[1, 2]
            dz = rot[2, 0] * xn + rot[2, 1] * yn + rot[2, 2]
            best, axis = _room_exit(origin, room, dx, dy, dz)
            hit = -1
            tile = (j // TILE_PX) * ntx + i // TILE_PX
            for q in range(tile_start[tile], tile_start[tile + 1]):
                b = tile_items[q]
                t, a = _box_entry(box_o[b], box_h[b], box_cs[b, 0], box_cs[b, 1], dx, dy, dz)
                if t < best:
                    best, hit, axis = t, b, a
            if hit >= 0:
                c, s, o, half = box_cs[hit, 0], box_cs[hit, 1], box_o[hit], box_h[hit]
            else:
                c, s, o, half = 1.0, 0.0, room_o, room_half
            # Everything below in the hit object's frame (yawed by (c, s)).
            d = (c * dx + s * dy, -s * dx + c * dy, dz)
            p = (o[0] + best * d[0], o[1] + best * d[1], o[2] + best * d[2])
            ex = (c * rot[0, 0] + s * rot[1, 0], -s * rot[0, 0] + c * rot[1, 0], rot[2, 0])
            ey = (c * rot[0, 1] + s * rot[1, 1], -s * rot[0, 1] + c * rot[1, 1], rot[2, 1])
            u, v, fw, fh, dux, dvx, duy, dvy, sign = _face_coords(axis, p, d, ex, ey, best / fx,
                                                                  best / fy, half)
            face = 2 * axis + (1 if sign > 0 else 0)
            if hit >= 0:
                m, off_u, off_v = box_mat[hit, face], box_off[hit, face, 0], box_off[hit, face, 1]
            else:
                m, off_u, off_v = room_mat[face], room_off[face, 0], room_off[face, 1]
            if mat_pic[m]:  # a picture is stretched over the whole face, clamped at its edges
                ku, kv, off_u, off_v = 1.0 / fw, 1.0 / fh, 0.0, 0.0
            else:
                ku, kv = 1.0 / mat_tile[m, 0], 1.0 / mat_tile[m, 1]
            tex = mat_tex[m]
            cr, cg, cb = _sample(atlas, lvl, tex_lv[tex, 0], tex_lv[tex, 1], u * ku + off_u,
                                 v * kv + off_v, dux * ku, dvx * kv, duy * ku, dvy * kv,
                                 mat_pic[m] != 0, fbuf, ibuf)
            # World normal of the face: the local axis, yawed back.
            nx = sign * c if axis == 0 else (-sign * s if axis == 1 else 0.0)
            ny = sign * s if axis == 0 else (sign * c if axis == 1 else 0.0)
            nz = sign if axis == 2 else 0.0
            shade = _AMBIENT
            for li in range(lights.shape[0]):
                lx = lights[li, 0] - (origin[0] + best * dx)
                ly = lights[li, 1] - (origin[1] + best * dy)
                lz = lights[li, 2] - (origin[2] + best * dz)
                facing = nx * lx + ny * ly + nz * lz
                if facing > 0.0:
                    dist2 = lx * lx + ly * ly + lz * lz
                    shade += _LIGHT_GAIN * facing / (np.sqrt(dist2) * (1.0 + _LIGHT_FALLOFF * dist2))
            rgb[j, i, 0] = np.uint8(min(cr * mat_tint[m, 0] * shade + 0.5, 255.0))
            rgb[j, i, 1] = np.uint8(min(cg * mat_tint[m, 1] * shade + 0.5, 255.0))
            rgb[j, i, 2] = np.uint8(min(cb * mat_tint[m, 2] * shade + 0.5, 255.0))
            depth[j, i] = best


# ----------------------------------------------------------------------------- renderer


class StereoRenderer:
    """Renders rectified stereo pairs with ground-truth depth of one world."""

    def __init__(self, world: World, intrinsics: Intrinsics, mount: HeadMount) -> None:
        check_fits(world, mount)
        self.world, self.intrinsics, self.mount = world, intrinsics, mount
        self._scene = _Scene(world)
        k = intrinsics
        self._intr = np.array([k.fx_px, k.fy_px, k.cx_px, k.cy_px], dtype=np.float64)
        nblocks = -(-k.height_px // ROW_BLOCK)
        self._block_stride = next((p for p in (7, 11, 13, 17) if math.gcd(p, nblocks) == 1), 1)

    def render(self, pose: Pose2D, pan_rad: float, tilt_rad: float) -> StereoFrame:
        left, depth = self.render_view(self.mount.camera_in_world(pose, pan_rad, tilt_rad, "left"))
        right, _ = self.render_view(self.mount.camera_in_world(pose, pan_rad, tilt_rad, "right"))
        return StereoFrame(left, right, depth)

    def render_view(self, camera_in_world: RigidTransform) -> tuple[np.ndarray, np.ndarray]:
        """(RGB (H, W, 3) uint8, z-depth (H, W) float32 metres) seen by one camera."""
        origin = np.ascontiguousarray(camera_in_world.translation, dtype=np.float64)
        room = self._scene.room
        if np.any(origin <= 0.0) or np.any(origin >= room):
            raise ValueError(f"camera at {origin.tolist()} is not inside the room {room.tolist()}")
        rot = np.ascontiguousarray(camera_in_world.rotation, dtype=np.float64)
        w, h = self.intrinsics.width_px, self.intrinsics.height_px
        sc = self._scene
        binned = _bin_boxes(origin, rot, self._intr, w, h, sc.box_c, sc.box_h, sc.box_cs)
        rgb = np.empty((h, w, 3), dtype=np.uint8)
        depth = np.empty((h, w), dtype=np.float32)
        _cast(origin, rot, self._intr, self._block_stride, *binned, *sc.kernel_args(), rgb, depth)
        return rgb, depth
