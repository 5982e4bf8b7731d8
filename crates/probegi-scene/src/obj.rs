//! Wavefront OBJ/MTL loader, written for the McGuire Computer Graphics Archive
//! scenes: `v`/`vt`/`vn`/`f` with negative (relative) indices and polygons of any
//! size (fan-triangulated), `s`, `usemtl`, `mtllib`; MTL `Kd`, `Ke`, `Ks`, `Ns`,
//! `d`, `Tr`, `map_Kd`, `map_Ke`, `map_d`, `bump`/`map_bump` (with `-bm`).
//! Everything else (`g`, `o`, `l`, `Ka`, `illum`, ...) is ignored.
//!
//! Shading normals follow the OBJ specification: a `vn` is used as given;
//! corners without one are smoothed within their smoothing group (`s N`,
//! N ≠ 0: angle-weighted normals of the group's faces that share the corner's
//! position), and take the face normal where smoothing is off (`s 0`,
//! `s off`, or no `s` statement at all).
//!
//! Conventions: texture `v` is flipped to the top-left origin the textures use;
//! cutouts and bump maps as in `material.rs`; a missing `.mtl`, unknown
//! material or missing texture degrades to grey / factor-only with a warning; any
//! malformed line is an error naming the file and line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::error::{Result, SceneError};
use crate::file_lookup::resolve_case_insensitive;
use crate::material::{AlphaMode, DEFAULT_ALPHA_CUTOFF, Material};
use crate::mesh::{Mesh, NormalSource};
use crate::scene::Scene;
use crate::texture::Texture;

struct LineCtx<'a> {
    path: &'a Path,
    line: usize,
}

impl LineCtx<'_> {
    fn err(&self, message: impl Into<String>) -> SceneError {
        SceneError::Parse { path: self.path.to_path_buf(), line: self.line, message: message.into() }
    }

    fn float(&self, tok: Option<&str>, what: &str) -> Result<f32> {
        let tok = tok.ok_or_else(|| self.err(format!("missing {what}")))?;
        let v: f32 = tok.parse().map_err(|_| self.err(format!("{what} `{tok}` is not a number")))?;
        if !v.is_finite() {
            return Err(self.err(format!("{what} `{tok}` is not finite")));
        }
        Ok(v)
    }

    fn vec3(&self, toks: &mut std::str::SplitWhitespace<'_>, what: &str) -> Result<Vec3> {
        Ok(Vec3::new(self.float(toks.next(), what)?, self.float(toks.next(), what)?, self.float(toks.next(), what)?))
    }

    /// A 1-based or negative OBJ index into a list of `count` elements, 0-based.
    fn index(&self, tok: &str, count: usize, what: &str) -> Result<u32> {
        let i: i64 = tok.parse().map_err(|_| self.err(format!("{what} index `{tok}` is not an integer")))?;
        let resolved = if i > 0 { i - 1 } else { count as i64 + i };
        if i == 0 || resolved < 0 || resolved >= count as i64 {
            return Err(self.err(format!("{what} index {i} out of range ({count} {what}s defined so far)")));
        }
        Ok(resolved as u32)
    }
}

/// Shared texture cache while loading one scene, keyed by resolved path.
#[derive(Default)]
pub(crate) struct TextureCache {
    by_path: HashMap<PathBuf, usize>,
}

impl TextureCache {
    /// Loads (once) the texture `name` relative to `base_dir`. Missing file: warning and
    /// `None`. Present but undecodable: error.
    pub(crate) fn get(
        &mut self,
        scene: &mut Scene,
        base_dir: &Path,
        name: &str,
        referenced_from: &Path,
    ) -> Result<Option<usize>> {
        let Some(path) = resolve_case_insensitive(base_dir, name) else {
            scene.warnings.push(format!(
                "{}: texture `{name}` not found; using the colour factor only",
                referenced_from.display()
            ));
            return Ok(None);
        };
        if let Some(&id) = self.by_path.get(&path) {
            return Ok(Some(id));
        }
        let tex = Texture::load(&path)?;
        scene.textures.push(tex);
        let id = scene.textures.len() - 1;
        self.by_path.insert(path, id);
        Ok(Some(id))
    }
}

