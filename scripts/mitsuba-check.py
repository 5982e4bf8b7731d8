#!/usr/bin/env python3
"""Independent check of `probegi reference` against Mitsuba 3.

What it checks
--------------
For each `--scene` (a Wavefront `.obj`, a probegi `.toml` scene file, or
`builtin:NAME` for the built-in scenes whose source is in this repository) the
script builds the same scene in Mitsuba 3 *by reading the files itself*,
following probegi's documented scene semantics (README "Scene conventions",
`crates/probegi-scene`), not by asking probegi for its geometry. It renders

  1. Mitsuba's `path` integrator (`volpath` when the scene has alpha cutouts,
     see below) to linear-radiance EXR, twice, with two seeds;
  2. `probegi reference` at the same resolution, camera, sample count, sky and
     maximum path length;

and prints a table with FLIP(Mitsuba seed A vs probegi), computed by
`probegi compare`, next to FLIP(Mitsuba seed A vs Mitsuba seed B), the noise
floor at that sample count. A probegi-vs-Mitsuba FLIP well above the noise floor
means the two renderers disagree about the scene; the per-channel mean ratio
(probegi / Mitsuba) tells an energy difference from a noise difference. Images,
the Mitsuba-vs-probegi contact sheet and `results.md` go to `--out-dir`.

Run from the repository root, e.g.

    python3 scripts/mitsuba-check.py \
        --scene ../shared/scenes/cornell-box/CornellBox-Original.obj \
        --camera-pos 0,1,3.9 --camera-target 0,1,0 --fov-y 39.3 \
        --width 160 --height 120 --spp 256
    python3 scripts/mitsuba-check.py --scene scenes/sponza-sun.toml --spp 64

It is a manual check, not part of CI (`scripts/test.sh` does not run it).

Needs
-----
  * Python >= 3.11 (tomllib), `pip install mitsuba numpy` (tested with
    mitsuba 3.9.1, drjit 1.5.0, numpy 2.4). No PIL: textures are read with
    Mitsuba's own `mi.Bitmap`.
  * a built probegi (`--probegi`, default `target/release/probegi`).
  * optional, much faster: the `llvm_ad_rgb` variant (`--variant llvm_ad_rgb`),
    which needs libLLVM: on Debian 12 `apt-get install -y libllvm19`. The
    script sets `DRJIT_LIBLLVM_PATH` to /usr/lib/x86_64-linux-gnu/libLLVM-19.so
    (or another libLLVM it finds) when the variable is unset. The default,
    `scalar_rgb`, needs nothing but is slow, above all with the Python GGX BSDF.

How probegi's semantics are mapped
----------------------------------
  * Camera: Mitsuba `perspective`, `fov_axis = y`, `look_at(position, target,
    up)`, box pixel filter (probegi jitters uniformly inside the pixel). The
    camera is resolved here (scene file's camera, else probegi's bounds-framing
    default, then the command-line overrides) and passed explicitly to both.
  * Scene files: `[[meshes]]` (translation, rotation_deg as intrinsic X-Y-Z
    Euler, scale, `normals`, `crease_angle_deg`), `[[instances]]` (transforms
    lists and jittered grids, with probegi's PCG32 so the copies land where
    probegi puts them), static `[[objects]]` (boxes, rooms, polygons, files),
    `[[lights]]` (keyframes evaluated at `--frame`), `sky_radiance`, `[camera]`;
    `builtin:NAME` reads `scenes/builtin/NAME.toml` (cornell-box: the shared
    CornellBox-Original.obj, which builtin.rs reproduces).
  * Surfaces: two-sided. Kd (× map_Kd) is decoded from sRGB with probegi's
    formula and stored pre-multiplied as a float bitmap (`raw`, bilinear,
    repeat; Mitsuba's and probegi's texel-centre and v = 0 = top-row
    conventions agree; the OBJ `vt` v is flipped as probegi does). Flat,
    unbumped Lambertian materials are Mitsuba `twosided(diffuse)`: exact.
  * Glossy (Ks > 0), bump-mapped and smooth-shaded materials go through a
    Python `mi.BSDF` (`ProbegiBSDF`) that evaluates probegi's BSDF exactly
    (diffuse × (1 − max F0)/π + GGX D · height-correlated Smith G2 · Schlick
    F(F0 = Ks) / (4 cos cos), α = r², r = (2 / (Ns + 2))^¼) in probegi's shading
    frame (shading normal flipped into the geometric hemisphere; bump, see
    below; sides chosen by the geometric normal; viewer clamped just above the
    shading horizon; light only above both planes), sampled with probegi's
    lobe mixture (VNDF + cosine). Mitsuba still does everything else: ray
    casting, UV interpolation, texture filtering, light sampling, MIS,
    Russian roulette. `--shading-model mitsuba` uses Mitsuba's own `bumpmap`
    and `twosided(diffuse)` rules instead: not equivalent (see "Known
    mismatches").
  * Bump maps (MTL `bump`/`map_bump`, `Scene::perturbed_normal` with
    `material::BUMP_WHITE_HEIGHT_REL`, G3D's reading): height = Rec. 709 grey
    of the stored unorm values (not sRGB-decoded), bilinear, repeat; grad =
    its analytic gradient per unit u and v (Mitsuba's `eval_1_grad`, in
    probegi's UV convention); for a W×H map, white_texels = 0.02 · max(W, H)
    and slope = (grad.u / W, grad.v / H) · white_texels · bm (`-bm`, else 1),
    the rise over run in texel space. With n the facing shading normal and
    ∂p/∂u, ∂p/∂v from Mitsuba's interaction (pbrt's formula, as probegi's
    `uv_derivatives`): along_u/v = normalize(∂p/∂u|v − n (n·∂p/∂u|v)) (zero
    where degenerate), n' = normalize(n − along_u slope.u − along_v slope.v)
    (n where degenerate), dropped unless n'·n_g > 1e-3. Triangles whose UV
    mapping is degenerate (|det| < 1e-12) get the material without its bump
    map, as probegi leaves them unbumped.
  * Emission: Ke (× map_Ke) through a Mitsuba `area` emitter on a mesh without
    vertex normals, so it emits from the counter-clockwise (front) face only,
    as probegi does. A constant Ke is given as an `rgb` radiance so that Mitsuba
    samples the emitter by area like probegi (a bitmap radiance would be
    importance-sampled through UVs, which untextured lights do not have).
  * Shading normals: OBJ `vn` as given; corners without one in a smoothing
    group `s N` (N != 0) get angle-weighted normals of the group's faces that
    share the position (bit-equal coordinates); `s 0`/`s off`/no `s` → face
    normal. TOML `normals = "flat" | "smooth"` (+ `crease_angle_deg`) re-derive
    every corner as probegi's `Mesh::derive_normals` does. Flat faces go into
    Mitsuba meshes without vertex normals.
  * Alpha cutouts: coverage = alpha of `map_d` (else its grey level), else the
    alpha of `map_Kd` when it has one, × `d` (or 1 − `Tr`), opaque where ≥ 0.5.
    probegi thresholds the bilinearly filtered coverage; Mitsuba gets a `mask`
    BSDF whose opacity is that threshold evaluated on a grid up to 8× finer
    than the texture (`--cutout-supersample`) and looked up with nearest filtering (a close
    approximation along the cut edges only). Such scenes use `volpath`,
    because Mitsuba's `path` integrator lets no shadow ray through a mask.
    `--no-cutouts` makes everything opaque on both sides
    (`--set alpha_cutouts=false`); `--no-bump` drops bump maps on both sides
    (`--set normal_maps=false`).
  * Lights: directional → `directional` (irradiance W/m², exact); point
    without range → `point` (W/sr, exact); spot lights, and point lights with
    a `range`, → a Python emitter with the glTF KHR_lights_punctual cone
    falloff and range window of probegi (Mitsuba's `spot` falls off linearly
    in angle). Sky → `constant` emitter.
  * Path length: probegi's `--max-depth N` surface interactions = Mitsuba
    `max_depth N + 1` (both default to effectively unbounded; Russian roulette
    differs but both are unbiased). At small N they differ by the sky seen
    from the last vertex: probegi reaches the sky only by BSDF sampling, which
    it does not trace past the last vertex; Mitsuba samples it as an emitter.

Known mismatches / limits
-------------------------
  * `--shading-model mitsuba` is NOT equivalent to probegi's bump rule; it is
    kept to show the pbrt/Mitsuba reading probegi deliberately departs from.
    Mitsuba's `bumpmap` displaces by scale × height in scene units, which for
    orthogonal ∂p/∂u, ∂p/∂v tilts n by slope = scale · grad.u / |∂p/∂u| (and
    likewise in v): matching probegi would need scale = 0.02 · max(W, H) / W ·
    bm · |∂p/∂u| per axis, which varies with the UV density of every triangle
    and differs between u and v, so no constant `scale` reproduces it. This
    checker passes `scale = bm` (1 scene unit per unit of grey). Besides,
    where the bumped normal turns away from the viewer probegi clamps the
    viewer onto the horizon and shades the point, while Mitsuba's `twosided`
    flip evaluates the back side (black, or lit from below).
  * Alpha cutouts in the forest (`scenes/builtin/forest.toml`): FLIP at the noise
    floor, but probegi's mean is 0.5 % below Mitsuba's at 128 spp, about as much as
    the cut-edge approximation moves it (`--cutout-supersample 1` gives +0.5 %).
  * glTF/GLB files are not read by this checker (an error says so).
  * Animated `[[objects]]` are refused; the static scene is rendered at
    `--frame` for lights only.
  * Alpha cut edges: nearest lookup of a finer thresholded grid (above).
  * Emissive triangles always use flat shading here; an emissive material
    with a cutout still emits in Mitsuba where it is cut (probegi: no).
  * glTF normal maps (`normalTexture`) are not handled (glTF is not read).
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import math
import os
import re
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parent.parent

# --------------------------------------------------------------------------------------
# Scene description (probegi's model, independent of Mitsuba)
# --------------------------------------------------------------------------------------

MIN_ALPHA = 1e-3
ALPHA_CUTOFF = 0.5


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = c.astype(np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


SRGB8_TO_LINEAR = srgb_to_linear(np.arange(256, dtype=np.float32) / 255.0)


@dataclass
class Texture:
    path: str
    rgb8: np.ndarray  # (H, W, 3) uint8, row 0 = top
    alpha8: np.ndarray | None  # (H, W) uint8, None if absent or all opaque

    def linear_rgb(self) -> np.ndarray:
        return SRGB8_TO_LINEAR[self.rgb8]

    def grey(self) -> np.ndarray:
        c = self.rgb8.astype(np.float32) / 255.0
        return (0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2]).astype(np.float32)

    def coverage(self) -> np.ndarray:
        if self.alpha8 is not None:
            return self.alpha8.astype(np.float32) / 255.0
        return self.grey()


@dataclass
class Material:
    name: str
    kd: np.ndarray = field(default_factory=lambda: np.full(3, 0.5, np.float32))
    kd_tex: Texture | None = None
    ke: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    ke_tex: Texture | None = None
    ks: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    roughness: float = 1.0
    mtl: bool = False  # MTL specular model (F0 = Ks); False = Lambertian only
    alpha_factor: float = 1.0
    alpha_tex: Texture | None = None
    bump_tex: Texture | None = None
    bump_multiplier: float = 1.0

    def has_specular(self) -> bool:
        return self.mtl and float(self.ks.max()) > 0.0

    def is_emissive(self) -> bool:
        return float(self.ke.max()) > 0.0

    def has_cutout(self) -> bool:
        return self.alpha_tex is not None or self.alpha_factor < ALPHA_CUTOFF


@dataclass
class Light:
    kind: str
    position: np.ndarray
    direction: np.ndarray
    color: np.ndarray
    intensity: float
    range: float | None
    inner: float
    outer: float


@dataclass
class Camera:
    position: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_y_deg: float


@dataclass
class Geometry:
    """Triangles expanded per corner: P (F,3,3), N (F,3,3; zero rows where flat),
    UV (F,3,2), mat (F,) material index, flat (F,) bool."""

    P: np.ndarray
    N: np.ndarray
    UV: np.ndarray
    mat: np.ndarray
    flat: np.ndarray

    @staticmethod
    def empty() -> "Geometry":
        return Geometry(
            np.zeros((0, 3, 3), np.float64),
            np.zeros((0, 3, 3), np.float64),
            np.zeros((0, 3, 2), np.float64),
            np.zeros(0, np.int64),
            np.zeros(0, bool),
        )

    def transform(self, m: np.ndarray) -> None:
        a, t = m[:3, :3], m[:3, 3]
        self.P = self.P @ a.T + t
        nm = np.linalg.inv(a).T
        n = self.N @ nm.T
        ln = np.linalg.norm(n, axis=-1, keepdims=True)
        self.N = np.where(ln > 0, n / np.where(ln > 0, ln, 1), 0.0)
        if np.linalg.det(a) < 0:  # mirroring: keep front faces front
            for arr in (self.P, self.N, self.UV):
                arr[:, [1, 2]] = arr[:, [2, 1]]


@dataclass
class Scene:
    geometry: Geometry
    materials: list[Material]
    lights: list[Light]
    sky: np.ndarray
    camera: Camera | None
    warnings: list[str]


def merge(dst: Scene, src: Scene) -> None:
    off = len(dst.materials)
    g, s = dst.geometry, src.geometry
    dst.geometry = Geometry(
        np.concatenate([g.P, s.P]),
        np.concatenate([g.N, s.N]),
        np.concatenate([g.UV, s.UV]),
        np.concatenate([g.mat, s.mat + off]),
        np.concatenate([g.flat, s.flat]),
    )
    dst.materials += src.materials
    dst.lights += src.lights
    dst.sky = np.maximum(dst.sky, src.sky)
    dst.warnings += src.warnings
    if dst.camera is None:
        dst.camera = src.camera


# --------------------------------------------------------------------------------------
# File lookup, textures
# --------------------------------------------------------------------------------------


def resolve_case_insensitive(base: Path, name: str) -> Path | None:
    name = name.replace("\\", "/")
    exact = base / name
    if exact.exists():
        return exact
    cur = Path("/") if name.startswith("/") else base
    for part in Path(name).parts:
        if part in ("/", "."):
            continue
        if part == "..":
            cur = cur / ".."
            continue
        cand = cur / part
        if cand.exists():
            cur = cand
            continue
        try:
            found = [e for e in os.listdir(cur) if e.lower() == part.lower()]
        except OSError:
            return None
        if not found:
            return None
        cur = cur / found[0]
    return cur if cur.exists() else None


_TEXTURES: dict[Path, Texture] = {}


def load_texture(path: Path) -> Texture:
    import mitsuba as mi

    key = path.resolve()
    if key in _TEXTURES:
        return _TEXTURES[key]
    bmp = mi.Bitmap(str(path))
    arr = np.array(bmp)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.dtype == np.uint16:
        arr = np.round(arr.astype(np.float32) / 257.0).astype(np.uint8)
    elif arr.dtype != np.uint8:
        arr = np.clip(np.round(arr.astype(np.float32) * 255.0), 0, 255).astype(np.uint8)
    ch = arr.shape[2]
    pf = str(bmp.pixel_format())
    has_alpha = ch in (2, 4) or "A" in pf.split(".")[-1]
    if ch in (1, 2):
        rgb = np.repeat(arr[..., :1], 3, axis=2)
    else:
        rgb = arr[..., :3]
    alpha = arr[..., -1] if has_alpha and ch in (2, 4) else None
    if alpha is not None and not (alpha < 255).any():
        alpha = None  # probegi drops an all-opaque alpha plane
    tex = Texture(str(path), np.ascontiguousarray(rgb), None if alpha is None else np.ascontiguousarray(alpha))
    _TEXTURES[key] = tex
    return tex


def texture_file_name(args: str) -> str | None:
    """probegi's obj.rs::texture_file_name: skip `-opt values`, the rest is the name."""
    rest = args.lstrip()
    while rest.startswith("-"):
        parts = rest.split(None, 1)
        option, rest = parts[0], (parts[1].lstrip() if len(parts) > 1 else "")
        words = 3 if option in ("-o", "-s", "-t") else 2 if option == "-mm" else 1
        for _ in range(words):
            parts = rest.split(None, 1)
            value = parts[0] if parts else ""
            after = parts[1] if len(parts) > 1 else ""
            try:
                float(value)
                is_num = True
            except ValueError:
                is_num = False
            is_value = is_num or value in ("on", "off", "r", "g", "b", "m", "l", "z") or (option == "-type" and value)
            if not is_value or not after.strip():
                break
            rest = after.lstrip()
    name = rest.strip()
    return name or None


