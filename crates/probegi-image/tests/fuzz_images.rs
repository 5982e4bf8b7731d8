//! A bounded mutation fuzzer over the image inputs of `probegi compare` (EXR and
//! PNG), on the stable toolchain: seed files written by this crate, mutated
//! byte-wise (flips, overwrites with extreme values, truncations, splices) by a
//! seeded PCG, each read under `catch_unwind` and, when two decode to the same
//! size, compared. Any panic fails the test. The suite runs it for
//! `PROBEGI_FUZZ_IMAGE_SECONDS` (default 5); `scripts/long-checks.sh` runs it in
//! release for 5 minutes, e.g. `PROBEGI_FUZZ_IMAGE_SECONDS=600 PROBEGI_FUZZ_SEED=3 cargo test --release
//! -p probegi-image --test fuzz_images`. Also checks that an EXR header claiming
//! more pixels than the tool reads is refused before any allocation.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use glam::Vec3;
use probegi_core::image::Image;
use probegi_core::rng::Pcg32;
use probegi_image::{compare_files, read_image, write_image};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("probegi-imgfuzz-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    d
}

fn seed_image() -> Image {
    let mut img = Image::new(7, 5);
    for (i, p) in img.pixels.iter_mut().enumerate() {
        *p = Vec3::new(i as f32 * 0.1, 1.0 / (1.0 + i as f32), (i % 3) as f32 * 2.5);
    }
    img
}

fn mutate(rng: &mut Pcg32, seed: &[u8]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.next_u32() % 4 {
        if b.is_empty() {
            break;
        }
        let at = rng.next_u32() as usize % b.len();
        match rng.next_u32() % 5 {
            0 => b[at] ^= 1 << (rng.next_u32() % 8),
            1 => b[at] = [0x00, 0xFF, 0x7F, 0x80][rng.next_u32() as usize % 4],
            2 => {
                let v = [u32::MAX, 0x7FFF_FFFF, 0x0001_0000, 0][rng.next_u32() as usize % 4].to_le_bytes();
                for (k, x) in v.iter().enumerate() {
                    if at + k < b.len() {
                        b[at + k] = *x;
                    }
                }
            }
            3 => b.truncate(at),
            _ => {
                let from = rng.next_u32() as usize % b.len();
                let len = (rng.next_u32() as usize % 16).min(b.len() - from);
                let chunk: Vec<u8> = b[from..from + len].to_vec();
                b.splice(at..at, chunk);
            }
        }
    }
    b
}

#[test]
fn image_inputs_survive_mutation_without_panicking() {
    let d = dir("run");
    let seed_img = seed_image();
    let (exr, png) = (d.join("seed.exr"), d.join("seed.png"));
    write_image(&exr, &seed_img).expect("exr");
    write_image(&png, &seed_img).expect("png");
    let seeds = [("exr", std::fs::read(&exr).expect("read")), ("png", std::fs::read(&png).expect("read"))];
    let secs = std::env::var("PROBEGI_FUZZ_IMAGE_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(5u64);
    let seed = std::env::var("PROBEGI_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(1u64);
    let mut rng = Pcg32::new(seed, 17);
    let start = Instant::now();
    let (mut runs, mut decoded, mut panics) = (0u64, 0u64, vec![]);
    // Quiet the default hook: panics are collected and reported once.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    while start.elapsed() < Duration::from_secs(secs) {
        let (ext, bytes) = &seeds[(runs % 2) as usize];
        let input = mutate(&mut rng, bytes);
        let path = d.join(format!("m.{ext}"));
        std::fs::write(&path, &input).expect("write");
        let other = if *ext == "exr" { &exr } else { &png };
        let outcome = std::panic::catch_unwind(|| {
            let ok = read_image(&path).is_ok();
            // `compare` on the pair: a mutated file against its intact seed.
            let _ = compare_files(other, &path, None);
            ok
        });
        match outcome {
            Ok(ok) => decoded += ok as u64,
            Err(_) => panics.push((ext.to_string(), input)),
        }
        runs += 1;
    }
    std::panic::set_hook(hook);
    eprintln!(
        "fuzzed {runs} image inputs in {secs} s (seed {seed}): {decoded} still decoded, {} panicked",
        panics.len()
    );
    assert!(runs > 200, "only {runs} inputs ran");
    if let Some((ext, input)) = panics.first() {
        let keep = d.join(format!("panic.{ext}"));
        std::fs::write(&keep, input).expect("keep");
        panic!("{} inputs panicked; the first is kept at {}", panics.len(), keep.display());
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn an_exr_header_claiming_a_huge_image_is_refused_before_allocating() {
    let d = dir("huge");
    let path = d.join("huge.exr");
    // 16 × 16 pixels as written, then the data window rewritten to 100 000 × 100 000.
    let mut img = Image::new(16, 16);
    img.pixels.iter_mut().for_each(|p| *p = Vec3::ONE);
    write_image(&path, &img).expect("exr");
    let mut bytes = std::fs::read(&path).expect("read");
    let key = b"dataWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).expect("dataWindow attribute") + key.len() + 4;
    // box2i: xMin, yMin, xMax, yMax.
    for (k, v) in [0i32, 0, 99_999, 99_999].iter().enumerate() {
        bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    let key = b"displayWindow\0box2i\0";
    if let Some(p) = bytes.windows(key.len()).position(|w| w == key) {
        let at = p + key.len() + 4;
        for (k, v) in [0i32, 0, 99_999, 99_999].iter().enumerate() {
            bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(&path, bytes).expect("write");
    let Err(e) = read_image(&path) else { panic!("a 100 000 × 100 000 header must be refused") };
    let e = e.to_string();
    assert!(e.contains("huge.exr") && (e.contains("more than this tool reads") || e.contains("100000")), "{e}");
    std::fs::remove_dir_all(&d).ok();
}