/// A text file as UTF-8, leniently: a leading byte-order mark is dropped and bytes
/// that are not UTF-8 (Latin-1 comments and names in old exports) are replaced.
fn read_text_lossy(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?;
    let bytes = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF][..]).unwrap_or(&bytes);
    Ok(String::from_utf8_lossy(bytes).into_owned())
}

/// The file name of an MTL texture statement's arguments: the options (`-bm 1`,
/// `-s 1 1 1`, `-clamp on`, `-imfchan l`, ...) are skipped, the rest of the line,
/// spaces included, is the name.
fn texture_file_name(args: &str) -> Option<&str> {
    let mut rest = args.trim_start();
    while rest.starts_with('-') {
        let (option, after) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
        rest = after.trim_start();
        // Each option takes at most three values: numbers, on/off, or a channel or type word.
        let words = match option {
            "-o" | "-s" | "-t" => 3,
            "-mm" => 2,
            _ => 1,
        };
        for _ in 0..words {
            let (value, after) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
            let is_value = value.parse::<f32>().is_ok()
                || matches!(value, "on" | "off" | "r" | "g" | "b" | "m" | "l" | "z")
                || (option == "-type" && !value.is_empty());
            // The last "value" is the file name when nothing follows it.
            if !is_value || after.trim().is_empty() {
                break;
            }
            rest = after.trim_start();
        }
    }
    let name = rest.trim();
    (!name.is_empty()).then_some(name)
}

/// Loads an OBJ file (and its MTL libraries and textures) as a scene.
pub fn load_obj(path: &Path) -> Result<Scene> {
    let text = read_text_lossy(path)?;
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut scene = Scene { name: path.display().to_string(), ..Default::default() };
    let mut textures = TextureCache::default();
    let mut material_ids: HashMap<String, u32> = HashMap::new();

    let mut geometry = ObjGeometry::new();
    let mut current_material: Option<u32> = None;
    // Smoothing group of the faces that follow; 0 = off (the specification's default).
    let mut smoothing_group: u32 = 0;

    for (line_idx, raw) in text.lines().enumerate() {
        let ctx = LineCtx { path, line: line_idx + 1 };
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut toks = line.split_whitespace();
        let Some(keyword) = toks.next() else { continue };
        match keyword {
            "v" => geometry.v.push(ctx.vec3(&mut toks, "vertex coordinate")?),
            "vn" => geometry.vn.push(ctx.vec3(&mut toks, "normal component")?),
            "vt" => {
                let u = ctx.float(toks.next(), "texture coordinate")?;
                let tv = match toks.next() {
                    Some(t) => ctx.float(Some(t), "texture coordinate")?,
                    None => 0.0,
                };
                geometry.vt.push(Vec2::new(u, 1.0 - tv));
            }
            "f" => {
                geometry.read_face(&ctx, toks)?;
                let mat = match current_material {
                    Some(m) => m,
                    None => {
                        let m = material_id(&mut scene, &mut material_ids, "default", None);
                        current_material = Some(m);
                        m
                    }
                };
                let source = match smoothing_group {
                    0 => NormalSource::Flat,
                    g => NormalSource::Smooth(g),
                };
                geometry.add_face_triangles(mat, source);
            }
            "s" => {
                smoothing_group = match toks.next() {
                    Some("off") | Some("0") => 0,
                    Some(t) => t
                        .parse::<u32>()
                        .map_err(|_| ctx.err(format!("smoothing group `{t}` is not `off` or a whole number")))?,
                    None => return Err(ctx.err("`s` without a smoothing group")),
                };
            }
            "usemtl" => {
                let name = line["usemtl".len()..].trim();
                let warn = format!("{}:{}: material `{name}` is not defined; using grey", path.display(), ctx.line);
                current_material = Some(material_id(&mut scene, &mut material_ids, name, Some(warn)));
            }
            "mtllib" => load_mtllib_line(line, &ctx, &base_dir, &mut scene, &mut material_ids, &mut textures)?,
            _ => {}
        }
    }

    scene.mesh = geometry.into_mesh(path)?;
    Ok(scene)
}