def texture_option(args: str, option: str) -> float | None:
    m = re.search(r"(?:^|\s)" + re.escape(option) + r"\s+([-+0-9.eE]+)", args)
    if m:
        try:
            return float(m.group(1))
        except ValueError:
            return None
    return None


# --------------------------------------------------------------------------------------
# OBJ / MTL
# --------------------------------------------------------------------------------------


def read_text(path: Path) -> str:
    data = path.read_bytes()
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    return data.decode("utf-8", errors="replace")


def parse_color(toks: list[str]) -> np.ndarray:
    if len(toks) >= 3:
        try:
            return np.array([float(toks[0]), float(toks[1]), float(toks[2])], np.float32)
        except ValueError:
            pass
    return np.full(3, float(toks[0]), np.float32)


def load_mtl(path: Path, materials: list[Material], ids: dict[str, int], warnings: list[str], bump: bool) -> None:
    base = path.parent
    cur: Material | None = None
    for raw in read_text(path).splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        toks = line.split()
        kw, rest = toks[0], line[len(toks[0]) :]
        if kw == "newmtl":
            name = rest.strip()
            cur = Material(name=name, kd=np.full(3, 0.8, np.float32), mtl=True)
            materials.append(cur)
            ids[name] = len(materials) - 1
            continue
        if cur is None:
            continue
        if kw == "Kd":
            cur.kd = parse_color(toks[1:])
        elif kw == "Ke":
            cur.ke = parse_color(toks[1:])
        elif kw == "Ks":
            cur.ks = parse_color(toks[1:])
        elif kw == "Ns":
            ns = max(float(toks[1]), 0.0)
            cur.roughness = (2.0 / (ns + 2.0)) ** 0.25
        elif kw == "d":
            cur.alpha_factor = float(toks[1]) if len(toks) > 1 and not toks[1].startswith("-") else cur.alpha_factor
        elif kw == "Tr":
            cur.alpha_factor = 1.0 - float(toks[1])
        elif kw in ("map_Kd", "map_Ke", "map_d", "bump", "map_bump"):
            name = texture_file_name(rest)
            if name is None:
                continue
            if kw in ("bump", "map_bump") and not bump:
                continue
            p = resolve_case_insensitive(base, name)
            if p is None:
                warnings.append(f"{path}: texture `{name}` not found; using the factor only")
                continue
            tex = load_texture(p)
            if kw == "map_Kd":
                cur.kd_tex = tex
            elif kw == "map_Ke":
                cur.ke_tex = tex
            elif kw == "map_d":
                cur.alpha_tex = tex
            else:
                cur.bump_tex = tex
                bm = texture_option(rest, "-bm")
                cur.bump_multiplier = 1.0 if bm is None else bm
    # MTL cutouts: map_d, else map_Kd's alpha when it has one.
    for m in materials:
        if m.alpha_tex is None and m.kd_tex is not None and m.kd_tex.alpha8 is not None:
            m.alpha_tex = m.kd_tex


