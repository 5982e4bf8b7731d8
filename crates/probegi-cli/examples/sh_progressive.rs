//! Seed 001 Fig. 4–5 as a picture: a blurry environment, its static L2 SH
//! projection, and the progressive (dynamic) projection after 1, 5, 20 and 100
//! iterations of 20×20 regular samples, as latitude–longitude strips, plus the
//! per-iteration error against the static projection on stdout.
//!
//! `cargo run --release -p probegi-cli --example sh_progressive` writes
//! `out/sh-progressive.png` (rows top to bottom: environment, static, progressive
//! after 1, 5, 20, 100 iterations).

use std::f32::consts::PI;

use glam::Vec3;
use probegi_core::fibonacci::{sample_uniform_rotation, spherical_fibonacci};
use probegi_core::image::Image;
use probegi_core::sh::{ShRgb9, progressive_update};

fn env(d: Vec3) -> Vec3 {
    Vec3::new(1.0 + 0.8 * d.z, 0.5 + 0.4 * d.x * d.y, 0.3 + 0.3 * (d.x + 0.5).max(0.0))
}

fn latlong_dir(x: u32, y: u32, w: u32, h: u32) -> Vec3 {
    let phi = 2.0 * PI * (x as f32 + 0.5) / w as f32;
    let theta = PI * (y as f32 + 0.5) / h as f32;
    Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
}

fn main() -> anyhow::Result<()> {
    let n = 20_000;
    let mut stat = ShRgb9::default();
    for i in 0..n {
        let d = spherical_fibonacci(i, n);
        stat.add_sample(d, env(d), 4.0 * PI / n as f32);
    }
    let (w, h) = (128u32, 64u32);
    let rows: Vec<Box<dyn Fn(Vec3) -> Vec3>> = vec![Box::new(env), Box::new(move |d| stat.eval(d))];
    let mut snapshots = Vec::new();
    let mut prog = ShRgb9::default();
    let m = 400;
    for it in 1..=100u32 {
        let rot = sample_uniform_rotation(Vec3::new(
            (it as f32 * 0.618_034).fract(),
            (it as f32 * 0.414_213_5).fract(),
            (it as f32 * 0.732_050_8).fract(),
        ));
        let samples: Vec<(Vec3, Vec3, f32)> = (0..m)
            .map(|i| {
                let d = rot * spherical_fibonacci(i, m);
                (d, env(d), 4.0 * PI / m as f32)
            })
            .collect();
        progressive_update(&mut prog, samples, 0.05);
        let err: f32 = prog.c.iter().zip(stat.c).map(|(a, b)| (*a - b).length_squared()).sum::<f32>().sqrt();
        println!("iteration {it:3}: |c - c_static| = {err:.5}");
        if [1, 5, 20, 100].contains(&it) {
            snapshots.push(prog);
        }
    }
    let mut img = Image::new(w, h * (rows.len() + snapshots.len()) as u32);
    let mut row = 0;
    let mut paint = |f: &dyn Fn(Vec3) -> Vec3| {
        for y in 0..h {
            for x in 0..w {
                img.set(x, row * h + y, f(latlong_dir(x, y, w, h)) * 0.5);
            }
        }
        row += 1;
    };
    for f in &rows {
        paint(f.as_ref());
    }
    for s in &snapshots {
        paint(&|d| s.eval(d));
    }
    let path = std::path::Path::new("out/sh-progressive.png");
    probegi_image::write_image(path, &img)?;
    println!("wrote {}", path.display());
    Ok(())
}