/// The vertex lists an OBJ file has declared so far (`v`, `vt`, `vn`) and the
/// mesh its faces build, one mesh vertex per distinct corner triple.
struct ObjGeometry {
    v: Vec<Vec3>,
    vt: Vec<Vec2>,
    vn: Vec<Vec3>,
    mesh: Mesh,
    needs_normal: Vec<bool>,
    vertex_of: HashMap<(u32, u32, u32), u32>,
    /// The mesh vertices of the face being read.
    face: Vec<u32>,
    normal_sources: Vec<NormalSource>,
}

impl ObjGeometry {
    fn new() -> Self {
        Self {
            v: Vec::new(),
            vt: Vec::new(),
            vn: Vec::new(),
            mesh: Mesh::default(),
            needs_normal: Vec::new(),
            vertex_of: HashMap::new(),
            face: Vec::with_capacity(8),
            normal_sources: Vec::new(),
        }
    }

    /// Reads an `f` statement's corners into `face`, adding the mesh vertices it
    /// is the first to use.
    fn read_face(&mut self, ctx: &LineCtx<'_>, toks: std::str::SplitWhitespace<'_>) -> Result<()> {
        let Self { v, vt, vn, mesh, needs_normal, vertex_of, face, .. } = self;
        face.clear();
        for tok in toks {
            let mut parts = tok.split('/');
            let pi = ctx.index(parts.next().unwrap_or(""), v.len(), "vertex")?;
            let ti = match parts.next() {
                Some("") | None => u32::MAX,
                Some(t) => ctx.index(t, vt.len(), "texture coordinate")?,
            };
            let ni = match parts.next() {
                Some("") | None => u32::MAX,
                Some(t) => ctx.index(t, vn.len(), "normal")?,
            };
            let id = *vertex_of.entry((pi, ti, ni)).or_insert_with(|| {
                mesh.positions.push(v[pi as usize]);
                mesh.uvs.push(if ti == u32::MAX { Vec2::ZERO } else { vt[ti as usize] });
                let n = if ni == u32::MAX { Vec3::ZERO } else { vn[ni as usize].normalize_or_zero() };
                mesh.normals.push(n);
                needs_normal.push(n == Vec3::ZERO);
                (mesh.positions.len() - 1) as u32
            });
            face.push(id);
        }
        if face.len() < 3 {
            return Err(ctx.err(format!("face has {} vertices; at least 3 are needed", face.len())));
        }
        Ok(())
    }

    /// Fan-triangulates `face` with material `mat` and normal source `source`.
    fn add_face_triangles(&mut self, mat: u32, source: NormalSource) {
        let Self { mesh, face, normal_sources, .. } = self;
        for k in 1..face.len() - 1 {
            mesh.triangles.push([face[0], face[k], face[k + 1]]);
            mesh.triangle_materials.push(mat);
            normal_sources.push(source);
        }
    }

    /// The finished mesh, normals derived where no `vn` gave one; an error without faces.
    fn into_mesh(self, path: &Path) -> Result<Mesh> {
        let Self { mut mesh, needs_normal, normal_sources, .. } = self;
        if mesh.triangles.is_empty() {
            return Err(SceneError::Invalid { path: path.to_path_buf(), message: "no faces".into() });
        }
        if needs_normal.iter().any(|&b| b) {
            mesh.derive_normals(&normal_sources, &needs_normal, 180.0);
        }
        Ok(mesh)
    }
}