def face_normals(P: np.ndarray) -> np.ndarray:
    """Unit counter-clockwise face normals; zero for degenerate triangles."""
    fn = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    return np.where(ln > 0, fn / np.where(ln > 0, ln, 1), 0.0)


def corner_angles(P: np.ndarray) -> np.ndarray:
    e1 = P[:, [1, 2, 0]] - P
    e2 = P[:, [2, 0, 1]] - P
    n1 = np.linalg.norm(e1, axis=2, keepdims=True)
    n2 = np.linalg.norm(e2, axis=2, keepdims=True)
    e1 = np.where(n1 > 0, e1 / np.where(n1 > 0, n1, 1), 0.0)
    e2 = np.where(n2 > 0, e2 / np.where(n2 > 0, n2, 1), 0.0)
    return np.arccos(np.clip((e1 * e2).sum(-1), -1.0, 1.0))


def position_keys(P: np.ndarray) -> np.ndarray:
    """An id per corner, equal for bit-equal f32 coordinates (probegi joins by position)."""
    bits = np.ascontiguousarray(P.reshape(-1, 3).astype(np.float32)).view(np.uint32)
    _, inv = np.unique(bits, axis=0, return_inverse=True)
    return inv.reshape(P.shape[:2])


def derive_normals(P: np.ndarray, N: np.ndarray, derive: np.ndarray, smooth_group: np.ndarray, crease_deg: float):
    """probegi's Mesh::derive_normals on corner-expanded triangles.

    derive (F,3): corners whose normal is re-derived; smooth_group (F,): 0 = flat
    (face normal), g > 0 = angle-weighted normals of the faces of group g that share
    the corner's position and turn from this face by at most crease_deg. Returns
    the new (F,3,3) normals."""
    fn = face_normals(P)
    ang = corner_angles(P)
    out = N.copy()
    F = P.shape[0]
    face_ok = np.linalg.norm(fn, axis=1) > 0
    fallback = np.where(face_ok[:, None], fn, np.array([0.0, 1.0, 0.0]))
    flat_c = derive & (smooth_group[:, None] == 0)
    out[flat_c] = np.broadcast_to(fallback[:, None, :], out.shape)[flat_c]
    smooth_c = derive & (smooth_group[:, None] != 0)
    if not smooth_c.any():
        return out
    pos = position_keys(P)
    # Members: every corner of a non-degenerate smooth face; keyed by (position, group).
    member = (smooth_group[:, None] != 0) & face_ok[:, None] & np.ones((F, 3), bool)
    keys = pos.astype(np.int64) * (int(smooth_group.max()) + 1) + smooth_group[:, None]
    flat_keys = keys.reshape(-1)
    corner_ids = np.arange(F * 3)
    mem_ids = corner_ids[member.reshape(-1)]
    want_ids = corner_ids[smooth_c.reshape(-1)]
    order = mem_ids[np.argsort(flat_keys[mem_ids], kind="stable")]
    sorted_keys = flat_keys[order]
    # For each wanted corner, the range of members with its key.
    lo = np.searchsorted(sorted_keys, flat_keys[want_ids], side="left")
    hi = np.searchsorted(sorted_keys, flat_keys[want_ids], side="right")
    cnt = hi - lo
    total = int(cnt.sum())
    I = np.repeat(want_ids, cnt)
    within = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    J = order[np.repeat(lo, cnt) + within]
    fi, fj = I // 3, J // 3
    cos_c = -2.0 if crease_deg >= 180.0 else math.cos(math.radians(crease_deg))
    keep = (fn[fi] * fn[fj]).sum(-1) >= cos_c
    acc = np.zeros((F * 3, 3))
    np.add.at(acc, I[keep], fn[fj[keep]] * ang.reshape(-1)[J[keep]][:, None])
    la = np.linalg.norm(acc, axis=1, keepdims=True)
    acc = np.where(la > 0, acc / np.where(la > 0, la, 1), 0.0)
    acc = acc.reshape(F, 3, 3)
    zero = np.linalg.norm(acc, axis=2) == 0
    acc = np.where(zero[..., None], fallback[:, None, :], acc)
    out[smooth_c] = acc[smooth_c]
    return out


def apply_normals_rule(scene: "Scene", rule: str, crease_deg: float) -> None:
    """TOML `normals = "file" | "flat" | "smooth"` (scene_file.rs NormalsRule)."""
    g = scene.geometry
    if rule == "file":
        return
    if rule not in ("flat", "smooth"):
        raise SystemExit(f"normals = {rule!r}: expected file, flat or smooth")
    F = g.P.shape[0]
    grp = np.zeros(F, np.int64) if rule == "flat" else np.ones(F, np.int64)
    g.N = derive_normals(g.P, g.N, np.ones((F, 3), bool), grp, crease_deg)
    g.flat = np.full(F, rule == "flat")
    if rule == "flat":
        g.N[:] = 0.0


