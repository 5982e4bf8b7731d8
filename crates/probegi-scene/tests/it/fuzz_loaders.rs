//! A bounded mutation fuzzer over every scene loader (OBJ + MTL, glTF, GLB, TOML),
//! on the stable toolchain: seeds (small hand-made files and the shared
//! CornellBox-Original), mutated byte-wise and number-wise by a seeded PCG, each
//! result loaded under `catch_unwind`. Any panic fails the test and prints the
//! inputs that caused it. The suite runs it for `PROBEGI_FUZZ_SECONDS` (default 10 in
//! all); `scripts/long-checks.sh` runs it in release for 10 minutes, and any
//! budget and seed can be given, e.g. `PROBEGI_FUZZ_SECONDS=1800
//! PROBEGI_FUZZ_SEED=7 cargo test --release -p probegi-scene --test it fuzz_loaders::`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use probegi_core::rng::Pcg32;
use probegi_scene::load_scene;

const OBJ: &str = "mtllib m.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n\
vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1 3 4\ng box\no thing\ns 1\nf -4 -3 -2 -1\n";
const MTL: &str = "newmtl red\nKd 0.8 0.1 0.1\nKs 0.5 0.5 0.5\nNs 40\nKe 0 0 0\nmap_Kd -bm 1 tex.png\n\
newmtl light\nKe 10 10 10\nnewmtl leaf\nd 0.9\nmap_d tex.png\nbump -bm 0.5 tex.png\n";
const TOML: &str = "sky_radiance = [0.2, 0.2, 0.25]\nframes_per_second = 30\n[[meshes]]\npath = \"q.obj\"\n\
translation = [0, 1, 0]\nrotation_deg = [0, 45, 0]\nscale = [1, 2, 1]\nnormals = \"smooth\"\ncrease_angle_deg = 40\n\
[[instances]]\npath = \"q.obj\"\nscale = [0.5, 0.5, 0.5]\ntransforms = [{ translation = [3, 0, 0] }]\n\
grid = { count = [3, 2], spacing_m = [2, 2], jitter_m = 0.5, random_yaw = true, scale_range = [0.5, 1.5], seed = 4 }\n[[objects]]\nbox_min_m = [0, 0, 0]\n\
box_max_m = [1, 1, 1]\nalbedo = [0.5, 0.5, 0.5]\nkeyframes = [{ frame = 0, translation = [0, 0, 0] }, \
{ frame = 10, translation = [1, 0, 0], rotation_deg = [0, 90, 0] }]\n[[lights]]\nkind = \"point\"\n\
position = [0, 2, 0]\nintensity = 5.0\nkeyframes = [{ frame = 0, intensity = 5.0 }, { frame = 5, intensity = 0.0 }]\n\
[camera]\nposition = [0, 1, 5]\ntarget = [0, 1, 0]\nfov_y_deg = 60.0\n[volume]\nprobe_counts = [4, 4, 4]\n";

/// A quad (4 float positions, 6 u16 indices) and a 2-key translation animation
/// (2 float times, 2 float VEC3 values), 92 bytes.
fn buffer() -> Vec<u8> {
    let mut b = Vec::new();
    let floats = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
    floats.iter().for_each(|f| b.extend_from_slice(&f.to_le_bytes()));
    [0u16, 1, 2, 0, 2, 3].iter().for_each(|i| b.extend_from_slice(&i.to_le_bytes()));
    [0.0f32, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0].iter().for_each(|f| b.extend_from_slice(&f.to_le_bytes()));
    b
}

fn gltf_json(uri: Option<&str>) -> String {
    let uri = uri.map(|u| format!("\"uri\": \"{u}\", ")).unwrap_or_default();
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
"nodes": [{{"children": [1], "translation": [0, 1, 0]}}, {{"mesh": 0, "scale": [2, 2, 2], "rotation": [0, 0, 0, 1]}}],
"meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
"materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": [0.2, 0.4, 0.6, 1], "metallicFactor": 0.5, "roughnessFactor": 0.3}}, "emissiveFactor": [1, 1, 1], "alphaMode": "MASK", "alphaCutoff": 0.4}}],
"animations": [{{"channels": [{{"sampler": 0, "target": {{"node": 0, "path": "translation"}}}}],
  "samplers": [{{"input": 2, "output": 3, "interpolation": "LINEAR"}}]}}],
"buffers": [{{{uri}"byteLength": 92}}],
"bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 48}}, {{"buffer": 0, "byteOffset": 48, "byteLength": 12}},
  {{"buffer": 0, "byteOffset": 60, "byteLength": 8}}, {{"buffer": 0, "byteOffset": 68, "byteLength": 24}}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
  {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}},
  {{"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]}},
  {{"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC3"}}]}}"#
    )
}

