#!/usr/bin/env python3
"""Independent check of `probegi reference` against Mitsuba 3.

What it checks
--------------
For each `--scene` (a Wavefront `.obj`, a glTF 2.0 `.gltf` or `.glb`, a probegi
`.toml` scene file, whose [[meshes]] may be any of those, or `builtin:NAME` for
the built-in scenes whose source is in this repository) the
script builds the same scene in Mitsuba 3 *by reading the files itself*,
following probegi's documented scene semantics (docs/SCENES.md,
`crates/probegi-scene`), not by asking probegi for its geometry. It renders

  1. Mitsuba's `path` integrator (`volpath` when the scene has alpha cutouts,
     see below) to linear-radiance EXR, twice, with two seeds;
  2. `probegi reference` at the same resolution, camera, sample count, sky and
     maximum path length;

and prints a table with FLIP(Mitsuba seed A vs probegi), computed by
`probegi compare`, next to FLIP(Mitsuba seed A vs Mitsuba seed B), the noise
floor at that sample count. A probegi-vs-Mitsuba FLIP well above the noise floor
means the two renderers disagree about the scene; the per-channel mean ratio
(probegi / Mitsuba) tells an energy difference from a noise difference; it is
given over the whole image and over the pixels that see geometry (a pixel whose
every sample reaches the constant sky is exactly the sky in both Mitsuba
images, and would dilute the ratio). Images, the Mitsuba-vs-probegi contact
sheet and `results.md` go to `--out-dir`.

Run from the repository root, e.g.

    python3 scripts/mitsuba-check.py \
        --scene ../shared/scenes/cornell-box/CornellBox-Original.obj \
        --camera-pos 0,1,3.9 --camera-target 0,1,0 --fov-y 39.3 \
        --width 160 --height 120 --spp 256
    python3 scripts/mitsuba-check.py --scene scenes/sponza-sun.toml --spp 64
    # Khronos samples shipped in the scena 1.5.0 crate's tests:
    #   mkdir -p ~/.cache/probegi && curl -L \
    #     https://static.crates.io/crates/scena/scena-1.5.0.crate | tar xz -C ~/.cache/probegi
    K=~/.cache/probegi/scena-1.5.0/tests/assets/gltf/khronos
    python3 scripts/mitsuba-check.py --variant llvm_ad_rgb --sky 1,1,1 --spp 64 \
        --scene $K/WaterBottle/WaterBottle.gltf --width 96 --height 160
    python3 scripts/mitsuba-check.py --variant llvm_ad_rgb --sky 1,1,1 --spp 64 \
        --scene $K/AlphaBlendModeTest/AlphaBlendModeTest.gltf --width 192 --height 80 \
        --camera-pos 0,1.25,8 --camera-target 0,1.1,0 --fov-y 28

It is a manual check, not part of CI (`scripts/test.sh` does not run it).

Needs
-----
  * Python >= 3.11 (tomllib), `pip install mitsuba numpy` (tested with
    mitsuba 3.9.1, drjit 1.5.0, numpy 2.4). No PIL: textures are read with
    Mitsuba's own `mi.Bitmap`; no glTF package either: .gltf/.glb files are
    read with `json` and numpy (accessors, strides, data URIs, GLB chunks,
    images in buffer views).
  * a built probegi (`--probegi`, default `target/release/probegi`).
  * optional, much faster: the `llvm_ad_rgb` variant (`--variant llvm_ad_rgb`),
    which needs libLLVM: on Debian 12 `apt-get install -y libllvm19`. The
    script sets `DRJIT_LIBLLVM_PATH` to /usr/lib/x86_64-linux-gnu/libLLVM-19.so
    (or another libLLVM it finds) when the variable is unset. The default,
    `scalar_rgb`, needs nothing but is slow, above all with the Python GGX BSDF,
    and falls back to Mitsuba's `area` emitter (see Emission).

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
  * Emission: Ke (× map_Ke; glTF emissiveFactor × emissiveStrength ×
    emissiveTexture, sRGB, through its texture reference) through a Python
    emitter, `ProbegiArea`, on each emissive mesh (flat or smooth-shaded as the
    material is): it emits from the counter-clockwise (front) face only, by the
    geometric normal, as probegi's `Scene::emitted` does, and next-event
    estimation picks points uniformly by area over the mesh's triangles. Not
    Mitsuba's `area` emitter: with vertex normals it emits by the interpolated
    normal's side, and it samples a textured radiance through the UV layout
    (`eval_parameterization`), which never reaches a triangle whose UVs overlap
    another's; on TransmissionTest.glb (two-sided labels sharing UVs) that made
    Mitsuba 1.3 % darker than probegi. The MIS density both strategies use has
    the normal Mitsuba puts in `ds.n` (the shading normal on hits), so the
    weights sum to one; the sample weight divides by the true (geometric)
    density. Scalar variants keep `area` (a note says so).
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
  * Placed files: a [[meshes]] / [[objects]] entry's placement moves the file's
    geometry and also its punctual lights and camera (`PLACE_SUB_SCENE_LIGHTS`;
    probegi moves only the geometry, see "Known mismatches").
  * glTF 2.0 (`load_gltf`, following `gltf_file.rs`): the default scene's nodes
    (else the first scene's; a file without scenes: the nodes nobody has as a
    child) walked with their `matrix` or TRS; triangle primitives, mode 4 as
    given, 5 (strips) and 6 (fans) as triangle lists with the section's
    windings (p_i = v_i, v_(i+1+i%2), v_(i+2−i%2); fans v_(i+1), v_(i+2), v_0),
    a strip's or fan's triangles that repeat a vertex dropped; other modes
    skipped with a warning. `POSITION`; `NORMAL` normalised (missing, zero or
    non-finite → the face normal at those corners; a triangle with none →
    Mitsuba mesh without vertex normals); `TANGENT` only with `NORMAL`;
    `TEXCOORD_0`/`_1` and `COLOR_0` (float or normalized u8/u16; COLOR_0's RGB
    clamped to [0, 1], its alpha unused); sparse accessors, animations and
    `extensionsRequired` beyond KHR_lights_punctual,
    KHR_materials_emissive_strength and KHR_texture_transform are refused,
    other `extensionsUsed` warned about (probegi ignores them too). First
    perspective camera in visiting order (eye = node origin, view −Z, up +Y,
    `yfov`), KHR_lights_punctual lights (point, spot, directional; node −Z).
  * glTF metallic-roughness materials: the Python `ProbegiBSDF` evaluates
    `Material::bsdf` per point, i.e. `probegi_core::bsdf::SurfaceBsdf` with
    base = baseColorFactor × COLOR_0 × baseColorTexture (sRGB decoded per texel,
    then filtered), r = roughnessFactor × G and m = metallicFactor × B of
    metallicRoughnessTexture (raw unorm), α = clamp(r², 1e-3, 1), diffuse =
    base (1 − m), F0 = lerp(0.04, base, m); so f = base (1 − m)(1 − max F0)/π
    + GGX D · height-correlated G2 · Schlick F / (4 cos cos), no specular lobe
    where max F0 = 0, probegi's lobe-selection mixture. A primitive without a
    material gets glTF's default (white, metallic 1, roughness 1). Textures are
    float bitmaps (`raw`) with the sampler's filter (magFilter, else
    minFilter's no-mipmap fallback, else bilinear; no mipmaps: probegi
    magnifies every lookup) and wrap mode (repeat, mirrored repeat, clamp to
    edge on the integer texel index: Mitsuba's `wrap_mode` rules; mixed wrapS /
    wrapT: the image padded by one texel per side and the coordinate folded per
    axis, which is exact). Each texture reference reads its `texCoord` set
    (TEXCOORD_1 through a mesh attribute; a set above 1 ignores the texture,
    as probegi) through its KHR_texture_transform (u' = sx cos r u + sy sin r v
    + ox, v' = −sx sin r u + sy cos r v + oy, `UvMapping::texture_transform`).
    Mitsuba's own `principled` BSDF (`--shading-model mitsuba`, wrapped in
    `twosided`, with `normalmap`) is kept only for contrast: it does not scale
    the diffuse lobe by 1 − max F0, its diffuse is Disney's, its Fresnel and
    specular differ, and it reads set 0 with Mitsuba's tangent frame. On
    WaterBottle and AlphaBlendModeTest it is 2–2.5× the noise floor in FLIP
    and 1.7 % brighter on the latter; ProbegiBSDF is at the floor.
  * glTF normal maps (`Scene::perturbed_normal`): the shading normal n (flipped
    into the geometric hemisphere), the interpolated tangent made orthogonal
    to n (unchanged where it vanishes), bitangent = sign(w of the triangle's
    first corner) · n × tangent, texel × 2 − 1 with X, Y × `scale`; dropped
    unless 1e-3 above the geometric plane. Without TANGENT (probegi:
    MikkTSpace over the normal map's coordinates) this checker accumulates
    ∂p/∂u per vertex (`approximate_tangents`, see Known mismatches).
  * glTF alpha: OPAQUE ignores alpha; MASK cuts at `alphaCutoff` (0.5 when
    absent), BLEND is MASK at 0.5; coverage = baseColorFactor.a × the alpha of
    the base colour texture when that image has an alpha channel with a texel
    below 255, read with TEXCOORD_0, repeat, bilinear and no transform whatever
    the base colour's sampler and transform (what probegi's traversal test
    reads; probegi warns where they differ). Mitsuba: `mask` with the
    thresholded grid, as for OBJ cutouts below.
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
  * glTF files without `scenes`: probegi's loader visits every node as a root
    (`doc.nodes().collect()` in gltf_file.rs), so a child node's mesh is drawn
    twice, once under its parents and once untransformed; this checker draws
    the hierarchy once, so such files differ (a probegi bug, reported).
  * Placed files' lights and camera: probegi's scene_file.rs transforms only a
    [[meshes]] / [[objects]] file's geometry; this checker also places its
    KHR_lights_punctual lights and camera (set `PLACE_SUB_SCENE_LIGHTS = False`
    to reproduce probegi).
  * Normal-mapped glTF primitives without TANGENT: `approximate_tangents`
    (angle-weighted ∂p/∂u per vertex index, orthogonalised, handedness from
    ∂p/∂v) instead of MikkTSpace. On WaterBottle with TANGENT removed, under a
    sun, it is at the noise floor; on meshes with UV seams or mirrored islands
    at shared vertices it may differ.
  * glTF cutout edges: as for OBJ, the thresholded grid is an approximation
    along the cut; where the coverage jumps within a texel (an alpha ramp
    wrapping from 255 to 0) raise `--cutout-supersample` (a synthetic GLB:
    1.10× the floor at 8, at the floor at 128).
  * Not read by either renderer: occlusionTexture, doubleSided (all surfaces
    are two-sided), KHR_materials_* other than emissive_strength, skins and
    morph targets (the stored rest pose), orthographic cameras; 16-bit images
    are ignored by both (a warning).
  * Animated `[[objects]]` are refused; the static scene is rendered at
    `--frame` for lights only.
  * Alpha cut edges: nearest lookup of a finer thresholded grid (above).
  * An emissive material with a cutout still emits in Mitsuba where it is cut
    (probegi: no).
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
    # glTF sampler (texture.rs `Sampler`): wrap along u, along v ("repeat", "mirror",
    # "clamp") and filter ("bilinear", "nearest"). OBJ textures: repeat, bilinear.
    wrap_u: str = "repeat"
    wrap_v: str = "repeat"
    filter: str = "bilinear"

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
    # glTF metallic-roughness (material.rs SpecularModel::MetallicRoughness): kd = base colour
    # factor, kd_tex = baseColorTexture, `roughness` and `metallic` the factors, mr_tex's G and B
    # multiply them; F0 = lerp(0.04, base, metallic), diffuse = base · (1 − metallic).
    gltf: bool = False
    metallic: float = 0.0
    mr_tex: Texture | None = None
    normal_tex: Texture | None = None
    normal_scale: float = 1.0
    alpha_cutoff: float = ALPHA_CUTOFF
    # Per texture reference: (TEXCOORD set, 2×3 KHR_texture_transform rows or None).
    kd_uv: tuple = (0, None)
    mr_uv: tuple = (0, None)
    normal_uv: tuple = (0, None)
    ke_uv: tuple = (0, None)
    vertex_color: bool = False  # COLOR_0 multiplies the base colour (set per primitive)

    def has_specular(self) -> bool:
        return self.gltf or (self.mtl and float(self.ks.max()) > 0.0)

    def is_emissive(self) -> bool:
        return float(self.ke.max()) > 0.0

    def has_cutout(self) -> bool:
        return self.alpha_tex is not None or self.alpha_factor < self.alpha_cutoff


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
    UV (F,3,2), mat (F,) material index, flat (F,) bool. glTF only (None elsewhere):
    T (F,3,3) tangents (zero = none), TS (F,) the bitangent sign of corner 0 (probegi
    reads the sign of the triangle's first corner), UV1 (F,3,2) TEXCOORD_1 (set 0 where
    absent), COL (F,3,3) linear COLOR_0 (white where absent)."""

    P: np.ndarray
    N: np.ndarray
    UV: np.ndarray
    mat: np.ndarray
    flat: np.ndarray
    T: np.ndarray | None = None
    TS: np.ndarray | None = None
    UV1: np.ndarray | None = None
    COL: np.ndarray | None = None

    EXTRA = ("T", "TS", "UV1", "COL")

    @staticmethod
    def empty() -> "Geometry":
        return Geometry(
            np.zeros((0, 3, 3), np.float64),
            np.zeros((0, 3, 3), np.float64),
            np.zeros((0, 3, 2), np.float64),
            np.zeros(0, np.int64),
            np.zeros(0, bool),
        )

    def extra(self, name: str) -> np.ndarray:
        """An optional attribute, or its default where this geometry has none."""
        v = getattr(self, name)
        if v is not None:
            return v
        f = self.P.shape[0]
        return {
            "T": lambda: np.zeros((f, 3, 3)),
            "TS": lambda: np.ones(f),
            "UV1": lambda: self.UV.copy(),
            "COL": lambda: np.ones((f, 3, 3)),
        }[name]()

    def copy(self) -> "Geometry":
        return Geometry(*[None if getattr(self, a) is None else getattr(self, a).copy() for a in self.FIELDS])

    def select(self, sel: np.ndarray) -> "Geometry":
        return Geometry(*[None if getattr(self, a) is None else getattr(self, a)[sel] for a in self.FIELDS])

    def transform(self, m: np.ndarray) -> None:
        a, t = m[:3, :3], m[:3, 3]
        self.P = self.P @ a.T + t
        nm = np.linalg.inv(a).T
        n = self.N @ nm.T
        ln = np.linalg.norm(n, axis=-1, keepdims=True)
        self.N = np.where(ln > 0, n / np.where(ln > 0, ln, 1), 0.0)
        mirror = np.linalg.det(a) < 0
        if self.T is not None:  # mesh.rs transformed_tangent: the linear part, normalised
            tv = self.T @ a.T
            lt = np.linalg.norm(tv, axis=-1, keepdims=True)
            self.T = np.where(lt > 0, tv / np.where(lt > 0, lt, 1), 0.0)
            if mirror:
                self.TS = -self.TS
        if mirror:  # mirroring: keep front faces front
            for arr in (self.P, self.N, self.UV, self.T, self.UV1, self.COL):
                if arr is not None:
                    arr[:, [1, 2]] = arr[:, [2, 1]]