def load_obj(path: Path, bump: bool = True) -> Scene:
    base = path.parent
    materials: list[Material] = []
    ids: dict[str, int] = {}
    warnings: list[str] = []
    v: list[tuple[float, float, float]] = []
    vt: list[tuple[float, float]] = []
    vn: list[tuple[float, float, float]] = []
    corners_p: list[int] = []
    corners_t: list[int] = []
    corners_n: list[int] = []
    tri_mat: list[int] = []
    tri_group: list[int] = []
    current_mat: int | None = None
    group = 0  # 0 = smoothing off

    def material_id(name: str, warn: str | None) -> int:
        if name in ids:
            return ids[name]
        if warn:
            warnings.append(warn)
        materials.append(Material(name=name))
        ids[name] = len(materials) - 1
        return ids[name]

    for lineno, raw in enumerate(read_text(path).splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        toks = line.split()
        kw = toks[0]
        if kw == "v":
            v.append((float(toks[1]), float(toks[2]), float(toks[3])))
        elif kw == "vt":
            u = float(toks[1])
            tv = float(toks[2]) if len(toks) > 2 else 0.0
            vt.append((u, 1.0 - tv))
        elif kw == "vn":
            vn.append((float(toks[1]), float(toks[2]), float(toks[3])))
        elif kw == "f":
            face = []
            for tok in toks[1:]:
                parts = tok.split("/")

                def idx(s: str, count: int) -> int:
                    i = int(s)
                    return i - 1 if i > 0 else count + i

                pi = idx(parts[0], len(v))
                ti = idx(parts[1], len(vt)) if len(parts) > 1 and parts[1] else -1
                ni = idx(parts[2], len(vn)) if len(parts) > 2 and parts[2] else -1
                face.append((pi, ti, ni))
            if len(face) < 3:
                raise SystemExit(f"{path}:{lineno}: face with fewer than 3 vertices")
            if current_mat is None:
                current_mat = material_id("default", None)
            for k in range(1, len(face) - 1):
                for c in (face[0], face[k], face[k + 1]):
                    corners_p.append(c[0])
                    corners_t.append(c[1])
                    corners_n.append(c[2])
                tri_mat.append(current_mat)
                tri_group.append(group)
        elif kw == "usemtl":
            name = line[len("usemtl") :].strip()
            current_mat = material_id(name, f"{path}:{lineno}: material `{name}` is not defined; using grey")
        elif kw == "mtllib":
            rest = line[len("mtllib") :].strip()
            names = [rest] if resolve_case_insensitive(base, rest) is not None else rest.split()
            for name in names:
                p = resolve_case_insensitive(base, name)
                if p is None:
                    warnings.append(f"{path}: material library `{name}` not found")
                else:
                    load_mtl(p, materials, ids, warnings, bump)
        elif kw == "s":
            arg = toks[1] if len(toks) > 1 else "off"
            if arg.lower() in ("off", "0"):
                group = 0
            else:
                try:
                    group = int(arg)
                except ValueError:
                    group = 1
    if not tri_mat:
        raise SystemExit(f"{path}: no faces")

    V = np.asarray(v, np.float64)
    cp = np.asarray(corners_p, np.int64).reshape(-1, 3)
    ct = np.asarray(corners_t, np.int64).reshape(-1, 3)
    cn = np.asarray(corners_n, np.int64).reshape(-1, 3)
    P = V[cp]
    VT = np.asarray(vt, np.float64) if vt else np.zeros((1, 2))
    UV = np.where((ct >= 0)[..., None], VT[np.maximum(ct, 0)], 0.0)
    VN = np.asarray(vn, np.float64) if vn else np.zeros((1, 3))
    lvn = np.linalg.norm(VN, axis=1, keepdims=True)
    VN = np.where(lvn > 0, VN / np.where(lvn > 0, lvn, 1), 0.0)
    N = np.where((cn >= 0)[..., None], VN[np.maximum(cn, 0)], 0.0)
    has_n = np.linalg.norm(N, axis=2) > 0  # (F,3)
    grp = np.asarray(tri_group, np.int64)

    # OBJ specification: vn as given; corners without one smoothed within their
    # smoothing group; face normals where smoothing is off.
    N = derive_normals(P, N, ~has_n, grp, 180.0)
    flat = ~has_n.any(axis=1) & (grp == 0)
    N[flat] = 0.0
    geom = Geometry(P, N, UV, np.asarray(tri_mat, np.int64), flat)
    return Scene(geom, materials, [], np.zeros(3), None, warnings)


# --------------------------------------------------------------------------------------
# TOML scene files
# --------------------------------------------------------------------------------------


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def placement_matrix(t, r_deg, s) -> np.ndarray:
    """Scale, then intrinsic Euler X-Y-Z rotation (glam EulerRot::XYZ = Rx·Ry·Rz), then translation."""
    r = [math.radians(x) for x in r_deg]
    m = np.eye(4)
    m[:3, :3] = rot_x(r[0]) @ rot_y(r[1]) @ rot_z(r[2]) @ np.diag(s)
    m[:3, 3] = t
    return m


def shared_dir() -> Path:
    env = os.environ.get("PROBEGI_SHARED_DIR")
    if env:
        return Path(env)
    for start in (Path.cwd(), REPO_ROOT):
        for d in [start, *start.parents]:
            if (d / "shared" / "scenes").is_dir():
                return d / "shared"
    raise SystemExit("shared scene folder not found: set PROBEGI_SHARED_DIR")


def polygon_geometry(corners: list, material: int) -> Geometry:
    c = np.asarray(corners, np.float64)
    tris = np.array([[c[0], c[k], c[k + 1]] for k in range(1, len(c) - 1)])
    f = len(tris)
    return Geometry(tris, np.zeros_like(tris), np.zeros((f, 3, 2)), np.full(f, material), np.ones(f, bool))


def box_faces(lo, hi):
    def c(x, y, z):
        return [hi[0] if x else lo[0], hi[1] if y else lo[1], hi[2] if z else lo[2]]

    F, T = False, True
    return [
        [c(F, F, F), c(T, F, F), c(T, F, T), c(F, F, T)],
        [c(F, T, F), c(F, T, T), c(T, T, T), c(T, T, F)],
        [c(F, F, F), c(F, T, F), c(T, T, F), c(T, F, F)],
        [c(F, F, T), c(T, F, T), c(T, T, T), c(F, T, T)],
        [c(F, F, F), c(F, F, T), c(F, T, T), c(F, T, F)],
        [c(T, F, F), c(T, T, F), c(T, T, T), c(T, F, T)],
    ]


def empty_scene() -> Scene:
    return Scene(Geometry.empty(), [], [], np.zeros(3), None, [])


def light_at_frame(d: dict, frame: float) -> dict:
    keys = d.get("keyframes", [])
    out = dict(d)
    for ch in ("position", "direction", "intensity"):
        ks = [(k["frame"], k[ch]) for k in keys if ch in k]
        if not ks:
            continue
        if frame <= ks[0][0]:
            val = ks[0][1]
        elif frame >= ks[-1][0]:
            val = ks[-1][1]
        else:
            for (f0, a), (f1, b) in zip(ks, ks[1:]):
                if f0 <= frame <= f1:
                    t = (frame - f0) / (f1 - f0) if f1 > f0 else 1.0
                    if ch == "intensity":
                        val = a + (b - a) * t
                    else:
                        val = list(np.asarray(a) + (np.asarray(b) - np.asarray(a)) * t)
                        if ch == "direction":
                            n = np.linalg.norm(val)
                            val = list(np.asarray(val) / n) if n > 0 else b
                    break
        out[ch] = val
    return out


def parse_light(d: dict, frame: float) -> Light:
    d = light_at_frame(d, frame)
    return Light(
        kind=d["kind"],
        position=np.asarray(d.get("position", [0, 0, 0]), np.float64),
        direction=np.asarray(d.get("direction", [0, 0, -1]), np.float64),
        color=np.asarray(d.get("color", [1, 1, 1]), np.float64),
        intensity=float(d["intensity"]),
        range=d.get("range"),
        inner=float(d.get("inner_cone_angle", 0.0)),
        outer=float(d.get("outer_cone_angle", math.pi / 4)),
    )


def parse_camera(d: dict) -> Camera:
    return Camera(
        np.asarray(d["position"], np.float64),
        np.asarray(d["target"], np.float64),
        np.asarray(d.get("up", [0, 1, 0]), np.float64),
        float(d["fov_y_deg"]),
    )


def load_sub(spec: str, base: Path, opts: dict, frame: float, bump: bool) -> Scene:
    if spec.startswith("builtin:"):
        sub = load_scene(spec, frame, bump)
    else:
        path = shared_dir() / spec[len("shared:") :] if spec.startswith("shared:") else base / spec
        sub = load_obj(path, bump) if path.suffix.lower() == ".obj" else load_scene(str(path), frame, bump)
    apply_normals_rule(sub, opts.get("normals", "file"), float(opts.get("crease_angle_deg", 180.0)))
    return sub


class Pcg32:
    """probegi_core::rng::Pcg32 (PCG XSH-RR 64/32), for `[[instances]] grid` placements."""

    MULT = 6364136223846793005
    MASK = (1 << 64) - 1

    def __init__(self, seed: int, stream: int):
        self.state = 0
        self.inc = ((stream << 1) | 1) & self.MASK
        self.next_u32()
        self.state = (self.state + seed) & self.MASK
        self.next_u32()

    def next_u32(self) -> int:
        old = self.state
        self.state = (old * self.MULT + self.inc) & self.MASK
        xs = (((old >> 18) ^ old) >> 27) & 0xFFFFFFFF
        rot = old >> 59
        return ((xs >> rot) | (xs << ((-rot) & 31))) & 0xFFFFFFFF

    def next_f32(self) -> np.float32:
        return np.float32(self.next_u32() >> 8) * np.float32(1.0 / 16777216.0)


def instance_placements(e: dict) -> list[np.ndarray]:
    """scene_file.rs InstanceEntry::placements: each copy's transform × the entry's own."""
    own = placement_matrix(e.get("translation", [0, 0, 0]), e.get("rotation_deg", [0, 0, 0]), e.get("scale", [1, 1, 1]))
    out = [
        placement_matrix(t.get("translation", [0, 0, 0]), t.get("rotation_deg", [0, 0, 0]), t.get("scale", [1, 1, 1]))
        @ own
        for t in e.get("transforms", [])
    ]
    g = e.get("grid")
    if g is not None:
        f32 = np.float32
        rng = Pcg32(int(g.get("seed", 1)), 0x1257)
        sx, sz = (f32(v) for v in g["spacing_m"])
        origin = np.asarray(g.get("origin_m", [0, 0, 0]), np.float32)
        jitter = f32(g.get("jitter_m", 0.0))
        s0, s1 = (f32(v) for v in g.get("scale_range", [1.0, 1.0]))
        for j in range(int(g["count"][1])):
            for i in range(int(g["count"][0])):
                jx = rng.next_f32() * f32(2) - f32(1)
                jz = rng.next_f32() * f32(2) - f32(1)
                yaw = rng.next_f32() * f32(2 * math.pi) if g.get("random_yaw", False) else f32(0)
                k = s0 + (s1 - s0) * rng.next_f32()
                at = origin + np.array([f32(i) * sx + jx * jitter, f32(0), f32(j) * sz + jz * jitter], np.float32)
                m = np.eye(4)
                m[:3, :3] = rot_y(float(yaw)) * float(k)
                m[:3, 3] = at
                out.append(m @ own)
    if not out:
        raise SystemExit("[[instances]]: give `transforms` or `grid`")
    return out


def load_toml(path: Path, text: str, base: Path, frame: float, bump: bool) -> Scene:
    f = tomllib.loads(text)
    scene = empty_scene()
    for i, m in enumerate(f.get("meshes", [])):
        sub = load_sub(m["path"], base, m, frame, bump)
        sub.geometry.transform(
            placement_matrix(m.get("translation", [0, 0, 0]), m.get("rotation_deg", [0, 0, 0]), m.get("scale", [1, 1, 1]))
        )
        merge(scene, sub)
    for i, e in enumerate(f.get("instances", [])):
        sub = load_sub(e["path"], base, e, frame, bump)
        sub.lights = []  # probegi does not copy an instanced file's lights
        copies = []
        for xf in instance_placements(e):
            g = Geometry(sub.geometry.P.copy(), sub.geometry.N.copy(), sub.geometry.UV.copy(), sub.geometry.mat, sub.geometry.flat)
            g.transform(xf)
            copies.append(g)
        sub.geometry = Geometry(*[np.concatenate([getattr(c, a) for c in copies]) for a in ("P", "N", "UV", "mat", "flat")])
        merge(scene, sub)
    for i, o in enumerate(f.get("objects", [])):
        if o.get("keyframes") or o.get("motion"):
            raise SystemExit(f"{path}: objects[{i}] is animated; this checker renders static objects only")
        if "path" in o:
            sub = load_sub(o["path"], base, o, frame, bump)
            sub.geometry.transform(
                placement_matrix(
                    o.get("translation", [0, 0, 0]), o.get("rotation_deg", [0, 0, 0]), o.get("scale", [1, 1, 1])
                )
            )
        else:
            name = o.get("name", "object")
            mat = Material(name=name, kd=np.asarray(o.get("albedo", [0.8, 0.8, 0.8]), np.float32))
            if "emission" in o:
                mat.ke = np.asarray(o["emission"], np.float32)
            sub = empty_scene()
            sub.materials = [mat]
            if "polygon_m" in o:
                sub.geometry = polygon_geometry(o["polygon_m"], 0)
            else:
                faces = box_faces(o["box_min_m"], o["box_max_m"])
                gs = [polygon_geometry(fc, 0) for fc in faces]
                g = Geometry(*[np.concatenate([getattr(x, a) for x in gs]) for a in ("P", "N", "UV", "mat", "flat")])
                if o.get("box_inward"):
                    g.P[:, [1, 2]] = g.P[:, [2, 1]]
                sub.geometry = g
        merge(scene, sub)
    scene.lights += [parse_light(l, frame) for l in f.get("lights", [])]
    if "sky_radiance" in f:
        scene.sky = np.asarray(f["sky_radiance"], np.float64)
    if "camera" in f:
        scene.camera = parse_camera(f["camera"])
    return scene


def load_scene(spec: str, frame: float = 0.0, bump: bool = True) -> Scene:
    if spec.startswith("builtin:"):
        name = spec[len("builtin:") :]
        if name == "cornell-box":
            # builtin.rs reproduces CornellBox-Original (materials and geometry) with the default camera.
            s = load_obj(shared_dir() / "scenes" / "cornell-box" / "CornellBox-Original.obj")
            s.camera = Camera(np.array([0, 1, 3.9]), np.array([0, 1, 0.0]), np.array([0, 1, 0.0]), 39.3)
            return s
        if name == "furnace-box":
            s = empty_scene()
            s.materials = [Material("furnace", kd=np.full(3, 0.5, np.float32), ke=np.ones(3, np.float32))]
            lo, hi = [-1, 0, -1], [1, 2, 1]
            gs = [polygon_geometry(fc, 0) for fc in box_faces(lo, hi)]
            g = Geometry(*[np.concatenate([getattr(x, a) for x in gs]) for a in ("P", "N", "UV", "mat", "flat")])
            g.P[:, [1, 2]] = g.P[:, [2, 1]]
            s.geometry = g
            s.camera = Camera(np.array([0, 1, 0.5]), np.array([0, 1, -1.0]), np.array([0, 1, 0.0]), 90.0)
            return s
        p = REPO_ROOT / "scenes" / "builtin" / f"{name}.toml"
        if not p.exists():
            raise SystemExit(f"unknown builtin scene {spec}")
        return load_toml(p, p.read_text(), Path("."), frame, bump)
    path = Path(spec)
    ext = path.suffix.lower()
    if ext == ".obj":
        return load_obj(path, bump=bump)
    if ext == ".toml":
        return load_toml(path, path.read_text(), path.parent, frame, bump)
    if ext in (".gltf", ".glb"):
        raise SystemExit(f"{spec}: glTF is not supported by this checker (OBJ and TOML scenes only)")
    raise SystemExit(f"{spec}: unknown scene type")


def default_camera(scene: Scene) -> Camera:
    """probegi's Scene::default_camera: the file's, else frame the bounds from +Z."""
    if scene.camera is not None:
        return scene.camera
    P = scene.geometry.P.reshape(-1, 3)
    lo, hi = P.min(0), P.max(0)
    centre, half = (lo + hi) * 0.5, (hi - lo) * 0.5
    fov = 45.0
    dist = max(half[0], half[1]) / math.tan(math.radians(fov) * 0.5) + half[2]
    return Camera(centre + np.array([0, 0, 1.0]) * max(dist, 1e-3) * 1.05, centre, np.array([0, 1, 0.0]), fov)


# --------------------------------------------------------------------------------------
# Mitsuba side
# --------------------------------------------------------------------------------------


def setup_mitsuba(variant: str):
    if variant.startswith("llvm") and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        cands = [
            "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
            "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
            *sorted(glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"), reverse=True),
            *sorted(glob.glob("/usr/lib/x86_64-linux-gnu/libLLVM*.so*"), reverse=True),
        ]
        for c in cands:
            if os.path.exists(c):
                os.environ["DRJIT_LIBLLVM_PATH"] = c
                break
    import mitsuba as mi

    try:
        mi.set_variant(variant)
    except Exception as e:  # noqa: BLE001
        print(f"note: Mitsuba variant {variant} unavailable ({e}); falling back to scalar_rgb", file=sys.stderr)
        variant = "scalar_rgb"
        mi.set_variant(variant)
    return mi, variant


def define_plugins(mi):
    import drjit as dr

    def lum(c):
        return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]

    def ggx_d(cos_h, a):
        a2 = a * a
        d = cos_h * cos_h * (a2 - 1.0) + 1.0
        return a2 / (dr.pi * d * d)

    def smith_g1(c, a):
        a2 = a * a
        return 2.0 * c / (c + dr.sqrt(a2 + (1.0 - a2) * c * c))

    def smith_g2(co, ci, a):
        a2 = a * a
        lo = ci * dr.sqrt(a2 + (1.0 - a2) * co * co)
        li = co * dr.sqrt(a2 + (1.0 - a2) * ci * ci)
        return 2.0 * co * ci / (lo + li)

    def vndf(wo, a, u):
        vh = dr.normalize(mi.Vector3f(a * wo.x, a * wo.y, wo.z))
        lensq = vh.x * vh.x + vh.y * vh.y
        inv = dr.rsqrt(dr.maximum(lensq, 1e-30))
        t1 = dr.select(lensq > 0, mi.Vector3f(-vh.y * inv, vh.x * inv, 0.0), mi.Vector3f(1.0, 0.0, 0.0))
        t2 = dr.cross(vh, t1)
        r = dr.sqrt(u.x)
        phi = 2.0 * dr.pi * u.y
        p1 = r * dr.cos(phi)
        s = 0.5 * (1.0 + vh.z)
        p2 = (1.0 - s) * dr.sqrt(dr.maximum(1.0 - p1 * p1, 0.0)) + s * r * dr.sin(phi)
        nh = t1 * p1 + t2 * p2 + vh * dr.sqrt(dr.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
        return dr.normalize(mi.Vector3f(a * nh.x, a * nh.y, dr.maximum(nh.z, 1e-6)))

    class ProbegiBSDF(mi.BSDF):
        """probegi's surface model at a Mitsuba interaction: `probegi_core::bsdf::SurfaceBsdf`
        (diffuse × (1 − max F0)/π + GGX, Schlick F, height-correlated Smith) in the frame of
        `probegi_cpu::shading::ShadingContext`: the shading normal flipped into the geometric
        hemisphere, optionally bump-perturbed as `Scene::perturbed_normal` does, turned to the
        viewer's side by the *geometric* normal; the viewer clamped to just above the shading
        horizon; light accepted only above both the shading and the geometric plane
        (`lambert_cos`). Sampling is probegi's mixture (VNDF + cosine)."""

        def __init__(self, props, diffuse=None, f0=(0.0, 0.0, 0.0), alpha=1.0, bump=None, bump_slope=(1.0, 1.0)):
            mi.BSDF.__init__(self, props)
            self.diffuse = diffuse
            self.f0 = mi.Color3f(*[float(x) for x in f0])
            self.has_spec = max(float(x) for x in f0) > 0.0
            self.f0_lum = float(0.2126 * f0[0] + 0.7152 * f0[1] + 0.0722 * f0[2])
            self.kdiff = 1.0 - min(max(float(x) for x in f0), 1.0)
            self.alpha = max(float(alpha), MIN_ALPHA)
            self.bump = bump
            # slope = grad_uv × bump_slope: (white_texels / W, white_texels / H) × bm.
            self.bump_slope = (float(bump_slope[0]), float(bump_slope[1]))
            both = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [mi.BSDFFlags.DiffuseReflection | both]
            if self.has_spec:
                self.m_components.append(mi.BSDFFlags.GlossyReflection | both)
            flags = self.m_components[0]
            for c in self.m_components[1:]:
                flags = flags | c
            self.m_flags = flags

        def _frame(self, si, active):
            """World facing normal, facing geometric normal, and the local viewer direction."""
            ng = si.n
            ns = si.sh_frame.n
            ns = dr.select(dr.dot(ns, ng) < 0, -ns, ns)
            if self.bump is not None:
                # `Scene::perturbed_normal` (height map): the bilinear gradient per unit u and v,
                # over the texel counts, times the white height in texels and `-bm`, is the
                # rise over run in texel space; it tilts ns against the directions of ∂p/∂u and
                # ∂p/∂v (made orthogonal to ns). glam's `normalize_or_zero` / `normalize_or(n)`
                # on degenerate vectors; dropped unless 1e-3 above the geometric plane.
                grad = self.bump.eval_1_grad(si, active)
                slope = mi.Vector2f(grad.x * self.bump_slope[0], grad.y * self.bump_slope[1])

                def normalize_or_zero(v):
                    ln = dr.norm(v)
                    ok = (ln > 0) & dr.isfinite(ln)
                    return dr.select(ok, v / dr.select(ok, ln, 1.0), 0.0), ok

                along_u, _ = normalize_or_zero(si.dp_du - ns * dr.dot(ns, si.dp_du))
                along_v, _ = normalize_or_zero(si.dp_dv - ns * dr.dot(ns, si.dp_dv))
                b, ok = normalize_or_zero(ns - along_u * slope.x - along_v * slope.y)
                b = dr.select(ok, b, ns)
                ns = dr.select(dr.dot(b, ng) > 1e-3, b, ns)
            wv_world = si.to_world(si.wi)
            front = dr.dot(wv_world, ng) > 0
            nf = dr.select(front, ns, -ns)
            gf = dr.select(front, ng, -ng)
            frame = mi.Frame3f(nf)
            wv = frame.to_local(wv_world)
            wv = dr.normalize(mi.Vector3f(wv.x, wv.y, dr.maximum(wv.z, 1e-4)))
            return frame, gf, wv

        def _lobe_probability(self, base):
            if not self.has_spec:
                return mi.Float(0.0)
            d = lum(base)
            s = self.f0_lum
            return dr.select(d <= 0, 1.0, dr.clip(s / (s + d), 0.1, 0.9))

        def _eval_pdf_local(self, si, wv, wl, ok, active):
            base = self.diffuse.eval(si, active) * self.kdiff
            valid = active & ok & (wv.z > 0) & (wl.z > 0)
            value = base * dr.inv_pi * wl.z
            ps = self._lobe_probability(base)
            pdf = (1.0 - ps) * wl.z * dr.inv_pi
            if self.has_spec:
                h = dr.normalize(wv + wl)
                a = self.alpha
                m = (1.0 - dr.clip(dr.dot(wl, h), 0.0, 1.0)) ** 5
                fres = self.f0 + (1.0 - self.f0) * m
                value += fres * (ggx_d(h.z, a) * smith_g2(wv.z, wl.z, a) / (4.0 * wv.z * wl.z)) * wl.z
                pdf += ps * smith_g1(wv.z, a) * ggx_d(h.z, a) / (4.0 * wv.z)
            return dr.select(valid, value, 0.0), dr.select(valid, pdf, 0.0)

        def sample(self, ctx, si, sample1, sample2, active=True):
            frame, gf, wv = self._frame(si, active)
            base = self.diffuse.eval(si, active) * self.kdiff
            ps = self._lobe_probability(base)
            wl = mi.warp.square_to_cosine_hemisphere(sample2)
            pick_spec = sample1 < ps
            if self.has_spec:
                h = vndf(wv, self.alpha, sample2)
                wl = dr.select(pick_spec, 2.0 * dr.dot(wv, h) * h - wv, wl)
            wl_world = frame.to_world(wl)
            ok = dr.dot(wl_world, gf) > 0
            value, pdf = self._eval_pdf_local(si, wv, wl, ok, active)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = si.to_local(wl_world)
            bs.eta = 1.0
            bs.sampled_type = dr.select(
                pick_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            )
            bs.sampled_component = dr.select(pick_spec, mi.UInt32(1), mi.UInt32(0))
            good = active & (pdf > 0)
            bs.pdf = dr.select(good, pdf, 0.0)
            return bs, dr.select(good, value / dr.select(good, pdf, 1.0), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            frame, gf, wv = self._frame(si, active)
            wl_world = si.to_world(wo)
            ok = dr.dot(wl_world, gf) > 0
            return self._eval_pdf_local(si, wv, frame.to_local(wl_world), ok, active)

        def eval(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[1]

        def eval_diffuse_reflectance(self, si, active=True):
            return self.diffuse.eval(si, active) * self.kdiff

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"ProbegiBSDF[f0={self.f0}, alpha={self.alpha}, bump={self.bump is not None}]"

    class GltfPunctual(mi.Emitter):
        """A point or spot light with KHR_lights_punctual falloff and range window."""

        def __init__(self, props, light: Light):
            mi.Emitter.__init__(self, props)
            self.m_flags = +mi.EmitterFlags.DeltaPosition
            self.pos = mi.Point3f(*[float(x) for x in light.position])
            dn = light.direction / max(np.linalg.norm(light.direction), 1e-30)
            self.dir = mi.Vector3f(*[float(x) for x in dn])
            self.power = mi.Color3f(*[float(x) * light.intensity for x in light.color])
            self.spot = light.kind == "spot"
            co, ci = math.cos(light.outer), math.cos(light.inner)
            self.scale = 1.0 / max(ci - co, 1e-3)
            self.offset = -co * self.scale
            self.range = light.range

        def sample_direction(self, it, sample, active=True):
            ds = dr.zeros(mi.DirectionSample3f)
            to = self.pos - it.p
            d2 = dr.squared_norm(to)
            dist = dr.sqrt(d2)
            wi = to / dist
            e = self.power / d2
            if self.range is not None:
                q = dist / self.range
                e = e * dr.clip(1.0 - q * q * q * q, 0.0, 1.0) ** 2
            if self.spot:
                t = dr.clip(dr.dot(self.dir, -wi) * self.scale + self.offset, 0.0, 1.0)
                e = e * t * t
            ds.p = self.pos
            ds.n = -wi
            ds.d = wi
            ds.dist = dist
            ds.pdf = 1.0
            ds.delta = True
            ds.time = it.time
            return ds, dr.select(active & (d2 > 0), e, 0.0)

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Color3f(0.0)

        def eval(self, si, active=True):
            return mi.Color3f(0.0)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            raise NotImplementedError("light tracing is not supported by this emitter")

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return "GltfPunctual[]"

    return ProbegiBSDF, GltfPunctual


def bitmap_texture(mi, arr: np.ndarray, nearest: bool = False):
    arr = np.ascontiguousarray(arr.astype(np.float32))
    return mi.load_dict(
        {
            "type": "bitmap",
            "bitmap": mi.Bitmap(arr),
            "raw": True,
            "filter_type": "nearest" if nearest else "bilinear",
            "wrap_mode": "repeat",
        }
    )


def const_texture(mi, c):
    """A constant colour (Mitsuba's `rgb` reflectance refuses values above 1: a 1×1 bitmap then)."""
    if max(float(x) for x in c) <= 1.0:
        return mi.load_dict({"type": "rgb", "value": [float(x) for x in c]})
    return bitmap_texture(mi, np.asarray(c, np.float32).reshape(1, 1, 3), nearest=True)


CUTOUT_SUPERSAMPLE = 8


def thresholded_coverage(tex: Texture, factor: float, max_res: int = 4096) -> np.ndarray:
    """Coverage ≥ 0.5 of probegi's bilinear filter, evaluated on a grid k× finer."""
    a = tex.coverage()
    h, w = a.shape
    k = max(1, min(CUTOUT_SUPERSAMPLE, max_res // max(w, h)))

    def resample(arr, n, axis):
        xs = (np.arange(n * k) + 0.5) / k - 0.5
        x0 = np.floor(xs).astype(np.int64)
        fx = (xs - x0).astype(np.float32)
        i0, i1 = np.mod(x0, n), np.mod(x0 + 1, n)
        if axis == 1:
            return arr[:, i0] * (1 - fx) + arr[:, i1] * fx
        return arr[i0, :] * (1 - fx)[:, None] + arr[i1, :] * fx[:, None]

    up = resample(resample(a, w, 1), h, 0)
    return (factor * up >= ALPHA_CUTOFF).astype(np.float32)


# probegi-scene `material::BUMP_WHITE_HEIGHT_REL`: a white texel of a height map rises
# 0.02 · max(W, H) texels (G3D's default `zExtentPixels` of −0.02), times MTL `-bm`.
BUMP_WHITE_HEIGHT_REL = 0.02


def bump_slope(m: Material) -> tuple[float, float]:
    """Factors from the height's gradient per unit (u, v) to probegi's texel-space slope:
    white_texels / W and white_texels / H, times `-bm` (`Scene::perturbed_normal`)."""
    h, w = m.bump_tex.rgb8.shape[:2]
    white_texels = BUMP_WHITE_HEIGHT_REL * max(w, h)
    return (white_texels / w * m.bump_multiplier, white_texels / h * m.bump_multiplier)


def material_bsdf(mi, ProbegiBSDF, m: Material, cache: dict, smooth: bool, model: str):
    """The Mitsuba BSDF of a material. model = "probegi": specular, bump-mapped and
    smooth-shaded materials use ProbegiBSDF (probegi's BSDF and shading-frame rules);
    "mitsuba": only specular ones do, bump maps go through Mitsuba's `bumpmap` with
    scale = bm (the pbrt/Mitsuba reading, not probegi's: see the module docstring)."""
    if m.kd_tex is not None:
        key = (id(m.kd_tex), tuple(m.kd))
        if key not in cache:
            cache[key] = bitmap_texture(mi, m.kd_tex.linear_rgb() * m.kd[None, None, :])
        diffuse = cache[key]
    else:
        diffuse = const_texture(mi, m.kd)
    height = None
    if m.bump_tex is not None:
        key = ("bump", id(m.bump_tex))
        if key not in cache:
            cache[key] = bitmap_texture(mi, m.bump_tex.grey()[..., None])
        height = cache[key]
    alpha = min(max(m.roughness * m.roughness, MIN_ALPHA), 1.0)
    f0 = tuple(float(x) for x in m.ks) if m.has_specular() else (0.0, 0.0, 0.0)
    if model == "probegi" and (m.has_specular() or height is not None or smooth):
        slope = bump_slope(m) if height is not None else (0.0, 0.0)
        bsdf = ProbegiBSDF(mi.Properties(), diffuse=diffuse, f0=f0, alpha=alpha, bump=height, bump_slope=slope)
    else:
        if m.has_specular():
            bsdf = ProbegiBSDF(mi.Properties(), diffuse=diffuse, f0=f0, alpha=alpha)
        else:
            bsdf = mi.load_dict({"type": "twosided", "material": {"type": "diffuse", "reflectance": diffuse}})
        if height is not None:
            bsdf = mi.load_dict(
                {"type": "bumpmap", "arbitrary": height, "scale": float(m.bump_multiplier), "bsdf": bsdf}
            )
    if m.has_cutout():
        if m.alpha_tex is not None:
            opacity = bitmap_texture(mi, thresholded_coverage(m.alpha_tex, m.alpha_factor)[..., None], nearest=True)
        else:
            opacity = mi.load_dict({"type": "rgb", "value": [0.0, 0.0, 0.0]})
        bsdf = mi.load_dict({"type": "mask", "opacity": opacity, "bsdf": bsdf})
    return bsdf


def uv_derivatives_ok(P: np.ndarray, UV: np.ndarray) -> np.ndarray:
    """Per triangle: whether probegi's `uv_derivatives` (pbrt's ∂p/∂u, ∂p/∂v) exists,
    i.e. |det| ≥ 1e-12 of the UV edges (f32, as probegi) and finite derivatives."""
    uv = UV.astype(np.float32)
    p = P.astype(np.float32)
    duv02, duv12 = uv[:, 0] - uv[:, 2], uv[:, 1] - uv[:, 2]
    dp02, dp12 = p[:, 0] - p[:, 2], p[:, 1] - p[:, 2]
    det = duv02[:, 0] * duv12[:, 1] - duv02[:, 1] * duv12[:, 0]
    ok = np.abs(det) >= np.float32(1e-12)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = np.float32(1.0) / np.where(ok, det, np.float32(1.0))
        dpdu = (dp02 * duv12[:, 1:2] - dp12 * duv02[:, 1:2]) * inv[:, None]
        dpdv = (dp12 * duv02[:, 0:1] - dp02 * duv12[:, 0:1]) * inv[:, None]
    return ok & np.isfinite(dpdu).all(axis=1) & np.isfinite(dpdv).all(axis=1)


def make_mesh(mi, name: str, P, N, UV, flat: bool, bsdf, emitter):
    f = P.shape[0]
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    mesh = mi.Mesh(name, 3 * f, f, props, has_vertex_normals=not flat, has_vertex_texcoords=True)
    params = mi.traverse(mesh)

    def put(key, arr):
        t = type(params[key])
        params[key] = t(np.ascontiguousarray(arr.reshape(-1)))

    put("vertex_positions", P.astype(np.float32))
    put("faces", np.arange(3 * f, dtype=np.uint32))
    put("vertex_texcoords", UV.astype(np.float32))
    if not flat:
        put("vertex_normals", N.astype(np.float32))
    params.update()
    return mesh


def build_mitsuba_scene(mi, ProbegiBSDF, GltfPunctual, scene: Scene, cam: Camera, args, notes: list[str]):
    g = scene.geometry
    d: dict = {"type": "scene"}
    cutouts = any(scene.materials[i].has_cutout() for i in np.unique(g.mat))
    integrator = "volpath" if cutouts else "path"
    if cutouts:
        notes.append("alpha cutouts: Mitsuba `volpath` (shadow rays through masks), thresholded-opacity mask BSDF")
    d["integrator"] = {"type": integrator, "max_depth": int(args.max_depth) + 1, "hide_emitters": False}
    try:
        to_world = mi.ScalarTransform4f().look_at(
            origin=[float(x) for x in cam.position], target=[float(x) for x in cam.target], up=[float(x) for x in cam.up]
        )
    except TypeError:
        to_world = mi.ScalarTransform4f.look_at(
            origin=[float(x) for x in cam.position], target=[float(x) for x in cam.target], up=[float(x) for x in cam.up]
        )
    extent = float(np.abs(g.P).max()) if g.P.size else 1.0
    d["sensor"] = {
        "type": "perspective",
        "fov": float(cam.fov_y_deg),
        "fov_axis": "y",
        "near_clip": 1e-4,
        "far_clip": max(1e4, 10.0 * extent),
        "to_world": to_world,
        "film": {
            "type": "hdrfilm",
            "width": args.width,
            "height": args.height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
        },
        "sampler": {"type": "independent", "sample_count": args.spp},
    }
    tex_cache: dict = {}
    n_spec = n_bump = n_pbsdf = 0
    for mi_idx in np.unique(g.mat):
        m = scene.materials[int(mi_idx)]
        sel = g.mat == mi_idx
        smooth = bool((sel & ~g.flat).any()) and not m.is_emissive()
        bsdf = material_bsdf(mi, ProbegiBSDF, m, tex_cache, smooth, args.shading_model)
        n_spec += m.has_specular()
        n_bump += m.bump_tex is not None
        n_pbsdf += args.shading_model == "probegi" and (m.has_specular() or m.bump_tex is not None or smooth)
        emitter = None
        if m.is_emissive():
            if m.ke_tex is not None:
                rad = bitmap_texture(mi, m.ke_tex.linear_rgb() * m.ke[None, None, :])
                emitter = mi.load_dict({"type": "area", "radiance": rad})
            else:
                # A constant radiance: Mitsuba then samples the emitter uniformly by area, as
                # probegi does (a spatially varying one would be sampled through its UVs).
                emitter = mi.load_dict(
                    {"type": "area", "radiance": {"type": "rgb", "value": [float(x) for x in m.ke]}}
                )
            if m.has_cutout():
                notes.append(f"material {m.name}: emissive with a cutout; Mitsuba emits where probegi cuts")
        # probegi leaves the normal unbumped on triangles whose UV mapping is degenerate
        # (`uv_derivatives` → None); Mitsuba would fall back to an arbitrary ∂p/∂u frame there.
        parts = [(sel, bsdf, "")]
        if m.bump_tex is not None and args.shading_model == "probegi":
            bad = sel & ~uv_derivatives_ok(g.P, g.UV)
            if bad.any():
                plain = dataclasses.replace(m, bump_tex=None)
                plain_bsdf = material_bsdf(mi, ProbegiBSDF, plain, tex_cache, smooth, "probegi")
                parts = [(sel & ~bad, bsdf, ""), (bad, plain_bsdf, "_nobump")]
                notes.append(f"material {m.name}: {int(bad.sum())} triangle(s) with degenerate UVs left unbumped")
        for part, part_bsdf, suffix in parts:
            for flat in (True, False):
                s = part & (g.flat == flat)
                if emitter is not None:
                    s = part if flat else np.zeros_like(part)  # emitters: face normals (front face emits)
                if not s.any():
                    continue
                key = f"mesh_{int(mi_idx)}_{'flat' if flat else 'smooth'}{suffix}"
                d[key] = make_mesh(mi, key, g.P[s], g.N[s], g.UV[s], flat, part_bsdf, emitter)
    if n_spec:
        notes.append(f"{n_spec} material(s) with Ks > 0 (GGX lobe)")
    if n_bump:
        how = "ProbegiBSDF's bump frame" if args.shading_model == "probegi" else "Mitsuba `bumpmap`"
        notes.append(f"{n_bump} material(s) with bump maps: {how}")
    if n_pbsdf:
        notes.append(f"{n_pbsdf} material(s) through the Python ProbegiBSDF (--shading-model {args.shading_model})")
    if float(scene.sky.max()) > 0:
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [float(x) for x in scene.sky]}}
    for i, l in enumerate(scene.lights):
        c = [float(x) * l.intensity for x in l.color]
        if max(c) <= 0:
            continue
        if l.kind == "directional":
            dn = l.direction / np.linalg.norm(l.direction)
            d[f"light_{i}"] = {
                "type": "directional",
                "direction": [float(x) for x in dn],
                "irradiance": {"type": "rgb", "value": c},
            }
        elif l.kind == "point" and l.range is None:
            d[f"light_{i}"] = {
                "type": "point",
                "position": [float(x) for x in l.position],
                "intensity": {"type": "rgb", "value": c},
            }
        else:
            d[f"light_{i}"] = GltfPunctual(mi.Properties(), l)
            notes.append(f"light {i} ({l.kind}): Python emitter with glTF cone falloff / range window")
    return mi.load_dict(d), integrator


def render_mitsuba(mi, scene_obj, spp: int, seed: int, pixels: int) -> np.ndarray:
    """Renders in passes of at most ~8M samples; the mean of passes is the same estimator."""
    per_pass = max(1, min(spp, (8 << 20) // max(pixels, 1)))
    acc = None
    done = 0
    k = 0
    while done < spp:
        n = min(per_pass, spp - done)
        img = np.array(mi.render(scene_obj, spp=n, seed=seed * 1000 + k), dtype=np.float64)
        acc = img * n if acc is None else acc + img * n
        done += n
        k += 1
    return (acc / spp).astype(np.float32)


def write_exr(mi, path: Path, img: np.ndarray) -> None:
    mi.Bitmap(np.ascontiguousarray(img[..., :3].astype(np.float32))).write(str(path))


def read_exr(mi, path: Path) -> np.ndarray:
    return np.array(mi.Bitmap(str(path)), dtype=np.float64)[..., :3]


# --------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------


def vec3(s: str) -> np.ndarray:
    parts = [float(x) for x in s.split(",")]
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z, got {s}")
    return np.asarray(parts, np.float64)


def fmt3(v) -> str:
    return ",".join(repr(float(x)) for x in v)


def run(cmd: list[str], nice: int) -> str:
    full = (["nice", "-n", str(nice)] if nice else []) + cmd
    r = subprocess.run(full, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"command failed ({r.returncode}): {' '.join(cmd)}\n{r.stderr[-4000:]}")
    return r.stdout + r.stderr


def flip(probegi: str, ref: Path, test: Path, sheet: Path | None = None) -> float:
    cmd = [probegi, "compare", str(ref), str(test)]
    if sheet is not None:
        cmd += ["--out", str(sheet)]
    out = run(cmd, 0)
    m = re.search(r"mean_flip:\s*([0-9.eE+-]+)", out)
    if not m:
        raise SystemExit(f"no mean_flip in output of {' '.join(cmd)}:\n{out}")
    return float(m.group(1))


def slug(spec: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(spec.replace("builtin:", "builtin-")).stem)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--scene", action="append", required=True, help=".obj, .toml or builtin:NAME (repeatable)")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--variant", default="scalar_rgb", help="Mitsuba variant (llvm_ad_rgb is much faster)")
    ap.add_argument("--probegi", default=str(REPO_ROOT / "target" / "release" / "probegi"))
    ap.add_argument("--out-dir", default="out/mitsuba-check")
    neg = "X,Y,Z (write --flag=X,Y,Z when X is negative)"
    ap.add_argument("--camera-pos", type=vec3, help=neg)
    ap.add_argument("--camera-target", type=vec3, help=neg)
    ap.add_argument("--camera-up", type=vec3, help=neg)
    ap.add_argument("--fov-y", type=float, help="vertical field of view, degrees")
    ap.add_argument("--sky", type=vec3, help="constant sky radiance R,G,B (overrides the scene's)")
    ap.add_argument("--max-depth", type=int, default=64, help="probegi's --max-depth (Mitsuba gets N + 1)")
    ap.add_argument("--frame", type=float, default=0.0, help="light keyframes evaluated at this frame")
    ap.add_argument("--seed", type=int, default=0, help="probegi seed; Mitsuba uses seed+1 and seed+2")
    ap.add_argument(
        "--no-bump", action="store_true", help="ignore MTL bump maps (probegi gets --set normal_maps=false)"
    )
    ap.add_argument(
        "--shading-model",
        choices=["probegi", "mitsuba"],
        default="probegi",
        help="probegi: bump-mapped, glossy and smooth-shaded materials use the Python ProbegiBSDF with\n"
        "probegi's shading-frame and bump rules; mitsuba: Mitsuba's bumpmap (scale = -bm, scene units;\n"
        "NOT equivalent to probegi's texel-space bump rule) and twosided(diffuse) rules",
    )
    ap.add_argument(
        "--no-cutouts", action="store_true", help="every material opaque (probegi gets --set alpha_cutouts=false)"
    )
    ap.add_argument(
        "--cutout-supersample",
        type=int,
        default=8,
        help="alpha cutouts: the thresholded opacity grid is up to this many times finer than the\n"
        "texture (at most 4096 texels a side); the cut edges converge as it grows",
    )
    ap.add_argument("--nice", type=int, default=10, help="nice level for the probegi render (0 = none)")
    ap.add_argument("--skip-probegi", action="store_true", help="only render Mitsuba (orientation checks)")
    args = ap.parse_args()

    if args.nice:
        try:
            os.nice(args.nice)  # the Mitsuba renders run in this process
        except OSError:
            pass
    global CUTOUT_SUPERSAMPLE
    CUTOUT_SUPERSAMPLE = max(1, args.cutout_supersample)
    mi, variant = setup_mitsuba(args.variant)
    ProbegiBSDF, GltfPunctual = define_plugins(mi)
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for spec in args.scene:
        t0 = time.time()
        scene = load_scene(spec, args.frame, bump=not args.no_bump)
        for w in scene.warnings:
            print(f"warning: {w}", file=sys.stderr)
        if args.sky is not None:
            scene.sky = args.sky
        if args.no_cutouts:
            for m in scene.materials:
                m.alpha_tex, m.alpha_factor = None, 1.0
        cam = default_camera(scene)
        cam = Camera(cam.position.copy(), cam.target.copy(), cam.up.copy(), cam.fov_y_deg)
        if args.camera_pos is not None:
            cam.position = args.camera_pos
        if args.camera_target is not None:
            cam.target = args.camera_target
        if args.camera_up is not None:
            cam.up = args.camera_up
        if args.fov_y is not None:
            cam.fov_y_deg = args.fov_y
        notes: list[str] = []
        g = scene.geometry
        print(
            f"[{spec}] {len(g.mat)} triangles ({int((~g.flat).sum())} smooth-shaded), {len(scene.materials)} materials, "
            f"{len(scene.lights)} punctual lights, sky {fmt3(scene.sky)}; camera {fmt3(cam.position)} -> "
            f"{fmt3(cam.target)} up {fmt3(cam.up)} fov_y {cam.fov_y_deg}",
            file=sys.stderr,
        )
        mscene, integrator = build_mitsuba_scene(mi, ProbegiBSDF, GltfPunctual, scene, cam, args, notes)
        t_load = time.time() - t0
        name = slug(spec)
        base = out_dir / f"{name}-{args.width}x{args.height}-{args.spp}spp"
        mit = []
        t_mit = 0.0
        for k in (1, 2):
            t1 = time.time()
            img = render_mitsuba(mi, mscene, args.spp, args.seed + k, args.width * args.height)
            t_mit = time.time() - t1
            p = Path(f"{base}-mitsuba-seed{args.seed + k}.exr")
            write_exr(mi, p, img)
            mit.append(p)
            print(f"[{spec}] Mitsuba ({variant}, {integrator}) seed {args.seed + k}: {t_mit:.1f} s -> {p}", file=sys.stderr)
        row = {"scene": spec, "res": f"{args.width}x{args.height}", "spp": args.spp, "notes": notes}
        row["floor"] = flip(args.probegi, mit[0], mit[1])
        if not args.skip_probegi:
            pg = Path(f"{base}-probegi.exr")
            cmd = [
                args.probegi,
                "reference",
                f"--scene={spec}",
                f"--width={args.width}",
                f"--height={args.height}",
                f"--spp={args.spp}",
                f"--max-depth={args.max_depth}",
                f"--frame={args.frame}",
                f"--seed={args.seed}",
                f"--camera-pos={fmt3(cam.position)}",
                f"--camera-target={fmt3(cam.target)}",
                f"--camera-up={fmt3(cam.up)}",
                f"--fov-y={cam.fov_y_deg!r}",
                f"--out={pg}",
            ]
            if args.sky is not None:
                cmd.append(f"--sky={fmt3(args.sky)}")
            if args.no_bump:
                cmd.append("--set=normal_maps=false")
            if args.no_cutouts:
                cmd.append("--set=alpha_cutouts=false")
            t1 = time.time()
            run(cmd, args.nice)
            t_pg = time.time() - t1
            print(f"[{spec}] probegi reference: {t_pg:.1f} s -> {pg}", file=sys.stderr)
            row["flip"] = flip(args.probegi, mit[0], pg, Path(f"{base}-sheet.png"))
            a, b = read_exr(mi, pg), read_exr(mi, mit[0])
            row["ratio"] = a.reshape(-1, 3).mean(0) / np.maximum(b.reshape(-1, 3).mean(0), 1e-12)
            b2 = read_exr(mi, mit[1])
            row["ratio_floor"] = b2.reshape(-1, 3).mean(0) / np.maximum(b.reshape(-1, 3).mean(0), 1e-12)
        rows.append(row)
        print(f"[{spec}] scene build {t_load:.1f} s", file=sys.stderr)

    lines = [
        f"Mitsuba {mi.__version__} ({variant}) vs probegi reference ({args.probegi})",
        "",
        "| scene | resolution | spp | FLIP probegi vs Mitsuba | FLIP Mitsuba seed A vs B (noise floor) "
        "| mean ratio probegi/Mitsuba (R,G,B) | same for Mitsuba B/A |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = " ".join(f"{x:.3f}" for x in r["ratio"]) if "ratio" in r else "-"
        rf = " ".join(f"{x:.3f}" for x in r["ratio_floor"]) if "ratio_floor" in r else "-"
        fl = f"{r['flip']:.4f}" if "flip" in r else "-"
        lines.append(f"| {r['scene']} | {r['res']} | {r['spp']} | {fl} | {r['floor']:.4f} | {ratio} | {rf} |")
    lines.append("")
    for r in rows:
        for n in r["notes"]:
            lines.append(f"- {r['scene']}: {n}")
    text = "\n".join(lines)
    print(text)
    (out_dir / "results.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
