//! Runs `examples/wgpu_embed.rs` (an application with its own device, triangles,
//! shading and shader, driving a DDGI volume through the seam with the library's
//! GPU trace and lighting its image with the included WGSL query) as part of the
//! suite. It fails when its shader's field term differs from the CPU query, a
//! pixel is non-finite, or the walls bleed no colour onto the floor.

#[path = "../../examples/wgpu_embed.rs"]
#[allow(dead_code)]
mod wgpu_embed;

#[test]
fn the_wgpu_embedding_example_draws_what_the_cpu_query_says() {
    // The same skip rule as the other GPU tests.
    if probegi_wgpu::GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set").is_none() {
        return;
    }
    let out = std::env::temp_dir().join(format!("probegi-wgpu-embed-{}.png", std::process::id()));
    wgpu_embed::main_to(&out).expect("wgpu_embed");
    assert!(std::fs::metadata(&out).map(|m| m.len() > 1000).unwrap_or(false), "a PNG was written");
}