Geometry.FIELDS = ("P", "N", "UV", "mat", "flat", *Geometry.EXTRA)


def cat_geometry(gs: list[Geometry]) -> Geometry:
    """Concatenates geometries; an optional attribute present in one is filled with its
    default in the others."""
    out = [np.concatenate([getattr(g, a) for g in gs]) for a in ("P", "N", "UV", "mat", "flat")]
    for a in Geometry.EXTRA:
        out.append(np.concatenate([g.extra(a) for g in gs]) if any(getattr(g, a) is not None for g in gs) else None)
    return Geometry(*out)


@dataclass
class Scene:
    geometry: Geometry
    materials: list[Material]
    lights: list[Light]
    sky: np.ndarray
    camera: Camera | None
    warnings: list[str]
    # An environment map instead of `sky` (probegi's [sky_map]): path, intensity, rotation_deg.
    sky_map: dict | None = None


def merge(dst: Scene, src: Scene) -> None:
    off = len(dst.materials)
    s = src.geometry.copy()
    s.mat = s.mat + off
    dst.geometry = cat_geometry([dst.geometry, s])
    dst.materials += src.materials
    dst.lights += src.lights
    dst.sky = np.maximum(dst.sky, src.sky)
    if dst.sky_map is None:
        dst.sky_map = src.sky_map
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


def load_texture(path: Path, source: str | None = None) -> Texture:
    """An 8-bit image as probegi keeps it. `source` set (a glTF image, possibly a temporary
    file): not cached, and a 16-bit image is refused (probegi's glTF loader ignores them)."""
    import mitsuba as mi

    key = path.resolve()
    if source is None and key in _TEXTURES:
        return _TEXTURES[key]
    bmp = mi.Bitmap(str(path))
    arr = np.array(bmp)
    if arr.ndim == 2:
        arr = arr[..., None]
    if source is not None and arr.dtype != np.uint8:
        raise _Unsupported16Bit()
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
    tex = Texture(source or str(path), np.ascontiguousarray(rgb), None if alpha is None else np.ascontiguousarray(alpha))
    if source is None:
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


def resolve_path(spec: str, base: Path) -> Path:
    """A file named in a scene file: `shared:PATH` or relative to the file (scene_file.rs)."""
    return shared_dir() / spec[len("shared:") :] if spec.startswith("shared:") else base / spec


def load_sub(spec: str, base: Path, opts: dict, frame: float, bump: bool) -> Scene:
    if spec.startswith("builtin:"):
        sub = load_scene(spec, frame, bump)
    else:
        path = resolve_path(spec, base)
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