fn glb() -> Vec<u8> {
    let mut json = gltf_json(None).into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let bin = buffer();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut g = Vec::new();
    g.extend_from_slice(b"glTF");
    g.extend_from_slice(&2u32.to_le_bytes());
    g.extend_from_slice(&(total as u32).to_le_bytes());
    g.extend_from_slice(&(json.len() as u32).to_le_bytes());
    g.extend_from_slice(b"JSON");
    g.extend_from_slice(&json);
    g.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    g.extend_from_slice(b"BIN\0");
    g.extend_from_slice(&bin);
    g
}

fn base64(data: &[u8]) -> String {
    const T: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            s.push(if k <= c.len() { T[(n >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    s
}

/// Numbers that break naive code: zero, signs, limits, overflow, NaN spellings.
const INTERESTING: [&str; 14] =
    ["0", "-1", "1", "3", "255", "65535", "4294967295", "99999999999", "1e39", "-1e39", "1e20", "nan", "inf", "0.0001"];

fn mutate(seed: &[u8], rng: &mut Pcg32) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.next_u32() % 4 {
        let len = b.len().max(1);
        let at = rng.next_u32() as usize % len;
        match rng.next_u32() % 6 {
            0 if !b.is_empty() => b[at] = rng.next_u32() as u8,
            1 => {
                // Replace the number at or after `at` with an interesting one.
                let Some(start) = (at..b.len()).find(|&i| b[i].is_ascii_digit()) else { continue };
                let end = (start..b.len()).find(|&i| !(b[i].is_ascii_digit() || b[i] == b'.')).unwrap_or(b.len());
                let pick = INTERESTING[rng.next_u32() as usize % INTERESTING.len()];
                b.splice(start..end, pick.bytes());
            }
            2 if !b.is_empty() => {
                let n = (rng.next_u32() as usize % 16).min(b.len() - at);
                b.drain(at..at + n);
            }
            3 if !b.is_empty() => {
                let n = (rng.next_u32() as usize % 32).min(b.len() - at);
                let chunk: Vec<u8> = b[at..at + n].to_vec();
                let to = rng.next_u32() as usize % len;
                b.splice(to..to, chunk);
            }
            4 => b.truncate(at),
            _ if !b.is_empty() => {
                // Binary fields: overwrite 4 bytes with a little-endian extreme.
                let v = [0u32, 1, 3, 0xFFFF, 0xFFFF_FFFF, 0x7FFF_FFFF, 0x8000_0000][rng.next_u32() as usize % 7];
                for (k, byte) in v.to_le_bytes().iter().enumerate() {
                    if at + k < b.len() {
                        b[at + k] = *byte;
                    }
                }
            }
            _ => {}
        }
    }
    b
}

struct Target {
    /// The file that is mutated and loaded.
    file: &'static str,
    seed: Vec<u8>,
    /// Files written unmutated beside it.
    extra: Vec<(&'static str, Vec<u8>)>,
}

fn targets() -> Vec<Target> {
    let shared = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/cornell-box");
    let cornell = std::fs::read(shared.join("CornellBox-Original.obj")).expect("shared CornellBox-Original.obj");
    let cornell_mtl = std::fs::read(shared.join("CornellBox-Original.mtl")).expect("its MTL");
    let data_uri = format!("data:application/octet-stream;base64,{}", base64(&buffer()));
    vec![
        Target { file: "q.obj", seed: OBJ.into(), extra: vec![("m.mtl", MTL.into())] },
        Target {
            file: "CornellBox-Original.obj",
            seed: cornell,
            extra: vec![("CornellBox-Original.mtl", cornell_mtl)],
        },
        Target { file: "q.obj", seed: OBJ.into(), extra: vec![] }.with_mutated_mtl(),
        Target { file: "s.gltf", seed: gltf_json(Some(&data_uri)).into(), extra: vec![] },
        Target { file: "e.gltf", seed: gltf_json(Some("e.bin")).into(), extra: vec![("e.bin", buffer())] },
        Target { file: "g.glb", seed: glb(), extra: vec![] },
        Target { file: "t.toml", seed: TOML.into(), extra: vec![("q.obj", OBJ.into()), ("m.mtl", MTL.into())] },
    ]
}

impl Target {
    /// The MTL is the mutated file; a fixed OBJ names it.
    fn with_mutated_mtl(self) -> Self {
        Target { file: "m.mtl", seed: MTL.into(), extra: vec![("q.obj", OBJ.into())] }
    }
}

fn load_target(dir: &Path, t: &Target) -> std::thread::Result<()> {
    let entry = if t.file.ends_with(".mtl") { "q.obj" } else { t.file };
    let spec = dir.join(entry).to_string_lossy().into_owned();
    std::panic::catch_unwind(|| {
        let _ = load_scene(&spec);
    })
}

#[test]
fn loaders_survive_mutated_inputs_without_panicking() {
    let budget = std::env::var("PROBEGI_FUZZ_SECONDS").ok().and_then(|v| v.parse().ok()).unwrap_or(10.0f64);
    let seed = std::env::var("PROBEGI_FUZZ_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1u64);
    let targets = targets();
    let dir = std::env::temp_dir().join(format!("probegi-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("mkdir");
    // Every seed loads as it is (so mutations start from valid files).
    for t in &targets {
        for (name, data) in &t.extra {
            std::fs::write(dir.join(name), data).expect("write");
        }
        std::fs::write(dir.join(t.file), &t.seed).expect("write");
        let spec = dir.join(if t.file.ends_with(".mtl") { "q.obj" } else { t.file });
        if let Err(e) = load_scene(&spec.to_string_lossy()) {
            panic!("seed {} does not load: {e}", t.file);
        }
    }
    // Silence the panics this thread catches, not those of the binary's other
    // tests running beside it (their failures must still print).
    let fuzz_thread = std::thread::current().id();
    let others = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if std::thread::current().id() != fuzz_thread {
            others(info)
        }
    }));
    let mut rng = Pcg32::new(seed, 0xf022);
    let (mut runs, mut panics) = (vec![0u64; targets.len()], Vec::new());
    let per_target = Duration::from_secs_f64(budget / targets.len() as f64);
    for (k, t) in targets.iter().enumerate() {
        for (name, data) in &t.extra {
            std::fs::write(dir.join(name), data).expect("write");
        }
        let start = Instant::now();
        while start.elapsed() < per_target {
            let input = mutate(&t.seed, &mut rng);
            std::fs::write(dir.join(t.file), &input).expect("write");
            runs[k] += 1;
            if load_target(&dir, t).is_err() && panics.len() < 20 {
                let kept = dir.join(format!("panic-{}-{}", runs[k], t.file));
                std::fs::write(&kept, &input).expect("keep the input");
                panics.push(kept);
            }
        }
    }
    let _ = std::panic::take_hook();
    let total: u64 = runs.iter().sum();
    eprintln!(
        "fuzzed {total} inputs in {budget} s (seed {seed}): {}; {} panicked",
        targets.iter().zip(&runs).map(|(t, n)| format!("{} {n}", t.file)).collect::<Vec<_>>().join(", "),
        panics.len()
    );
    assert!(panics.is_empty(), "inputs that panicked (kept): {panics:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn crafted_gltf_attacks_are_errors_that_name_the_file() {
    let dir = std::env::temp_dir().join(format!("probegi-gltf-attacks-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(dir.join("e.bin"), buffer()).expect("write");
    let base = gltf_json(Some("e.bin"));
    let cases = [
        ("cycle", base.replace(r#"{"mesh": 0, "scale""#, r#"{"mesh": 0, "children": [0], "scale""#), "ancestor"),
        (
            "stride",
            base.replace(
                r#""byteOffset": 0, "byteLength": 48"#,
                r#""byteOffset": 0, "byteLength": 48, "byteStride": 4"#,
            ),
            "byteStride",
        ),
        ("float-indices", base.replace(r#""componentType": 5123"#, r#""componentType": 5126"#), "indices"),
        ("short-indices", base.replace(r#""componentType": 5123"#, r#""componentType": 5122"#), "indices"),
        ("node-target", base.replace(r#""target": {"node": 0"#, r#""target": {"node": 9"#), "node"),
        ("accessor-range", base.replace(r#""POSITION": 0"#, r#""POSITION": 7"#), "s"),
        ("overrun", base.replace(r#""count": 4, "type": "VEC3""#, r#""count": 400, "type": "VEC3""#), "elements"),
    ];
    for (name, json, expect) in cases {
        assert_ne!(json, base, "{name}: the edit must apply");
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(&path, json).expect("write");
        let e = load_scene(&path.to_string_lossy()).expect_err(name).to_string();
        assert!(e.contains(&format!("{name}.gltf")) && e.contains(expect), "{name}: {e}");
    }
    // A missing external buffer is named.
    std::fs::write(dir.join("nobin.gltf"), base.replace("e.bin", "missing%20file.bin")).expect("write");
    let e = load_scene(&dir.join("nobin.gltf").to_string_lossy()).expect_err("missing bin").to_string();
    assert!(e.contains("nobin.gltf") && e.contains("missing file.bin") && e.contains("not found"), "{e}");
    // A GLB header claiming 4 GiB in a small file is refused before any allocation.
    let mut g = glb();
    g[8..12].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    std::fs::write(dir.join("huge.glb"), g).expect("write");
    let e = load_scene(&dir.join("huge.glb").to_string_lossy()).expect_err("huge").to_string();
    assert!(e.contains("huge.glb") && e.contains("header"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
