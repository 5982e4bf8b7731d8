//! A cubemap the host cannot read (block-compressed, or texels only on the
//! device) becomes the field's sky map on the device
//! (`probegi_wgpu::sky_from_cubemap`), by the lookup the host's twin
//! (`environment_sky::equirect_from_cubemap`) makes it with: on one
//! `Rgba32Float` cube that both can read, turned by a rotation, the two maps
//! must hold the same texels.
//!
//! Error analysis: both take the nearest cube texel along the same direction;
//! the device's `sin`/`cos` differ from the host's by a few ULPs, which moves
//! a lookup across a texel edge only where the direction lies within ~10⁻⁶
//! of a texel of the face's width from it. On a 16-texel face that is far
//! below one map texel in a thousand; a lookup that does cross reads the
//! neighbour, a different value here (every texel differs). So: at most 1 %
//! of the texels may differ, and every other one is equal to 10⁻⁶.

use std::sync::Arc;

use bevy::asset::RenderAssetUsages;
use bevy::image::Image;
use bevy::math::Quat;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use probegi_bevy::environment_sky::{device_sky_placeholder, equirect_from_cubemap, to_cube};
use probegi_wgpu::sky_from_cubemap::GpuSkyFromCubemap;
use probegi_wgpu::{GpuContext, wgpu};

const FACE: u32 = 16;

/// Six faces of `FACE`² texels, each texel its own colour (RGBA f32 bytes).
fn cube_bytes() -> Vec<u8> {
    let texel = |l: u32, x: u32, y: u32| {
        let k = (l * FACE + y) * FACE + x;
        [(k % 7) as f32 + 0.25 * l as f32, (k % 11) as f32 * 0.5, (k % 13) as f32 + 0.125 * y as f32, 1.0]
    };
    (0..6)
        .flat_map(|l| (0..FACE).flat_map(move |y| (0..FACE).map(move |x| texel(l, x, y))))
        .flat_map(|c| c.into_iter().flat_map(f32::to_le_bytes))
        .collect()
}

/// The same cube as a texture on `ctx`'s device.
fn cube_texture(ctx: &GpuContext, bytes: &[u8]) -> wgpu::Texture {
    let size = wgpu::Extent3d { width: FACE, height: FACE, depth_or_array_layers: 6 };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("test sky cube"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let layout = wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(FACE * 16), rows_per_image: Some(FACE) };
    ctx.queue.write_texture(texture.as_image_copy(), bytes, layout, size);
    texture
}

#[test]
fn the_device_makes_the_sky_map_the_host_makes() {
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let bytes = cube_bytes();
    let size = Extent3d { width: FACE, height: FACE, depth_or_array_layers: 6 };
    let image =
        Image::new(size, TextureDimension::D2, bytes.clone(), TextureFormat::Rgba32Float, RenderAssetUsages::default());
    let rotation = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.3);
    let host = equirect_from_cubemap(&image, rotation, "test sky").expect("the host reads Rgba32Float");
    // The device's: a scene with the black placeholder, written by the pass.
    let placeholder = device_sky_placeholder(&image, "test sky").expect("a cubemap");
    assert_eq!(placeholder.size(), host.size(), "the placeholder is the host map's size");
    let mut scene = probegi_scene::load_scene("builtin:cornell-box").expect("built in");
    scene.sky_map = Some(probegi_scene::SkyMap::new(Arc::new(placeholder)));
    let gpu_scene = probegi_wgpu::gpu_scene::GpuScene::upload(&ctx, &scene).expect("uploads");
    let pass = GpuSkyFromCubemap::new(&ctx);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    pass.record(&ctx, &mut encoder, &cube_texture(&ctx, &bytes), to_cube(rotation), &gpu_scene).expect("records");
    ctx.submit(encoder.finish());
    let device = gpu_scene.sky_map_texels(&ctx).expect("reads back").expect("a map");
    assert_eq!(device.len(), host.texels().len());
    assert!(host.texels().iter().map(|t| t.x + t.y + t.z).sum::<f32>() > 1.0, "the map is not black");
    let differ = host.texels().iter().zip(&device).filter(|(a, b)| !a.abs_diff_eq(**b, 1e-6)).count();
    let (w, h) = host.size();
    eprintln!("{differ} of {w}×{h} texels differ between the host's and the device's map");
    assert!(differ * 100 <= device.len(), "{differ} of {} texels differ", device.len());
}

/// A BC6H (unsigned) block of one colour: mode 11 (10-bit endpoints, one
/// region), both endpoints `c`, every index 0 (D3D11's BC6H layout).
fn bc6h_constant_block(c: [u16; 3]) -> [u8; 16] {
    let mut bits: u128 = 0b00011;
    for (i, v) in c.iter().chain(c.iter()).enumerate() {
        bits |= (*v as u128 & 0x3ff) << (5 + 10 * i);
    }
    bits.to_le_bytes()
}