# probegi's scene_file.rs moves only the geometry of a placed file (`sub.mesh.transform(xf)`):
# a glTF's KHR_lights_punctual lights and camera stay where the file put them. This checker
# places them with the geometry (the file's lights belong to it); False reproduces probegi.
PLACE_SUB_SCENE_LIGHTS = True


def place_sub_scene(sub: Scene, xf: np.ndarray) -> None:
    """A [[meshes]] / [[objects]] placement: the geometry, and (PLACE_SUB_SCENE_LIGHTS) the
    file's punctual lights and camera."""
    sub.geometry.transform(xf)
    if not PLACE_SUB_SCENE_LIGHTS:
        return
    a, t = xf[:3, :3], xf[:3, 3]

    def unit(v):
        n = np.linalg.norm(v)
        return v / n if n > 0 else v

    for l in sub.lights:
        l.position = a @ l.position + t
        l.direction = unit(a @ l.direction)
    if sub.camera is not None:
        c = sub.camera
        sub.camera = Camera(a @ c.position + t, a @ c.target + t, unit(a @ c.up), c.fov_y_deg)


def load_toml(path: Path, text: str, base: Path, frame: float, bump: bool) -> Scene:
    f = tomllib.loads(text)
    scene = empty_scene()
    for i, m in enumerate(f.get("meshes", [])):
        sub = load_sub(m["path"], base, m, frame, bump)
        place_sub_scene(
            sub,
            placement_matrix(m.get("translation", [0, 0, 0]), m.get("rotation_deg", [0, 0, 0]), m.get("scale", [1, 1, 1])),
        )
        merge(scene, sub)
    for i, e in enumerate(f.get("instances", [])):
        sub = load_sub(e["path"], base, e, frame, bump)
        sub.lights = []  # probegi does not copy an instanced file's lights
        copies = []
        for xf in instance_placements(e):
            g = sub.geometry.copy()
            g.transform(xf)
            copies.append(g)
        sub.geometry = cat_geometry(copies)
        merge(scene, sub)
    for i, o in enumerate(f.get("objects", [])):
        if o.get("keyframes") or o.get("motion"):
            raise SystemExit(f"{path}: objects[{i}] is animated; this checker renders static objects only")
        if "path" in o:
            sub = load_sub(o["path"], base, o, frame, bump)
            place_sub_scene(
                sub,
                placement_matrix(
                    o.get("translation", [0, 0, 0]), o.get("rotation_deg", [0, 0, 0]), o.get("scale", [1, 1, 1])
                ),
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
                g = cat_geometry(gs)
                if o.get("box_inward"):
                    g.P[:, [1, 2]] = g.P[:, [2, 1]]
                sub.geometry = g
        merge(scene, sub)
    scene.lights += [parse_light(l, frame) for l in f.get("lights", [])]
    if "sky_radiance" in f:
        scene.sky = np.asarray(f["sky_radiance"], np.float64)
    if "sky_map" in f:
        m = f["sky_map"]
        scene.sky_map = {
            "path": str(resolve_path(m["path"], base)),
            "intensity": float(m.get("intensity", 1.0)),
            "rotation_deg": float(m.get("rotation_deg", 0.0)),
        }
    if "camera" in f:
        scene.camera = parse_camera(f["camera"])
    return scene


# --------------------------------------------------------------------------------------
# glTF 2.0 (.gltf / .glb), read with json + numpy (gltf_file.rs's rules)
# --------------------------------------------------------------------------------------

GLTF_FOLLOWED_EXTENSIONS = ("KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_texture_transform")
_GLTF_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_GLTF_TYPE_SIZE = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLTF_WRAP = {10497: "repeat", 33648: "mirror", 33071: "clamp"}


def _data_uri(uri: str) -> bytes | None:
    import base64
    import urllib.parse

    if not uri.startswith("data:"):
        return None
    head, _, data = uri.partition(",")
    return base64.b64decode(data) if head.endswith(";base64") else urllib.parse.unquote_to_bytes(data)


def quat_matrix(q) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def gltf_node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T  # column-major
    m = np.eye(4)
    m[:3, :3] = quat_matrix(node.get("rotation", [0, 0, 0, 1])) @ np.diag(node.get("scale", [1, 1, 1]))
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


def triangles_of(mode: int, v: np.ndarray) -> np.ndarray:
    """gltf_file.rs triangles_of: lists as given, strips p_i = {v_i, v_(i+1+i%2), v_(i+2−i%2)},
    fans p_i = {v_(i+1), v_(i+2), v_0}; strips' and fans' triangles that repeat a vertex dropped."""
    if mode == 4:
        if len(v) % 3:
            raise SystemExit(f"index count {len(v)} is not a multiple of 3")
        return v.reshape(-1, 3)
    i = np.arange(max(len(v) - 2, 0))
    if mode == 5:
        t = np.stack([v[i], v[i + 1 + i % 2], v[i + 2 - i % 2]], axis=1)
    else:
        t = np.stack([v[i + 1], v[i + 2], np.full_like(i, v[0]) if len(v) else v[i]], axis=1)
    keep = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
    return t[keep]


def approximate_tangents(P: np.ndarray, N: np.ndarray, UV: np.ndarray, tri: np.ndarray, nv: int):
    """Per-vertex tangents for a normal-mapped primitive without TANGENT. probegi runs
    MikkTSpace (the `mikktspace` crate); this is Lengyel's accumulation of ∂p/∂u over the
    faces sharing a vertex index (angle-weighted), orthogonalised against the vertex normal,
    w = handedness: the same frame as MikkTSpace on smooth, unmirrored UV layouts, not
    bit-equal (MikkTSpace also splits vertices and joins by position)."""
    p, uv = P[tri], UV[tri]
    duv1, duv2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    dp1, dp2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = duv1[:, 0] * duv2[:, 1] - duv1[:, 1] * duv2[:, 0]
    ok = np.abs(det) > 1e-20
    r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    su = (dp1 * duv2[:, 1:2] - dp2 * duv1[:, 1:2]) * r
    sv = (dp2 * duv1[:, 0:1] - dp1 * duv2[:, 0:1]) * r
    ang = corner_angles(p)
    t_acc = np.zeros((nv, 3))
    b_acc = np.zeros((nv, 3))
    for k in range(3):
        np.add.at(t_acc, tri[:, k], su * ang[:, k : k + 1])
        np.add.at(b_acc, tri[:, k], sv * ang[:, k : k + 1])
    t = t_acc - N * (N * t_acc).sum(1, keepdims=True)
    lt = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.where(lt > 1e-20, t / np.where(lt > 1e-20, lt, 1), 0.0)
    w = np.where((np.cross(N, t) * b_acc).sum(1) < 0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1)


class GltfFile:
    def __init__(self, path: Path, warnings: list[str]):
        self.path = path
        self.base = path.parent
        self.warnings = warnings
        data = path.read_bytes()
        self.blob = None
        if data[:4] == b"glTF":
            import struct

            _, _, length = struct.unpack_from("<III", data, 0)
            off, js = 12, None
            while off + 8 <= min(length, len(data)):
                clen, ctype = struct.unpack_from("<II", data, off)
                chunk = data[off + 8 : off + 8 + clen]
                if ctype == 0x4E4F534A:
                    js = chunk
                elif ctype == 0x004E4942 and self.blob is None:
                    self.blob = chunk
                off += 8 + clen
            if js is None:
                raise SystemExit(f"{path}: GLB without a JSON chunk")
            data = js
        import json

        self.doc = json.loads(data.decode("utf-8"))
        for e in self.doc.get("extensionsRequired", []):
            if e not in GLTF_FOLLOWED_EXTENSIONS:
                raise SystemExit(f"{path}: the file requires extension {e}, which probegi does not implement")
        for e in self.doc.get("extensionsUsed", []):
            if e not in GLTF_FOLLOWED_EXTENSIONS:
                warnings.append(f"{path}: extension {e} is used but not followed (probegi ignores it too)")
        self.buffers: list[bytes] = []
        import urllib.parse

        for i, b in enumerate(self.doc.get("buffers", [])):
            uri = b.get("uri")
            if uri is None:
                if self.blob is None:
                    raise SystemExit(f"{path}: buffer {i} has no uri and the file no BIN chunk")
                self.buffers.append(self.blob)
            else:
                raw = _data_uri(uri)
                if raw is None:
                    f = self.base / urllib.parse.unquote(uri)
                    if not f.exists():
                        raise SystemExit(f"{path}: buffer {i}: file {f} not found")
                    raw = f.read_bytes()
                self.buffers.append(raw)
        self.textures: dict = {}

    def view_bytes(self, view_index: int) -> tuple[bytes, int, int | None]:
        v = self.doc["bufferViews"][view_index]
        buf = self.buffers[v["buffer"]]
        off = v.get("byteOffset", 0)
        return buf[off : off + v["byteLength"]], v.get("byteStride"), v.get("buffer")

    def accessor(self, index: int, normalize_ints: bool = False) -> np.ndarray:
        a = self.doc["accessors"][index]
        if "sparse" in a:
            raise SystemExit(f"{self.path}: accessor {index}: sparse accessors are not supported (probegi refuses them)")
        dt = np.dtype(_GLTF_COMPONENT[a["componentType"]])
        ncomp = _GLTF_TYPE_SIZE[a["type"]]
        count = a["count"]
        raw, stride, _ = self.view_bytes(a["bufferView"])
        elem = dt.itemsize * ncomp
        stride = stride or elem
        off = a.get("byteOffset", 0)
        if count == 0:
            out = np.zeros((0, ncomp), dt)
        else:
            buf = np.frombuffer(raw, np.uint8, count=stride * (count - 1) + elem, offset=off)
            rows = np.lib.stride_tricks.as_strided(buf, shape=(count, elem), strides=(stride, 1))
            out = np.ascontiguousarray(rows).view(dt).reshape(count, ncomp)
        if normalize_ints and dt.kind in "ui":
            if dt.kind == "u":
                return out.astype(np.float64) / float(np.iinfo(dt).max)
            return np.maximum(out.astype(np.float64) / float(np.iinfo(dt).max), -1.0)
        return out.astype(np.float64) if dt.kind == "f" else out

    def texture(self, index: int) -> Texture | None:
        """A glTF texture: its image (8-bit PNG/JPEG, as probegi reads them) with its sampler."""
        if index in self.textures:
            return self.textures[index]
        tex = None
        t = self.doc["textures"][index]
        src = t.get("source")
        img = self.doc.get("images", [])[src] if src is not None else None
        if img is not None:
            import tempfile
            import urllib.parse

            try:
                if "uri" in img and _data_uri(img["uri"]) is None:
                    f = self.base / urllib.parse.unquote(img["uri"])
                    base = load_texture(f) if f.exists() else None
                    if base is None:
                        self.warnings.append(f"{self.path}: image {src} `{f}` not found; textures using it are ignored")
                else:
                    raw = _data_uri(img["uri"]) if "uri" in img else self.view_bytes(img["bufferView"])[0]
                    suffix = ".jpg" if raw[:3] == b"\xff\xd8\xff" else ".png"
                    with tempfile.NamedTemporaryFile(suffix=suffix, delete=False) as fh:
                        fh.write(raw)
                    try:
                        base = load_texture(Path(fh.name), f"{self.path} image {src}")
                    finally:
                        os.unlink(fh.name)
            except _Unsupported16Bit:
                self.warnings.append(f"{self.path}: image {src} is 16-bit; ignored as probegi ignores it")
                base = None
            if base is not None:
                s = self.doc.get("samplers", [])[t["sampler"]] if "sampler" in t else {}
                mag, minf = s.get("magFilter"), s.get("minFilter")
                nearest = mag == 9728 or (mag is None and minf in (9728, 9984, 9986))
                tex = dataclasses.replace(
                    base,
                    wrap_u=_GLTF_WRAP.get(s.get("wrapS", 10497), "repeat"),
                    wrap_v=_GLTF_WRAP.get(s.get("wrapT", 10497), "repeat"),
                    filter="nearest" if nearest else "bilinear",
                )
        self.textures[index] = tex
        return tex

    def texture_ref(self, info: dict | None, material: str):
        """(texture, (set, rows)) of a textureInfo, KHR_texture_transform applied."""
        if info is None:
            return None, (0, None)
        xf = info.get("extensions", {}).get("KHR_texture_transform")
        uv_set = int(info.get("texCoord", 0))
        rows = None
        if xf is not None:
            uv_set = int(xf.get("texCoord", uv_set))
            ox, oy = xf.get("offset", [0.0, 0.0])
            r = float(xf.get("rotation", 0.0))
            sx, sy = xf.get("scale", [1.0, 1.0])
            c, s = math.cos(r), math.sin(r)
            rows = np.array([[sx * c, sy * s, ox], [-sx * s, sy * c, oy]], np.float64)
            if np.array_equal(rows, np.array([[1.0, 0, 0], [0, 1.0, 0]])):
                rows = None
        if uv_set > 1:
            self.warnings.append(f"{self.path}: material `{material}`: TEXCOORD_{uv_set}; texture ignored (as probegi)")
            return None, (0, None)
        return self.texture(info["index"]), (uv_set, rows)

    def material(self, index: int | None, bump: bool) -> Material:
        m = self.doc["materials"][index] if index is not None else {}
        name = m.get("name", "gltf-default")
        pbr = m.get("pbrMetallicRoughness", {})

        def unit(v, what):
            v = float(v)
            if 0.0 <= v <= 1.0:
                return v
            c = 0.0 if math.isnan(v) else min(max(v, 0.0), 1.0)
            self.warnings.append(f"{self.path}: material `{name}`: {what} {v} clamped to {c}")
            return c

        bc = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
        kd_tex, kd_uv = self.texture_ref(pbr.get("baseColorTexture"), name)
        mr_tex, mr_uv = self.texture_ref(pbr.get("metallicRoughnessTexture"), name)
        ke_tex, ke_uv = self.texture_ref(m.get("emissiveTexture"), name)
        normal_tex, normal_uv = self.texture_ref(m.get("normalTexture"), name) if bump else (None, (0, None))
        strength = float(m.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0))
        mode = m.get("alphaMode", "OPAQUE")
        cutoff = float(m.get("alphaCutoff", ALPHA_CUTOFF)) if mode == "MASK" else ALPHA_CUTOFF
        mat = Material(
            name=name,
            kd=np.asarray(bc[:3], np.float32),
            kd_tex=kd_tex,
            ke=np.asarray(m.get("emissiveFactor", [0.0, 0.0, 0.0]), np.float32) * np.float32(strength),
            ke_tex=ke_tex,
            roughness=unit(pbr.get("roughnessFactor", 1.0), "roughnessFactor"),
            metallic=unit(pbr.get("metallicFactor", 1.0), "metallicFactor"),
            mr_tex=mr_tex,
            normal_tex=normal_tex,
            normal_scale=float(m.get("normalTexture", {}).get("scale", 1.0)),
            gltf=True,
            alpha_cutoff=cutoff,
            kd_uv=kd_uv,
            mr_uv=mr_uv,
            normal_uv=normal_uv,
            ke_uv=ke_uv,
        )
        if mode in ("MASK", "BLEND"):
            # BLEND is MASK at 0.5; coverage = baseColorFactor.a × the base colour texture's alpha
            # (TEXCOORD_0, repeat, bilinear: what probegi's traversal test reads).
            mat.alpha_factor = unit(bc[3], "baseColorFactor alpha")
            mat.alpha_tex = kd_tex if kd_tex is not None and kd_tex.alpha8 is not None else None
        return mat