/// An `mtllib` statement: loads each library it names (one name with spaces,
/// or several); a missing one is a warning.
fn load_mtllib_line(
    line: &str,
    ctx: &LineCtx<'_>,
    base_dir: &Path,
    scene: &mut Scene,
    material_ids: &mut HashMap<String, u32>,
    textures: &mut TextureCache,
) -> Result<()> {
    let path = ctx.path;
    // One library name with spaces, or several separated by spaces.
    let rest = line["mtllib".len()..].trim();
    let names: Vec<&str> =
        if resolve_case_insensitive(base_dir, rest).is_some() { vec![rest] } else { rest.split_whitespace().collect() };
    for name in names {
        match resolve_case_insensitive(base_dir, name) {
            Some(mtl_path) => load_mtl(&mtl_path, scene, material_ids, textures)?,
            None => scene.warnings.push(format!(
                "{}:{}: material library `{name}` not found; materials fall back to grey",
                path.display(),
                ctx.line
            )),
        }
    }
    Ok(())
}

/// The id of material `name`, creating a grey one (and recording `warn_if_new`) if unknown.
fn material_id(scene: &mut Scene, ids: &mut HashMap<String, u32>, name: &str, warn_if_new: Option<String>) -> u32 {
    if let Some(&id) = ids.get(name) {
        return id;
    }
    if let Some(w) = warn_if_new {
        scene.warnings.push(w);
    }
    scene.materials.push(Material::default_grey(name));
    let id = (scene.materials.len() - 1) as u32;
    ids.insert(name.to_string(), id);
    id
}

fn load_mtl(path: &Path, scene: &mut Scene, ids: &mut HashMap<String, u32>, textures: &mut TextureCache) -> Result<()> {
    let text = read_text_lossy(path)?;
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut current: Option<usize> = None;
    let first_material = scene.materials.len();
    for (line_idx, raw) in text.lines().enumerate() {
        let ctx = LineCtx { path, line: line_idx + 1 };
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut toks = line.split_whitespace();
        let Some(keyword) = toks.next() else { continue };
        if keyword == "newmtl" {
            let name = line["newmtl".len()..].trim();
            if name.is_empty() {
                return Err(ctx.err("newmtl without a name"));
            }
            let mut m = Material::default_grey(name);
            // MTL's implicit Kd is 0.8 (the spec's default).
            m.base_color_factor = Vec3::splat(0.8);
            m.specular_model = crate::material::SpecularModel::Mtl;
            m.alpha_mode = AlphaMode::Mask { cutoff: DEFAULT_ALPHA_CUTOFF };
            scene.materials.push(m);
            current = Some(scene.materials.len() - 1);
            ids.insert(name.to_string(), (scene.materials.len() - 1) as u32);
            continue;
        }
        let Some(cur) = current else {
            if matches!(
                keyword,
                "Kd" | "Ke" | "Ks" | "Ns" | "d" | "Tr" | "map_Kd" | "map_Ke" | "map_d" | "bump" | "map_bump"
            ) {
                return Err(ctx.err(format!("`{keyword}` before any `newmtl`")));
            }
            continue;
        };
        match keyword {
            "Kd" => scene.materials[cur].base_color_factor = color(&ctx, &mut toks)?,
            "Ke" => scene.materials[cur].emissive_factor = color(&ctx, &mut toks)?,
            "Ks" => scene.materials[cur].specular_color = color(&ctx, &mut toks)?,
            "Ns" => {
                let ns = ctx.float(toks.next(), "Ns")?.max(0.0);
                scene.materials[cur].specular_exponent = ns;
                scene.materials[cur].roughness = (2.0 / (ns + 2.0)).powf(0.25);
            }
            "d" | "Tr" => {
                let v = ctx.float(toks.next(), keyword)?;
                if !(0.0..=1.0).contains(&v) {
                    return Err(ctx.err(format!("`{keyword}` {v} is outside [0, 1]")));
                }
                scene.materials[cur].alpha_factor = if keyword == "d" { v } else { 1.0 - v };
            }
            "map_Kd" | "map_Ke" | "map_d" | "bump" | "map_bump" => {
                // Options (`-bm 1`, `-s u v w`, ...) precede the file name, which is
                // the rest of the line (names may contain spaces).
                let args = &line[keyword.len()..];
                let Some(name) = texture_file_name(args) else {
                    return Err(ctx.err(format!("`{keyword}` without a file name")));
                };
                let tex = textures.get(scene, &base_dir, name, path)?;
                let m = &mut scene.materials[cur];
                match keyword {
                    "map_Kd" => m.base_color_texture = tex,
                    "map_Ke" => m.emissive_texture = tex,
                    "map_d" => m.alpha_texture = tex,
                    _ => {
                        m.bump_texture = tex;
                        m.bump_multiplier = bump_multiplier(&ctx, args)?;
                    }
                }
            }
            _ => {}
        }
    }
    // Without `map_d`, the alpha channel of `map_Kd` cuts out (most OBJ viewers' rule).
    for m in &mut scene.materials[first_material..] {
        if m.alpha_texture.is_none() {
            m.alpha_texture = m.base_color_texture.filter(|&t| scene.textures[t].alpha.is_some());
        }
    }
    Ok(())
}