/// What a BC6H unsigned decoder gives for a 10-bit endpoint `c` at index 0:
/// the endpoint unquantised to 16 bits, then scaled by 31/64 into a half.
fn bc6h_value(c: u16) -> f32 {
    let unquantised = (((c as u32) << 16) + 0x8000) >> 10;
    probegi_bevy::environment_sky::half_to_f32(((unquantised * 31) >> 6) as u16)
}

#[test]
fn a_block_compressed_skybox_lights_an_open_floor_through_the_field() {
    use bevy::prelude::*;
    use bevy::render::RenderApp;
    use probegi_bevy::field_on_bevy_device::ProbegiRenderField;
    use probegi_bevy::{ProbegiPlugin, ProbegiScene, ProbegiSky};
    // The sky furnace of `field_on_bevy_device` with a BC6H skybox, which
    // the host cannot read: the device makes the map, and the floor's E is
    // π L × brightness once the blend has converged (within 1 %).
    let plugin = ProbegiPlugin { sky: ProbegiSky::Radiance(Vec3::ZERO), seed: 11 };
    let Some(mut app) = crate::field_on_bevy_device::render_app_with(plugin) else { return };
    let device_features = app.world().resource::<bevy::render::renderer::RenderDevice>().features();
    if !device_features.contains(bevy::render::settings::WgpuFeatures::TEXTURE_COMPRESSION_BC) {
        assert!(std::env::var("PROBEGI_REQUIRE_GPU").is_err(), "PROBEGI_REQUIRE_GPU is set but the device has no BC");
        eprintln!("warning: SKIP: the device samples no BC6H");
        return;
    }
    let c = [300u16, 420, 512];
    let radiance = glam::Vec3::new(bc6h_value(c[0]), bc6h_value(c[1]), bc6h_value(c[2]));
    let face = 16u32;
    let blocks = (face / 4) * (face / 4) * 6;
    let data: Vec<u8> = (0..blocks).flat_map(|_| bc6h_constant_block(c)).collect();
    let image = crate::extract::cube_image(face, TextureFormat::Bc6hRgbUfloat, data);
    crate::field_on_bevy_device::sky_furnace_frames(&mut app, image, 40);
    let s = app.world().resource::<ProbegiScene>();
    assert!(s.sky_error.is_none(), "{:?}", s.sky_error);
    assert!(s.sky_on_device.is_some(), "the device makes the map of a BC6H cube");
    // The sky pass joins the frame's one submission, with no wait.
    let counters = |app: &App| {
        let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
        rf.field.as_ref().expect("a field").tracer.ctx.counters()
    };
    let before = counters(&app);
    for _ in 0..3 {
        app.update();
    }
    let d = counters(&app) - before;
    assert_eq!((d.submissions, d.blocking_waits), (3, 0), "one submission a frame, no wait, with the sky pass");
    let render_world = app.sub_app_mut(RenderApp).world_mut();
    let mut rf = render_world.resource_mut::<ProbegiRenderField>();
    assert!(rf.error.is_none(), "{:?}", rf.error);
    let field = rf.field.as_mut().expect("a field on Bevy's device");
    let (_, gpu_scene) = field.tracer.shading().expect("the device shades");
    let texels = gpu_scene.sky_map_texels(&field.tracer.ctx).expect("reads back").expect("a map");
    assert!(texels.iter().all(|t| t.abs_diff_eq(radiance, 1e-6)), "every texel is the block's colour {radiance}");
    field.set.sync_host_atlases(Some(&field.tracer)).expect("read the atlases back");
    let want = radiance * 2.0 * std::f32::consts::PI;
    for p in [glam::Vec3::ZERO, glam::Vec3::new(1.0, 0.0, -0.7)] {
        let e = field.set.irradiance(p, glam::Vec3::Y, glam::Vec3::Y);
        assert!((e - want).abs().max_element() < 0.01 * want.max_element(), "E at {p}: {e}, want {want}");
    }
}

#[test]
fn a_cube_the_device_cannot_read_either_is_an_error_naming_it() {
    // An integer cube: neither the host nor the device pass reads it as radiance.
    let size = Extent3d { width: 4, height: 4, depth_or_array_layers: 6 };
    let bytes = vec![7u8; 4 * 4 * 6 * 4];
    let image = Image::new(size, TextureDimension::D2, bytes, TextureFormat::Rgba8Uint, RenderAssetUsages::default());
    assert!(!probegi_bevy::environment_sky::host_reads(&image));
    let e = device_sky_placeholder(&image, "camera 3's sky").expect_err("no float format");
    assert!(e.starts_with("camera 3's sky:") && e.contains("Rgba8Uint"), "{e}");
    // A 3D texture of six slices is no cubemap either.
    let mut image = Image::new(
        size,
        TextureDimension::D3,
        vec![0u8; 4 * 4 * 6 * 8],
        TextureFormat::Rgba16Float,
        RenderAssetUsages::default(),
    );
    image.texture_descriptor.dimension = TextureDimension::D3;
    assert!(device_sky_placeholder(&image, "a volume").is_err());
}