class _Unsupported16Bit(Exception):
    pass


def load_gltf(path: Path, bump: bool = True) -> Scene:
    """gltf_file.rs: the default scene's nodes (else the first scene's, else the root nodes) with
    their transforms, triangle primitives (modes 4, 5, 6), metallic-roughness materials,
    the first perspective camera, KHR_lights_punctual."""
    warnings: list[str] = []
    f = GltfFile(path, warnings)
    doc = f.doc
    if doc.get("animations"):
        raise SystemExit(f"{path}: the file has animations; this checker renders static glTF scenes only")
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes", [])
    if scenes:
        roots = scenes[doc.get("scene", 0)]["nodes"] if "scene" in doc else scenes[0]["nodes"]
    else:
        # No scenes: every node that is nobody's child (the hierarchy's roots). probegi's
        # gltf_file.rs visits *every* node as a root (`doc.nodes().collect()`), which draws
        # each child node a second time, untransformed by its parents (reported).
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    materials: list[Material] = []
    mat_ids: dict = {}
    parts: list[Geometry] = []
    lights: list[Light] = []
    camera: Camera | None = None
    light_defs = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])

    def material_id(index, vertex_color: bool) -> int:
        key = (index, vertex_color)
        if key not in mat_ids:
            m = f.material(index, bump)
            m.vertex_color = vertex_color
            materials.append(m)
            mat_ids[key] = len(materials) - 1
        return mat_ids[key]

    def add_primitive(mesh: dict, k: int, prim: dict, world: np.ndarray) -> None:
        nonlocal parts
        what = f"{path}: mesh {mesh.get('name', '')} primitive {k}"
        mode = prim.get("mode", 4)
        if mode not in (4, 5, 6):
            warnings.append(f"{what}: mode {mode} skipped (points and lines)")
            return
        at = prim["attributes"]
        pos = f.accessor(at["POSITION"])
        nv = len(pos)
        nrm = f.accessor(at["NORMAL"]) if "NORMAL" in at else None
        uv0 = f.accessor(at["TEXCOORD_0"], True) if "TEXCOORD_0" in at else np.zeros((nv, 2))
        uv1 = f.accessor(at["TEXCOORD_1"], True) if "TEXCOORD_1" in at else None
        col = f.accessor(at["COLOR_0"], True)[:, :3] if "COLOR_0" in at else None
        if col is not None:
            col = np.clip(np.nan_to_num(col, nan=0.0), 0.0, 1.0)
        tan = f.accessor(at["TANGENT"]) if ("TANGENT" in at and nrm is not None) else None
        idx = f.accessor(prim["indices"]).reshape(-1).astype(np.int64) if "indices" in prim else np.arange(nv)
        if (idx >= nv).any():
            raise SystemExit(f"{what}: index out of range")
        tri = triangles_of(mode, idx)
        if len(tri) == 0:
            return
        mid = material_id(prim.get("material"), col is not None)
        m = materials[mid]
        # Normals: as given; invalid ones (zero, non-finite) and a missing NORMAL → face normals.
        Nv = nrm if nrm is not None else np.zeros((nv, 3))
        good = np.isfinite(Nv).all(1) & (np.linalg.norm(np.nan_to_num(Nv), axis=1) > 0)
        Nv = np.where(good[:, None], np.nan_to_num(Nv), 0.0)
        ln = np.linalg.norm(Nv, axis=1, keepdims=True)
        Nv = np.where(ln > 0, Nv / np.where(ln > 0, ln, 1), 0.0)
        if m.normal_tex is not None and (tan is None or not np.any(tan)):
            # Over the coordinates the normal map reads (glTF 2.0 §3.7.2.1): its set and transform.
            uvt = uv1 if (m.normal_uv[0] == 1 and uv1 is not None) else uv0
            if m.normal_uv[1] is not None:
                rows = m.normal_uv[1]
                uvt = uvt @ rows[:, :2].T + rows[:, 2]
            tan = approximate_tangents(pos, Nv, uvt, tri, nv)
            warnings.append(f"{what}: no TANGENT; approximate tangents (probegi: MikkTSpace)")
        if tan is not None:
            tan = np.where(np.isfinite(tan).all(1, keepdims=True), tan, 0.0)
        P = pos[tri]
        N = Nv[tri]
        derive = ~good[tri]
        N = derive_normals(P, N, derive, np.zeros(len(tri), np.int64), 180.0)
        flat = derive.all(axis=1)
        N[flat] = 0.0
        g = Geometry(P, N, uv0[tri], np.full(len(tri), mid), flat)
        if tan is not None:
            g.T = tan[tri][..., :3]
            g.TS = np.where(tan[tri[:, 0], 3] < 0, -1.0, 1.0)
        if uv1 is not None:
            g.UV1 = uv1[tri]
        if col is not None:
            g.COL = col[tri]
        g.transform(world)
        parts.append(g)

    def visit(i: int, parent: np.ndarray, stack: list[int]) -> None:
        nonlocal camera
        if i in stack:
            raise SystemExit(f"{path}: node {i} is its own ancestor")
        node = nodes[i]
        world = parent @ gltf_node_matrix(node)
        if "mesh" in node:
            mesh = doc["meshes"][node["mesh"]]
            for k, prim in enumerate(mesh["primitives"]):
                add_primitive(mesh, k, prim, world)
        lref = node.get("extensions", {}).get("KHR_lights_punctual")
        if lref is not None:
            ld = light_defs[lref["light"]]
            dn = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
            ln = np.linalg.norm(dn)
            spot = ld.get("spot", {})
            lights.append(
                Light(
                    kind=ld["type"],
                    position=world[:3, 3].copy(),
                    direction=dn / ln if ln > 0 else dn,
                    color=np.asarray(ld.get("color", [1.0, 1.0, 1.0]), np.float64),
                    intensity=float(ld.get("intensity", 1.0)),
                    range=ld.get("range"),
                    inner=float(spot.get("innerConeAngle", 0.0)),
                    outer=float(spot.get("outerConeAngle", math.pi / 4)),
                )
            )
        if "camera" in node and camera is None:
            c = doc["cameras"][node["camera"]]
            if c.get("type") == "perspective":
                pos = world[:3, 3].copy()
                fwd = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
                up = world[:3, :3] @ np.array([0.0, 1.0, 0.0])
                fwd /= max(np.linalg.norm(fwd), 1e-30)
                up /= max(np.linalg.norm(up), 1e-30)
                camera = Camera(pos, pos + fwd, up, math.degrees(float(c["perspective"]["yfov"])))
        for ch in node.get("children", []):
            visit(ch, world, stack + [i])

    for r in roots:
        visit(r, np.eye(4), [])
    if not parts:
        raise SystemExit(f"{path}: no triangle primitives")
    return Scene(cat_geometry(parts), materials, lights, np.zeros(3), camera, warnings)


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
            g = cat_geometry(gs)
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
        return load_gltf(path, bump=bump)
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


