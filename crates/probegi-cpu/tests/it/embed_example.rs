//! Runs `examples/embed_ddgi.rs` (an application driving the field-set seam with
//! its own triangles, ray caster and shading) as part of the suite: it fails when
//! the white furnace misses E = π·Le/(1−ρ) by more than 3 %.

#[path = "../../examples/embed_ddgi.rs"]
mod embed_ddgi;

#[test]
fn the_embedding_example_converges_to_the_furnace_irradiance() {
    embed_ddgi::main().expect("embed_ddgi");
}