/// The `-bm` value of a bump statement's options, 1 when absent.
fn bump_multiplier(ctx: &LineCtx<'_>, args: &str) -> Result<f32> {
    let mut toks = args.split_whitespace();
    while let Some(t) = toks.next() {
        if t == "-bm" {
            return ctx.float(toks.next(), "-bm multiplier");
        }
    }
    Ok(1.0)
}

/// An MTL colour: `r g b`, or a single value for grey. Negative components are an error.
fn color(ctx: &LineCtx<'_>, toks: &mut std::str::SplitWhitespace<'_>) -> Result<Vec3> {
    let r = ctx.float(toks.next(), "colour component")?;
    let c = match toks.next() {
        Some(g) => Vec3::new(r, ctx.float(Some(g), "colour component")?, ctx.float(toks.next(), "colour component")?),
        None => Vec3::splat(r),
    };
    if c.min_element() < 0.0 {
        return Err(ctx.err(format!("colour {c} has a negative component")));
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_tmp(name: &str, files: &[(&str, &str)]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("probegi-obj-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("mkdir");
        for (f, text) in files {
            std::fs::write(dir.join(f), text).expect("write");
        }
        dir
    }

    #[test]
    fn quads_negative_indices_and_materials() {
        let dir = write_tmp(
            "ok",
            &[
                (
                    "a.obj",
                    "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\nvt 0 0\nusemtl lamp\nf -4/1 -3/1 -2/1 -1/1\n",
                ),
                ("a.mtl", "newmtl lamp\nKd 0.5 0.25 0.125\nKe 17 12 4\nNs 10\n"),
            ],
        );
        let s = load_obj(&dir.join("a.obj")).expect("loads");
        assert_eq!(s.mesh.triangles.len(), 2);
        assert_eq!(s.materials.len(), 1);
        assert_eq!(s.materials[0].base_color_factor, Vec3::new(0.5, 0.25, 0.125));
        assert_eq!(s.materials[0].emissive_factor, Vec3::new(17.0, 12.0, 4.0));
        assert!((s.materials[0].roughness - (2.0f32 / 12.0).powf(0.25)).abs() < 1e-6);
        // Generated normals of a CCW quad seen from above point up; v was flipped.
        assert!(s.mesh.normals.iter().all(|n| (*n - Vec3::Y).length() < 1e-6));
        assert_eq!(s.mesh.uvs[0], Vec2::new(0.0, 1.0));
        assert!(s.warnings.is_empty(), "{:?}", s.warnings);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn missing_mtl_and_unknown_material_warn_and_fall_back_to_grey() {
        let dir = write_tmp("nomtl", &[("b.obj", "mtllib gone.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")]);
        let s = load_obj(&dir.join("b.obj")).expect("loads");
        assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
        assert_eq!(s.materials[0].base_color_factor, Vec3::splat(0.5));
        std::fs::remove_dir_all(&dir).ok();
    }

    fn error_of(name: &str, obj: &str) -> String {
        let dir = write_tmp(name, &[("bad.obj", obj)]);
        let e = load_obj(&dir.join("bad.obj")).expect_err("must fail").to_string();
        std::fs::remove_dir_all(&dir).ok();
        e
    }

    #[test]
    fn malformed_files_name_file_and_line() {
        let e = error_of("range", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
        assert!(e.contains("bad.obj:4:") && e.contains("out of range"), "{e}");
        let e = error_of("few", "v 0 0 0\nv 1 0 0\nf 1 2\n");
        assert!(e.contains("bad.obj:3:") && e.contains("at least 3"), "{e}");
        let e = error_of("nan", "v 0 0 0\nv nan 0 0\n");
        assert!(e.contains("bad.obj:2:") && e.contains("not finite"), "{e}");
        let e = error_of("inf", "v 0 inf 0\n");
        assert!(e.contains("bad.obj:1:") && e.contains("not finite"), "{e}");
        let e = error_of("text", "v 0 zero 0\n");
        assert!(e.contains("bad.obj:1:") && e.contains("not a number"), "{e}");
        let e = error_of("zero", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
        assert!(e.contains("bad.obj:4:"), "{e}");
        let e = error_of("empty", "# nothing\n");
        assert!(e.contains("no faces"), "{e}");
    }

    #[test]
    fn corrupt_texture_is_an_error_missing_texture_a_warning() {
        let dir = write_tmp(
            "tex",
            &[
                ("c.obj", "mtllib c.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n"),
                ("c.mtl", "newmtl m\nmap_Kd broken.png\n"),
                ("broken.png", "not a png"),
                ("d.obj", "mtllib d.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n"),
                ("d.mtl", "newmtl m\nKd 0.3 0.3 0.3\nmap_Kd -bm 1 absent.png\n"),
            ],
        );
        let e = load_obj(&dir.join("c.obj")).expect_err("corrupt texture").to_string();
        assert!(e.contains("broken.png"), "{e}");
        let s = load_obj(&dir.join("d.obj")).expect("missing texture is recoverable");
        assert!(s.warnings.iter().any(|w| w.contains("absent.png")));
        assert_eq!(s.materials[0].base_color_texture, None);
        assert_eq!(s.materials[0].base_color_factor, Vec3::splat(0.3));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn texture_names_keep_their_spaces_and_options_are_skipped() {
        assert_eq!(texture_file_name(" my texture.png"), Some("my texture.png"));
        assert_eq!(texture_file_name(" -bm 1 -s 1 1 1 stone wall.jpg"), Some("stone wall.jpg"));
        assert_eq!(texture_file_name(" -clamp on -imfchan l a.png"), Some("a.png"));
        assert_eq!(texture_file_name(" -bm 1"), Some("1"), "a lone value after an option is a name");
        assert_eq!(texture_file_name("   "), None);
    }

    #[test]
    fn latin_1_comments_and_a_byte_order_mark_are_accepted() {
        let d = std::env::temp_dir().join(format!("probegi-obj-lossy-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("mkdir");
        let mut bytes = vec![0xEF, 0xBB, 0xBF];
        bytes.extend_from_slice(b"v 0 0 0\n# caf\xE9\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        std::fs::write(d.join("t.obj"), bytes).expect("write");
        let s = load_obj(&d.join("t.obj")).expect("lenient load");
        assert_eq!(s.mesh.triangles.len(), 1, "the first vertex after the BOM is kept");
        std::fs::remove_dir_all(&d).ok();
    }
}