PLUGINS: dict = {}  # define_plugins: "area" = ProbegiArea (the emitter of emissive meshes)


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

    def normalize_or_zero(v):
        ln = dr.norm(v)
        ok = (ln > 0) & dr.isfinite(ln)
        return dr.select(ok, v / dr.select(ok, ln, 1.0), 0.0), ok

    def mapped_uv(ref, uv0, uv1):
        tex, (uv_set, rows), fold = ref
        uv = uv1 if uv_set == 1 else uv0
        if rows is not None:
            r = [[float(x) for x in row] for row in rows]
            uv = mi.Point2f(r[0][0] * uv.x + r[0][1] * uv.y + r[0][2], r[1][0] * uv.x + r[1][1] * uv.y + r[1][2])
        if fold is not None:
            uv = fold(uv)
        return uv

    def lookup(ref, si, active):
        """A texture reference (texture, (set, rows), fold) evaluated at the interaction:
        TEXCOORD_0 (`si.uv`) or TEXCOORD_1 (mesh attribute `vertex_uv1`), through the
        KHR_texture_transform rows, folded per axis for mixed wrap modes (`gltf_tex_ref`)."""
        tex, (uv_set, rows), fold = ref
        if uv_set == 0 and rows is None and fold is None:
            return tex.eval(si, active)
        uv1 = None
        if uv_set == 1:
            a = si.shape.eval_attribute_3("vertex_uv1", si, active)
            uv1 = mi.Point2f(a[0], a[1])
        si2 = mi.SurfaceInteraction3f(si)
        si2.uv = mapped_uv(ref, mi.Point2f(si.uv), uv1)
        return tex.eval(si2, active)

    def lookup_uv(ref, uv0, uv1, active):
        """The same at explicit coordinates (emitter samples, which have no interaction)."""
        si2 = dr.zeros(mi.SurfaceInteraction3f)
        si2.uv = mapped_uv(ref, uv0, uv1)
        return ref[0].eval(si2, active)

    class ProbegiBSDF(mi.BSDF):
        """probegi's surface model at a Mitsuba interaction: `probegi_core::bsdf::SurfaceBsdf`
        (diffuse × (1 − max F0)/π + GGX, Schlick F, height-correlated Smith) in the frame of
        `probegi_cpu::shading::ShadingContext`: the shading normal flipped into the geometric
        hemisphere, optionally bump- or normal-map-perturbed as `Scene::perturbed_normal` does,
        turned to the viewer's side by the *geometric* normal; the viewer clamped to just above
        the shading horizon; light accepted only above both the shading and the geometric plane
        (`lambert_cos`). Sampling is probegi's mixture (VNDF + cosine).

        MTL: `diffuse` (Kd × map_Kd), constant `f0` (Ks) and `alpha`. glTF (`gltf` a dict, see
        `material_bsdf`): `Material::bsdf` per point: base = factor × COLOR_0 × baseColorTexture,
        roughness/metalness = factors × G/B of metallicRoughnessTexture, α = clamp(r², 1e-3, 1),
        diffuse = base (1 − metallic), F0 = lerp(0.04, base, metallic)."""

        def __init__(
            self, props, diffuse=None, f0=(0.0, 0.0, 0.0), alpha=1.0, bump=None, bump_slope=(1.0, 1.0), gltf=None
        ):
            mi.BSDF.__init__(self, props)
            self.diffuse = diffuse
            self.gltf = gltf
            self.f0 = mi.Color3f(*[float(x) for x in f0])
            self.has_spec = gltf is not None or max(float(x) for x in f0) > 0.0
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

        def _params(self, si, active):
            """(diffuse albedo after the 1 − max F0 split, F0, α, specular lobe on)."""
            if self.gltf is None:
                base = self.diffuse.eval(si, active) * self.kdiff
                return base, self.f0, mi.Float(self.alpha), mi.Bool(self.has_spec)
            g = self.gltf
            base = lookup(g["base"], si, active)
            if g["vertex_color"]:
                base = base * si.shape.eval_attribute_3("vertex_color", si, active)
            rough, metal = mi.Float(g["roughness"]), mi.Float(g["metallic"])
            if g["mr"] is not None:
                t = lookup(g["mr"], si, active)
                rough, metal = rough * t[1], metal * t[2]
            a = dr.clip(rough * rough, MIN_ALPHA, 1.0)
            f0 = 0.04 * (1.0 - metal) + base * metal
            fmax = dr.maximum(dr.maximum(f0[0], f0[1]), f0[2])
            diffuse = base * (1.0 - metal) * (1.0 - dr.minimum(fmax, 1.0))
            return diffuse, f0, a, fmax > 0.0

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
                along_u, _ = normalize_or_zero(si.dp_du - ns * dr.dot(ns, si.dp_du))
                along_v, _ = normalize_or_zero(si.dp_dv - ns * dr.dot(ns, si.dp_dv))
                b, ok = normalize_or_zero(ns - along_u * slope.x - along_v * slope.y)
                b = dr.select(ok, b, ns)
                ns = dr.select(dr.dot(b, ng) > 1e-3, b, ns)
            if self.gltf is not None and self.gltf["normal"] is not None:
                # `Scene::perturbed_normal` (normal map): the interpolated tangent made
                # orthogonal to ns, bitangent = sign(corner 0's w) · ns × tangent, the texel
                # (raw unorm × 2 − 1) with X, Y × normalTexture.scale; unchanged where the
                # tangent vanishes, dropped unless 1e-3 above the geometric plane.
                t = mi.Vector3f(si.shape.eval_attribute_3("vertex_tangent", si, active))
                sign = dr.select(si.shape.eval_attribute_1("face_tsign", si, active) < 0, -1.0, 1.0)
                tan, tan_ok = normalize_or_zero(t - ns * dr.dot(ns, t))
                bit = dr.cross(ns, tan) * sign
                s = lookup(self.gltf["normal"], si, active) * 2.0 - 1.0
                k = self.gltf["normal_scale"]
                b, ok = normalize_or_zero(tan * (s[0] * k) + bit * (s[1] * k) + ns * s[2])
                b = dr.select(ok & tan_ok, b, ns)
                ns = dr.select(dr.dot(b, ng) > 1e-3, b, ns)
            wv_world = si.to_world(si.wi)
            front = dr.dot(wv_world, ng) > 0
            nf = dr.select(front, ns, -ns)
            gf = dr.select(front, ng, -ng)
            frame = mi.Frame3f(nf)
            wv = frame.to_local(wv_world)
            wv = dr.normalize(mi.Vector3f(wv.x, wv.y, dr.maximum(wv.z, 1e-4)))
            return frame, gf, wv

        @staticmethod
        def _lobe_probability(diffuse, f0, spec_on):
            d = lum(diffuse)
            s = lum(f0)
            p = dr.select(d <= 0, 1.0, dr.clip(s / dr.maximum(s + d, 1e-30), 0.1, 0.9))
            return dr.select(spec_on, p, 0.0)

        def _eval_pdf_local(self, params, wv, wl, ok, active):
            diffuse, f0, a, spec_on = params
            valid = active & ok & (wv.z > 0) & (wl.z > 0)
            value = diffuse * dr.inv_pi * wl.z
            ps = self._lobe_probability(diffuse, f0, spec_on)
            pdf = (1.0 - ps) * wl.z * dr.inv_pi
            if self.has_spec:
                h = dr.normalize(wv + wl)
                m = (1.0 - dr.clip(dr.dot(wl, h), 0.0, 1.0)) ** 5
                fres = f0 + (1.0 - f0) * m
                wlz = dr.maximum(wl.z, 1e-12)  # invalid directions are masked; scalar floats raise on /0
                spec = fres * (ggx_d(h.z, a) * smith_g2(wv.z, wlz, a) / (4.0 * wv.z * wlz)) * wl.z
                value += dr.select(spec_on, spec, 0.0)
                pdf += ps * smith_g1(wv.z, a) * ggx_d(h.z, a) / (4.0 * wv.z)
            return dr.select(valid, value, 0.0), dr.select(valid, pdf, 0.0)

        def sample(self, ctx, si, sample1, sample2, active=True):
            frame, gf, wv = self._frame(si, active)
            params = self._params(si, active)
            ps = self._lobe_probability(params[0], params[1], params[3])
            wl = mi.warp.square_to_cosine_hemisphere(sample2)
            pick_spec = sample1 < ps
            if self.has_spec:
                h = vndf(wv, params[2], sample2)
                wl = dr.select(pick_spec, 2.0 * dr.dot(wv, h) * h - wv, wl)
            wl_world = frame.to_world(wl)
            ok = dr.dot(wl_world, gf) > 0
            value, pdf = self._eval_pdf_local(params, wv, wl, ok, active)
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
            return self._eval_pdf_local(self._params(si, active), wv, frame.to_local(wl_world), ok, active)

        def eval(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[1]

        def eval_diffuse_reflectance(self, si, active=True):
            return self._params(si, active)[0]

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"ProbegiBSDF[f0={self.f0}, alpha={self.alpha}, bump={self.bump is not None}, gltf={self.gltf is not None}]"

    def new_direction_sample():
        """dr.zeros(DirectionSample3f); scalar variants cannot build one that way."""
        if mi.variant().startswith("scalar"):
            return mi.DirectionSample3f()
        return dr.zeros(mi.DirectionSample3f)

    class ProbegiArea(mi.Emitter):
        """An emissive mesh as probegi treats it (`Scene::emitted`, `DirectLighting`): it emits
        from the front (counter-clockwise) face only, decided by the *geometric* normal, with
        radiance Ke (× the emissive texture through its reference: TEXCOORD_0/1,
        KHR_texture_transform, sampler). Next-event estimation picks a point uniformly by area
        over the mesh's own triangle list (Mitsuba's `area` emitter samples a textured radiance
        through the UV layout instead, `eval_parameterization`, which misses every triangle
        whose UVs overlap another's: mirrored labels, two-sided cards). The density MIS weighs
        with (`ds.pdf`, `pdf_direction`) uses the normal in `ds.n`, the shading normal as
        Mitsuba fills it on hits, in both places, so the weights still sum to one; the
        returned weight divides by the true density (geometric cosine). JIT variants only."""

        def __init__(self, props, geom: "Geometry", flat: bool, radiance, tex_ref=None):
            mi.Emitter.__init__(self, props)
            self.m_flags = +mi.EmitterFlags.Surface
            if tex_ref is not None:
                self.m_flags = self.m_flags | mi.EmitterFlags.SpatiallyVarying
            P = geom.P.astype(np.float64)
            areas = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
            self.inv_area = 1.0 / max(float(areas.sum()), 1e-30)
            self.dist = mi.DiscreteDistribution(mi.Float(areas.astype(np.float32)))
            f32 = lambda a: mi.Float(np.ascontiguousarray(a, np.float32).reshape(-1))  # noqa: E731
            self.p = [f32(P[:, k]) for k in range(3)]
            self.n = None if flat else [f32(geom.N[:, k]) for k in range(3)]
            self.uv = [f32(geom.UV[:, k]) for k in range(3)]
            self.uv1 = [f32(geom.extra("UV1")[:, k]) for k in range(3)] if geom.UV1 is not None else self.uv
            self.radiance = mi.Color3f(*[float(x) for x in radiance])
            self.tex_ref = tex_ref

        def _le(self, uv0, uv1, active):
            if self.tex_ref is None:
                return self.radiance
            return self.radiance * lookup_uv(self.tex_ref, uv0, uv1, active)

        def eval(self, si, active=True):
            front = dr.dot(si.n, si.to_world(si.wi)) > 0
            uv1 = None
            if self.tex_ref is not None and self.tex_ref[1][0] == 1:
                a = si.shape.eval_attribute_3("vertex_uv1", si, active)
                uv1 = mi.Point2f(a[0], a[1])
            return dr.select(active & front, self._le(mi.Point2f(si.uv), uv1, active), 0.0)

        def sample_direction(self, it, sample, active=True):
            idx, u = self.dist.sample_reuse(sample.x, active)
            b = mi.warp.square_to_uniform_triangle(mi.Point2f(u, sample.y))
            w0 = 1.0 - b.x - b.y

            def at(arrs, T):
                c = [dr.gather(T, a, idx, active) for a in arrs]
                return c[0] * w0 + c[1] * b.x + c[2] * b.y

            q = [dr.gather(mi.Point3f, a, idx, active) for a in self.p]
            p = q[0] * w0 + q[1] * b.x + q[2] * b.y
            ng = dr.normalize(dr.cross(q[1] - q[0], q[2] - q[0]))
            ns = ng if self.n is None else dr.normalize(at(self.n, mi.Vector3f))
            d = p - it.p
            dist2 = dr.squared_norm(d)
            dist = dr.sqrt(dist2)
            wi = d / dist
            cos_g = -dr.dot(ng, wi)
            cos_s = dr.abs(dr.dot(ns, wi))
            ok = active & (cos_g > 0) & (dist2 > 0)
            ds = dr.zeros(mi.DirectionSample3f)
            ds.p = p
            ds.n = ns
            ds.uv = at(self.uv, mi.Point2f)
            ds.d = wi
            ds.dist = dist
            ds.pdf = dr.select(ok, self.inv_area * dist2 / dr.maximum(cos_s, 1e-12), 0.0)
            ds.delta = False
            ds.time = it.time
            ds.emitter = mi.EmitterPtr(self)
            uv1 = at(self.uv1, mi.Point2f) if (self.tex_ref is not None and self.tex_ref[1][0] == 1) else None
            le = self._le(ds.uv, uv1, ok)
            weight = le * cos_g / (self.inv_area * dr.maximum(dist2, 1e-30))
            return ds, dr.select(ok, weight, 0.0)

        def pdf_direction(self, it, ds, active=True):
            c = dr.abs(dr.dot(ds.d, ds.n))
            return dr.select(active & (c > 0), self.inv_area * ds.dist * ds.dist / dr.maximum(c, 1e-12), 0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Color3f(0.0)  # not used by `path` / `volpath`

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            raise NotImplementedError("light tracing is not supported by this emitter")

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"ProbegiArea[textured={self.tex_ref is not None}]"

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
            ds = new_direction_sample()
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

    PLUGINS["area"] = ProbegiArea
    return ProbegiBSDF, GltfPunctual


def bitmap_texture(mi, arr: np.ndarray, nearest: bool = False, wrap: str = "repeat", to_uv=None):
    arr = np.ascontiguousarray(arr.astype(np.float32))
    d = {
        "type": "bitmap",
        "bitmap": mi.Bitmap(arr),
        "raw": True,
        "filter_type": "nearest" if nearest else "bilinear",
        "wrap_mode": wrap,
    }
    if to_uv is not None:
        d["to_uv"] = to_uv
    return mi.load_dict(d)


def uv_transform(mi, rows):
    """KHR_texture_transform rows as a Mitsuba `to_uv` transform (None: identity)."""
    if rows is None:
        return None
    m = np.eye(3)
    m[:2, :] = rows
    return mi.ScalarTransform3f(m.tolist())


def gltf_tex_ref(mi, tex: Texture | None, arr: np.ndarray | None, mapping, const=None):
    """A glTF texture reference for `lookup` in ProbegiBSDF: (Mitsuba texture, (set, rows),
    fold). texture.rs samplers: the filter (bilinear or nearest, no mipmaps) and wrapping on
    the integer texel index. One wrap mode on both axes is Mitsuba's own `wrap_mode` (repeat,
    mirror, clamp: the same index rules); mixed modes are exact too: the image padded by one
    texel per side (the wrapped neighbour for repeat, the edge texel for mirror and clamp),
    read with clamp, the coordinate folded per axis into [0, 1] by its mode first."""
    if tex is None:
        return (const_texture(mi, const), (0, None), None)
    nearest = tex.filter == "nearest"
    if tex.wrap_u == tex.wrap_v:
        return (bitmap_texture(mi, arr, nearest, tex.wrap_u), mapping, None)
    import drjit as dr

    h, w = arr.shape[:2]

    def pad(a, axis, mode):
        n = a.shape[axis]
        lo, hi = ([n - 1], [0]) if mode == "repeat" else ([0], [n - 1])
        return np.concatenate([np.take(a, lo, axis), a, np.take(a, hi, axis)], axis)

    padded = pad(pad(arr, 1, tex.wrap_u), 0, tex.wrap_v)

    def fold1(c, mode, n):
        if mode == "repeat":
            c = c - dr.floor(c)
        elif mode == "mirror":
            t = c - 2.0 * dr.floor(c * 0.5)
            c = dr.select(t > 1.0, 2.0 - t, t)
        else:
            c = dr.clip(c, 0.0, 1.0)
        return (c * n + 1.0) / (n + 2.0)

    def fold(uv):
        return mi.Point2f(fold1(uv.x, tex.wrap_u, w), fold1(uv.y, tex.wrap_v, h))

    return (bitmap_texture(mi, padded, nearest, "clamp"), mapping, fold)


def gltf_material_bsdf(mi, ProbegiBSDF, m: Material, cache: dict, model: str, notes: list[str]):
    """glTF metallic-roughness → ProbegiBSDF (probegi's Material::bsdf per point), or, with
    `--shading-model mitsuba`, Mitsuba's own `principled` (+ `normalmap`) for contrast."""
    unorm = lambda t: t.rgb8.astype(np.float32) / 255.0  # noqa: E731

    def cached(key, make):
        if key not in cache:
            cache[key] = make()
        return cache[key]

    kd = m.kd.astype(np.float32)
    if model == "mitsuba":
        base = (
            bitmap_texture(mi, m.kd_tex.linear_rgb() * kd[None, None, :], to_uv=uv_transform(mi, m.kd_uv[1]))
            if m.kd_tex is not None
            else const_texture(mi, kd)
        )
        d = {"type": "principled", "base_color": base, "specular": 0.5, "spec_tint": 0.0}
        if m.mr_tex is not None:
            t = unorm(m.mr_tex)
            xf = uv_transform(mi, m.mr_uv[1])
            d["roughness"] = bitmap_texture(mi, (t[..., 1] * m.roughness)[..., None], to_uv=xf)
            d["metallic"] = bitmap_texture(mi, (t[..., 2] * m.metallic)[..., None], to_uv=xf)
        else:
            d["roughness"], d["metallic"] = float(m.roughness), float(m.metallic)
        bsdf = mi.load_dict({"type": "twosided", "material": d})
        if m.normal_tex is not None:
            nm = bitmap_texture(mi, unorm(m.normal_tex), to_uv=uv_transform(mi, m.normal_uv[1]))
            bsdf = mi.load_dict({"type": "normalmap", "normalmap": nm, "bsdf": bsdf})
        return bsdf
    g = {
        "base": cached(
            ("kd", id(m.kd_tex), tuple(kd), m.kd_uv[0], None if m.kd_uv[1] is None else m.kd_uv[1].tobytes()),
            lambda: gltf_tex_ref(
                mi, m.kd_tex, None if m.kd_tex is None else m.kd_tex.linear_rgb() * kd[None, None, :], m.kd_uv, kd
            ),
        ),
        "vertex_color": m.vertex_color,
        "roughness": float(m.roughness),
        "metallic": float(m.metallic),
        "mr": None
        if m.mr_tex is None
        else cached(("mr", id(m.mr_tex), m.mr_uv[0], None if m.mr_uv[1] is None else m.mr_uv[1].tobytes()),
                    lambda: gltf_tex_ref(mi, m.mr_tex, unorm(m.mr_tex), m.mr_uv)),
        "normal": None
        if m.normal_tex is None
        else cached(("nm", id(m.normal_tex), m.normal_uv[0], None if m.normal_uv[1] is None else m.normal_uv[1].tobytes()),
                    lambda: gltf_tex_ref(mi, m.normal_tex, unorm(m.normal_tex), m.normal_uv)),
        "normal_scale": float(m.normal_scale),
    }
    return ProbegiBSDF(mi.Properties(), gltf=g)


def const_texture(mi, c):
    """A constant colour (Mitsuba's `rgb` reflectance refuses values above 1: a 1×1 bitmap then)."""
    if max(float(x) for x in c) <= 1.0:
        return mi.load_dict({"type": "rgb", "value": [float(x) for x in c]})
    return bitmap_texture(mi, np.asarray(c, np.float32).reshape(1, 1, 3), nearest=True)


CUTOUT_SUPERSAMPLE = 8


def thresholded_coverage(tex: Texture, factor: float, cutoff: float = ALPHA_CUTOFF, max_res: int = 4096) -> np.ndarray:
    """Coverage ≥ the cutoff of probegi's bilinear filter (repeat), evaluated on a grid k× finer."""
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
    return (factor * up >= cutoff).astype(np.float32)


# probegi-scene `material::BUMP_WHITE_HEIGHT_REL`: a white texel of a height map rises
# 0.02 · max(W, H) texels (G3D's default `zExtentPixels` of −0.02), times MTL `-bm`.
BUMP_WHITE_HEIGHT_REL = 0.02


def bump_slope(m: Material) -> tuple[float, float]:
    """Factors from the height's gradient per unit (u, v) to probegi's texel-space slope:
    white_texels / W and white_texels / H, times `-bm` (`Scene::perturbed_normal`)."""
    h, w = m.bump_tex.rgb8.shape[:2]
    white_texels = BUMP_WHITE_HEIGHT_REL * max(w, h)
    return (white_texels / w * m.bump_multiplier, white_texels / h * m.bump_multiplier)


def material_bsdf(mi, ProbegiBSDF, m: Material, cache: dict, smooth: bool, model: str, notes: list[str] | None = None):
    """The Mitsuba BSDF of a material. model = "probegi": specular, bump-mapped and
    smooth-shaded materials use ProbegiBSDF (probegi's BSDF and shading-frame rules);
    "mitsuba": only specular ones do, bump maps go through Mitsuba's `bumpmap` with
    scale = bm (the pbrt/Mitsuba reading, not probegi's: see the module docstring).
    glTF materials: `gltf_material_bsdf`. Cutouts: a `mask` around it."""
    if m.gltf:
        return with_cutout(mi, m, gltf_material_bsdf(mi, ProbegiBSDF, m, cache, model, notes if notes is not None else []))
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
    return with_cutout(mi, m, bsdf)


def with_cutout(mi, m: Material, bsdf):
    """A `mask` BSDF with the thresholded coverage (TEXCOORD_0, repeat, bilinear, as
    probegi's traversal test reads it whatever the texture's sampler) where it has a cutout."""
    if m.has_cutout():
        if m.alpha_tex is not None:
            cov = thresholded_coverage(m.alpha_tex, m.alpha_factor, m.alpha_cutoff)
            opacity = bitmap_texture(mi, cov[..., None], nearest=True)
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


def make_mesh(mi, name: str, P, N, UV, flat: bool, bsdf, emitter, extra: Geometry | None = None):
    """A Mitsuba mesh of corner-expanded triangles. `extra` (glTF materials): its tangents
    (`vertex_tangent`), corner-0 bitangent signs (`face_tsign`), TEXCOORD_1 (`vertex_uv1`)
    and COLOR_0 (`vertex_color`) become mesh attributes that ProbegiBSDF reads."""
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
    if extra is not None:
        uv1 = extra.extra("UV1")
        uv1 = np.concatenate([uv1, np.zeros(uv1.shape[:2] + (1,))], axis=2)
        for key, arr, k in (
            ("vertex_tangent", extra.extra("T"), 3),
            ("vertex_uv1", uv1, 3),
            ("vertex_color", extra.extra("COL"), 3),
            ("face_tsign", extra.extra("TS"), 1),
        ):
            mesh.add_attribute(key, k, np.ascontiguousarray(arr.astype(np.float32).reshape(-1)).tolist())
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
    n_spec = n_bump = n_pbsdf = n_gltf = n_normal = 0
    for mi_idx in np.unique(g.mat):
        m = scene.materials[int(mi_idx)]
        sel = g.mat == mi_idx
        smooth = bool((sel & ~g.flat).any())
        bsdf = material_bsdf(mi, ProbegiBSDF, m, tex_cache, smooth, args.shading_model, notes)
        n_spec += m.has_specular() and not m.gltf
        n_bump += m.bump_tex is not None
        n_gltf += m.gltf
        n_normal += m.normal_tex is not None
        n_pbsdf += args.shading_model == "probegi" and (m.has_specular() or m.bump_tex is not None or smooth)
        emitter = None
        if m.is_emissive():
            jit = not mi.variant().startswith("scalar")
            tex_ref = None
            if m.ke_tex is not None:
                tex_ref = gltf_tex_ref(mi, m.ke_tex, m.ke_tex.linear_rgb(), m.ke_uv)
            if jit:

                def emitter(sub, flat, ke=m.ke, tex_ref=tex_ref):
                    return PLUGINS["area"](mi.Properties(), sub, flat, ke, tex_ref)

            else:
                # scalar variants: Mitsuba's `area` (a Python emitter's gathers need JIT arrays).
                # It emits from the side of the interpolated normal, and samples a textured
                # radiance through the UV layout (wrong where UVs overlap).
                notes.append(f"material {m.name}: emitter is Mitsuba's `area` (scalar variant; see docstring)")

                def emitter(sub, flat, m=m):
                    if m.ke_tex is None:
                        rad = {"type": "rgb", "value": [float(x) for x in m.ke]}
                    else:
                        t = m.ke_tex
                        rad = bitmap_texture(
                            mi, t.linear_rgb() * m.ke[None, None, :], t.filter == "nearest", t.wrap_u,
                            uv_transform(mi, m.ke_uv[1]),
                        )
                    return mi.load_dict({"type": "area", "radiance": rad})

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
                if not s.any():
                    continue
                key = f"mesh_{int(mi_idx)}_{'flat' if flat else 'smooth'}{suffix}"
                extra = g.select(s) if m.gltf else None
                em = emitter(g.select(s), flat) if emitter is not None else None
                d[key] = make_mesh(mi, key, g.P[s], g.N[s], g.UV[s], flat, part_bsdf, em, extra)
    if n_spec:
        notes.append(f"{n_spec} material(s) with Ks > 0 (GGX lobe)")
    if n_bump:
        how = "ProbegiBSDF's bump frame" if args.shading_model == "probegi" else "Mitsuba `bumpmap`"
        notes.append(f"{n_bump} material(s) with bump maps: {how}")
    if n_pbsdf:
        notes.append(f"{n_pbsdf} material(s) through the Python ProbegiBSDF (--shading-model {args.shading_model})")
    if n_gltf:
        how = "ProbegiBSDF (probegi's Material::bsdf)" if args.shading_model == "probegi" else "Mitsuba `principled`"
        notes.append(f"{n_gltf} glTF metallic-roughness material(s): {how}; {n_normal} with normal maps")
    if scene.sky_map is not None:
        # probegi's convention is Mitsuba's envmap (environment_map.rs): the same
        # file, scale and turn about +y; --sky-map-extra-rotation-deg turns
        # Mitsuba's alone (a sensitivity check that must fail).
        m = scene.sky_map
        turn = m["rotation_deg"] + float(args.sky_map_extra_rotation_deg)
        d["sky"] = {
            "type": "envmap",
            "filename": m["path"],
            "scale": m["intensity"],
            "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], turn),
        }
        notes.append(f"sky map {m['path']} × {m['intensity']}, turned {m['rotation_deg']}° (Mitsuba {turn}°)")
    elif float(scene.sky.max()) > 0:
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
    ap.add_argument(
        "--scene", action="append", required=True, help=".obj, .gltf, .glb, .toml or builtin:NAME (repeatable)"
    )
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
    ap.add_argument("--sky-map", help="equirectangular .exr/.hdr sky (overrides the scene's sky)")
    ap.add_argument("--sky-intensity", type=float, default=1.0, help="the sky map's radiance scale")
    ap.add_argument("--sky-rotation-deg", type=float, default=0.0, help="the sky map's turn about +y")
    ap.add_argument(
        "--sky-map-extra-rotation-deg",
        type=float,
        default=0.0,
        help="turn Mitsuba's sky map alone by this much more (a sensitivity check: 90 must fail)",
    )
    ap.add_argument("--max-depth", type=int, default=64, help="probegi's --max-depth (Mitsuba gets N + 1)")
    ap.add_argument("--frame", type=float, default=0.0, help="light keyframes evaluated at this frame")
    ap.add_argument("--seed", type=int, default=0, help="probegi seed; Mitsuba uses seed+1 and seed+2")
    ap.add_argument(
        "--no-bump",
        action="store_true",
        help="ignore MTL bump maps and glTF normal maps (probegi gets --set normal_maps=false)",
    )
    ap.add_argument(
        "--shading-model",
        choices=["probegi", "mitsuba"],
        default="probegi",
        help="probegi: bump-mapped, glossy and smooth-shaded materials use the Python ProbegiBSDF with\n"
        "probegi's shading-frame and bump rules; mitsuba: Mitsuba's bumpmap (scale = -bm, scene units;\n"
        "NOT equivalent to probegi's texel-space bump rule) and twosided(diffuse) rules; glTF materials:\n"
        "twosided(principled) + normalmap (NOT equivalent either, for contrast)",
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
            scene.sky_map = None
        if args.sky_map is not None:
            scene.sky_map = {
                "path": str(Path(args.sky_map).resolve()),
                "intensity": args.sky_intensity,
                "rotation_deg": args.sky_rotation_deg,
            }
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
            if scene.sky_map is not None:
                m = scene.sky_map
                cmd += [f"--sky-map={m['path']}", f"--sky-intensity={m['intensity']!r}"]
                cmd.append(f"--sky-rotation-deg={m['rotation_deg']!r}")
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
            # The same over the pixels that see geometry: a pixel whose every sample leaves for the
            # constant sky is exactly the sky in both Mitsuba images (it would dilute the ratio).
            sky = np.asarray(scene.sky, np.float64)
            tol = 1e-4 * max(float(sky.max()), 1.0)
            obj = (np.abs(b - sky).max(-1) > tol) | (np.abs(b2 - sky).max(-1) > tol)
            if scene.sky_map is not None:
                # Pixels that see the map differ between seeds too: no object mask.
                obj = np.ones(obj.shape, bool)
            row["object_px"] = float(obj.mean())
            if obj.any():
                row["ratio_obj"] = a[obj].mean(0) / np.maximum(b[obj].mean(0), 1e-12)
                row["ratio_obj_floor"] = b2[obj].mean(0) / np.maximum(b[obj].mean(0), 1e-12)
        rows.append(row)
        print(f"[{spec}] scene build {t_load:.1f} s", file=sys.stderr)

    lines = [
        f"Mitsuba {mi.__version__} ({variant}) vs probegi reference ({args.probegi})",
        "",
        "| scene | resolution | spp | FLIP probegi vs Mitsuba | FLIP Mitsuba seed A vs B (noise floor) "
        "| mean ratio probegi/Mitsuba (R,G,B) | same for Mitsuba B/A "
        "| object pixels | mean ratio over them, probegi/Mitsuba | same for Mitsuba B/A |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def f3(r, k):
        return " ".join(f"{x:.3f}" for x in r[k]) if k in r else "-"

    for r in rows:
        fl = f"{r['flip']:.4f}" if "flip" in r else "-"
        px = f"{100 * r['object_px']:.0f} %" if "object_px" in r else "-"
        lines.append(
            f"| {r['scene']} | {r['res']} | {r['spp']} | {fl} | {r['floor']:.4f} | {f3(r, 'ratio')} "
            f"| {f3(r, 'ratio_floor')} | {px} | {f3(r, 'ratio_obj')} | {f3(r, 'ratio_obj_floor')} |"
        )
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
