//! The trace pass on the GPU: obvhs's compressed-wide BVH (Ylitie et al. 2017),
//! built on the CPU by `probegi_scene::BvhTracer` and uploaded as it is
//! ([`probegi_scene::BvhExport`]), traversed in a compute shader
//! (`shaders/bvh.wgsl`, `shaders/trace_rays.wgsl`), so the trace runs on every
//! adapter, software ones included, with no ray-query hardware. Closest-hit and
//! any-hit queries, both faces, alpha cutouts tested inside the traversal as on
//! the CPU (`probegi_scene::bvh`). The same tree, the same node order, the same
//! Möller–Trumbore test: hits agree with the CPU's up to float rounding
//! (`tests/it/trace_equivalence.rs`).
//!
//! Moving objects and instanced meshes are traced through the CPU's two
//! levels: every bottom level is uploaded once, and the top level (a CWBVH over
//! instance bounds that the host rebuilds each frame, `TlasLayout::export_at`)
//! is rewritten by [`GpuBvh::place`]; `bvh.wgsl` walks both in one loop.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};
use probegi_scene::{BvhExport, RayHit, TlasExport, TraceGuardCounts};

use crate::gpu_context::{GpuContext, GpuError, buffers_bind_group, storage_entry};
use crate::shader_registry::{BVH_INSTANCE_IDENTITY, BVH_INSTANCE_MOVING, BVH_STORAGE_BUFFERS, TRACE_RAYS};

/// The trace pass's uniform block; must match `TraceParams` in `trace_rays.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct TraceParams {
    pub(crate) ray_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) any_hit: u32,
    /// `bvh.wgsl`'s `BVH_INSTANCE_*` flags of instances left out.
    pub(crate) skip: u32,
    /// Entries of `segments` in use.
    pub(crate) segment_count: u32,
    pub(crate) _pad: [u32; 3],
    /// [`TraceSegment`]s as (first ray, probes, rays per probe, 0).
    pub(crate) segments: [[u32; 4]; TRACE_MAX_SEGMENTS],
}
const _: () = assert!(std::mem::size_of::<TraceParams>() == 160);

/// Most [`TraceSegment`]s a batch's trace orders (one per volume of a field
/// set; a batch with more traces the rest in batch order).
pub const TRACE_MAX_SEGMENTS: usize = 8;

/// Rays `first_ray..first_ray + probe_count × rays_per_probe` of a batch, stored
/// probe-major: the trace runs them direction-major instead, neighbouring
/// threads tracing the same direction from neighbouring probes
/// (`trace_rays.wgsl`'s thread order). Hits are unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraceSegment {
    /// The segment's first ray in the batch.
    pub first_ray: u32,
    /// Probes in the segment, consecutive.
    pub probe_count: u32,
    /// Rays each probe casts, consecutive per probe.
    pub rays_per_probe: u32,
}

/// One ray; must match `GpuRay` in `trace_rays.wgsl` (vec3 + f32, twice).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuRay {
    /// Origin (world space, m).
    pub origin: [f32; 3],
    /// Hits nearer than this are ignored.
    pub t_min: f32,
    /// Unit direction.
    pub dir: [f32; 3],
    /// `+∞` is stored as `f32::MAX` ([`GpuRay::new`]); a NaN stays NaN (a
    /// miss under the ray rule of `bvh.wgsl`).
    pub t_max: f32,
}
const _: () = assert!(std::mem::size_of::<GpuRay>() == 32);

impl GpuRay {
    /// A ray from `origin` along unit `dir`, hits between `t_min` and `t_max`.
    pub fn new(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Self {
        // Only +∞ becomes f32::MAX: a NaN stays NaN, for the ray rule to refuse.
        let t_max = if t_max == f32::INFINITY { f32::MAX } else { t_max };
        Self { origin: origin.into(), t_min, dir: dir.into(), t_max }
    }
}

/// One ray's result; must match `GpuRayHit` in `trace_rays.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuRayHit {
    /// Hit distance; the ray's `t_max` for a miss.
    pub t: f32,
    /// Scene triangle with bit 31 set on a back face; `u32::MAX` for a miss.
    pub triangle: u32,
    /// Weights of vertices 1 and 2.
    pub bary: [f32; 2],
    /// `Scene::instances` index (`RayHit::instance`), `u32::MAX` for the scene's own mesh.
    pub instance: u32,
    /// Keeps the 8-byte alignment of `bary` (always 0).
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<GpuRayHit>() == 24);

impl GpuRayHit {
    /// Whether the ray hit a triangle.
    pub fn is_hit(&self) -> bool {
        self.triangle != u32::MAX
    }

    /// The CPU tracer's record of the same hit.
    pub fn ray_hit(&self) -> Option<RayHit> {
        self.is_hit().then(|| RayHit {
            t: self.t,
            triangle: self.triangle & 0x7fff_ffff,
            barycentric: Vec2::from(self.bary),
            backface: self.triangle & 0x8000_0000 != 0,
            instance: self.instance,
        })
    }
}

/// Largest workgroup count per dispatch dimension (WebGPU's default limit).
const MAX_GROUPS: u32 = 65_535;
const WORKGROUP: u32 = 64;

/// The bind-group layout of `bvh.wgsl` (`BVH_GROUP`): `BVH_STORAGE_BUFFERS`
/// storage buffers, all read-only but the last (`bvh_guards`).
pub(crate) fn bvh_bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let entries: Vec<_> = (0..BVH_STORAGE_BUFFERS).map(|b| storage_entry(b, b + 1 < BVH_STORAGE_BUFFERS)).collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("bvh"), entries: &entries })
}

/// A scene's BVH on the device, with its bind group (`bvh.wgsl`'s group,
/// `shader_registry::BVH_GROUP`).
pub struct GpuBvh {
    /// Nodes of the bottom levels.
    pub node_count: usize,
    /// Leaf triangles (each leaf's triangles, in the tree's order).
    pub leaf_count: usize,
    /// Triangles with an alpha cutout.
    pub cut_triangle_count: usize,
    /// Instances of the top level (0: none, rays go straight to the bottom level).
    pub instance_count: usize,
    bytes: u64,
    bind_group: wgpu::BindGroup,
    nodes: wgpu::Buffer,
    instances: wgpu::Buffer,
    /// `bvh_guards`: rays refused and walks cut short (`bvh.wgsl`).
    guards: wgpu::Buffer,
    /// First node of the top level's region and the nodes it may hold.
    tlas_base: u32,
    tlas_capacity: u32,
}

/// `bvh_instances` of `bvh.wgsl` for `tlas`, whose root is node `tlas_base`.
fn pack_instances(tlas: &TlasExport, blas_roots: &[u32], tlas_base: u32) -> Result<Vec<[f32; 4]>, GpuError> {
    let bits = f32::from_bits;
    let mut out = vec![[bits(tlas.instances.len() as u32), bits(tlas_base), 0.0, 0.0]];
    for inst in &tlas.instances {
        let root = *blas_roots.get(inst.blas as usize).ok_or_else(|| {
            GpuError::Input(format!("a top-level instance names bottom level {} of {}", inst.blas, blas_roots.len()))
        })?;
        let flags = match inst.local_from_world {
            None => BVH_INSTANCE_IDENTITY,
            Some(_) => 0,
        } | if inst.moving { BVH_INSTANCE_MOVING } else { 0 };
        let m = inst.local_from_world.unwrap_or(glam::Affine3A::IDENTITY);
        if !(m.matrix3.is_finite() && m.translation.is_finite()) {
            return Err(GpuError::Input("a top-level instance has a non-finite transform".into()));
        }
        let col = |c: glam::Vec3A, w: u32| [c.x, c.y, c.z, bits(w)];
        out.push(col(m.matrix3.x_axis, root));
        out.push(col(m.matrix3.y_axis, inst.scene_instance));
        out.push(col(m.matrix3.z_axis, flags));
        out.push(col(m.translation, 0));
    }
    Ok(out)
}

/// An error unless `words` is whole 20-word nodes.
fn check_node_words(words: &[u32], what: &str) -> Result<(), GpuError> {
    if !words.len().is_multiple_of(20) {
        return Err(GpuError::Input(format!("BVH export: {what} hold {} words, not whole 20-word nodes", words.len())));
    }
    Ok(())
}

/// A top level's node words with their child indices moved to start at `tlas_base`.
fn rebased_tlas_nodes(tlas: &TlasExport, tlas_base: u32) -> Vec<u32> {
    let mut words = tlas.node_words.clone();
    for node in words.chunks_exact_mut(20) {
        node[4] = node[4].wrapping_add(tlas_base);
    }
    words
}

/// `bvh_triangles` of `bvh.wgsl` (one zero vec4 for an empty tree), after
/// checking that `export`'s per-leaf arrays agree.
fn pack_leaf_triangles(export: &BvhExport) -> Result<Vec<[f32; 4]>, GpuError> {
    check_node_words(&export.node_words, "the bottom levels")?;
    if let Some(t) = &export.tlas {
        check_node_words(&t.node_words, "the top level")?;
    }
    let leaves = export.leaf_triangles.len();
    if export.leaf_triangle_ids.len() != leaves
        || (!export.leaf_cutouts.is_empty() && export.leaf_cutouts.len() != leaves)
    {
        return Err(GpuError::Input(format!(
            "BVH export: {leaves} leaf triangles, {} ids, {} cutout entries",
            export.leaf_triangle_ids.len(),
            export.leaf_cutouts.len()
        )));
    }
    let mut triangles: Vec<[f32; 4]> = Vec::with_capacity(leaves * 4);
    for (k, t) in export.leaf_triangles.iter().enumerate() {
        let id = f32::from_bits(export.leaf_triangle_ids[k]);
        let cut = f32::from_bits(export.leaf_cutouts.get(k).copied().unwrap_or(u32::MAX));
        triangles.push([t[0].x, t[0].y, t[0].z, id]);
        triangles.push([t[1].x, t[1].y, t[1].z, cut]);
        triangles.push([t[2].x, t[2].y, t[2].z, 0.0]);
        triangles.push([t[3].x, t[3].y, t[3].z, 0.0]);
    }
    if triangles.is_empty() {
        triangles.push([0.0; 4]);
    }
    Ok(triangles)
}

impl GpuBvh {
    /// Uploads `export` in `bvh.wgsl`'s layout.
    pub fn upload(ctx: &GpuContext, export: &BvhExport) -> Result<Self, GpuError> {
        let triangles = pack_leaf_triangles(export)?;
        let cutouts = pack_cutouts(export);
        let mut nodes = export.node_words.clone();
        // The top level's region after the bottom levels: a CWBVH over n
        // instances has at most n − 1 nodes (one per inner node of the binary
        // tree it collapses), so n + 1 always holds a rebuilt one.
        let tlas_base = export.node_count() as u32;
        let (mut instances, mut tlas_capacity) = (vec![[0.0f32; 4]], 0u32);
        if let Some(tlas) = &export.tlas {
            tlas_capacity = (tlas.instances.len() as u32 + 1).max(tlas.node_count() as u32);
            nodes.extend(rebased_tlas_nodes(tlas, tlas_base));
            nodes.resize((tlas_base + tlas_capacity) as usize * 20, 0);
            instances = pack_instances(tlas, &export.blas_root_nodes, tlas_base)?;
        }
        if nodes.is_empty() {
            nodes.push(0); // shorter than a node: `bvh_trace` sees an empty tree
        }
        for (what, bytes) in [
            ("the BVH nodes", nodes.len() * 4),
            ("the BVH triangles", triangles.len() * 16),
            ("the cutouts", cutouts.len() * 4),
            ("the instances", instances.len() * 16),
        ] {
            ctx.check_buffer(bytes as u64, what)?;
        }
        let device = &ctx.device;
        let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
            ctx.buffer_with(label, contents, wgpu::BufferUsages::STORAGE | usage)
        };
        let copy = wgpu::BufferUsages::COPY_DST;
        let buffers = [
            init("bvh nodes", bytemuck::cast_slice(&nodes), copy),
            init("bvh triangles", bytemuck::cast_slice(&triangles), wgpu::BufferUsages::empty()),
            init("bvh cutouts", bytemuck::cast_slice(&cutouts), wgpu::BufferUsages::empty()),
            init("bvh instances", bytemuck::cast_slice(&instances), copy),
            init("bvh guards", bytemuck::cast_slice(&[0u32; 2]), wgpu::BufferUsages::COPY_SRC),
        ];
        let bytes = buffers.iter().map(|b| b.size()).sum();
        let bind_group = buffers_bind_group(ctx, "bvh", &bvh_bind_group_layout(device), &buffers);
        let [nodes, _, _, instance_buffer, guards] = buffers;
        Ok(Self {
            node_count: export.node_count(),
            leaf_count: export.leaf_triangles.len(),
            cut_triangle_count: export.cut_triangles.len(),
            instance_count: export.tlas.as_ref().map_or(0, |t| t.instances.len()),
            bytes,
            bind_group,
            nodes,
            instances: instance_buffer,
            guards,
            tlas_base,
            tlas_capacity,
        })
    }

    /// Places the instances for a frame: rewrites the top level with `tlas`
    /// (`TlasLayout::export_at` of the tracer this was uploaded from), which
    /// must place as many instances as the one uploaded. `blas_root_nodes`:
    /// the upload's `BvhExport::blas_root_nodes`.
    pub fn place(&self, ctx: &GpuContext, tlas: &TlasExport, blas_root_nodes: &[u32]) -> Result<(), GpuError> {
        check_node_words(&tlas.node_words, "the top level")?;
        if tlas.instances.len() != self.instance_count || tlas.node_count() as u32 > self.tlas_capacity {
            return Err(GpuError::Input(format!(
                "a top level of {} instances and {} nodes for a BVH uploaded with {} instances and room for {} nodes",
                tlas.instances.len(),
                tlas.node_count(),
                self.instance_count,
                self.tlas_capacity
            )));
        }
        let nodes = rebased_tlas_nodes(tlas, self.tlas_base);
        let instances = pack_instances(tlas, blas_root_nodes, self.tlas_base)?;
        if !nodes.is_empty() {
            ctx.write_buffer(&self.nodes, self.tlas_base as u64 * 80, bytemuck::cast_slice(&nodes));
        }
        ctx.write_buffer(&self.instances, 0, bytemuck::cast_slice(&instances));
        Ok(())
    }

    /// A BVH over a caller's own triangle soup (an engine's geometry): built on
    /// the CPU with the same settings as probegi's scenes, all triangles opaque.
    /// Hit `triangle` ids index `triangles`; the front face is the one whose
    /// counter-clockwise normal `(v1 − v0) × (v2 − v0)` faces the ray's origin.
    pub fn from_triangles(ctx: &GpuContext, triangles: &[[Vec3; 3]]) -> Result<Self, GpuError> {
        if let Some(k) = triangles.iter().position(|t| !t.iter().all(|v| v.is_finite())) {
            return Err(GpuError::Input(format!("triangle {k} has a non-finite vertex: {:?}", triangles[k])));
        }
        let mut mesh = probegi_scene::mesh::Mesh::default();
        for (k, t) in triangles.iter().enumerate() {
            let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
            for &v in t {
                mesh.positions.push(v);
                mesh.normals.push(n);
                mesh.uvs.push(Vec2::ZERO);
            }
            let b = 3 * k as u32;
            mesh.triangles.push([b, b + 1, b + 2]);
            mesh.triangle_materials.push(0);
        }
        let tracer = probegi_scene::BvhTracer::build(&mesh, probegi_scene::BvhSettings::default());
        Self::upload(ctx, &tracer.export())
    }

    /// Rays the device's walks answered without a full walk since the upload
    /// (the ray rule's misses, walks cut short), as the CPU tracer counts them
    /// (`BvhTracer::trace_guard_counts`). Waits for the device.
    pub fn trace_guard_counts(&self, ctx: &GpuContext) -> Result<TraceGuardCounts, GpuError> {
        let bytes = ctx.read_back(&self.guards)?;
        let words: Vec<u32> = bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        let word = |i: usize| words.get(i).copied().unwrap_or(0) as u64;
        Ok(TraceGuardCounts { rays_refused: word(0), walks_cut_short: word(1) })
    }

    /// Device memory of the BVH's buffers.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    pub(crate) fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }
}

/// `bvh_cutouts` of `bvh.wgsl`: a header, the masks, the cut triangles, the coverage bytes.
fn pack_cutouts(export: &BvhExport) -> Vec<u32> {
    let masks = &export.cutout_masks;
    let cut_offset = 4 + masks.len() * 6;
    let coverage_offset = cut_offset + export.cut_triangles.len() * 7;
    let mut words = vec![masks.len() as u32, cut_offset as u32, coverage_offset as u32, 0];
    let mut coverage_words = 0usize;
    for m in masks {
        let first = if m.coverage.is_empty() { u32::MAX } else { coverage_words as u32 };
        coverage_words += m.coverage.len().div_ceil(4);
        words.extend([m.width, m.height, first, m.factor.to_bits(), m.cutoff.to_bits(), 0]);
    }
    for c in &export.cut_triangles {
        words.push(c.mask);
        for uv in c.uv {
            words.extend([uv.x.to_bits(), uv.y.to_bits()]);
        }
    }
    for m in masks {
        for chunk in m.coverage.chunks(4) {
            let mut b = [0u8; 4];
            b[..chunk.len()].copy_from_slice(chunk);
            words.push(u32::from_le_bytes(b));
        }
    }
    words
}

/// The dispatch shape of `n` threads in workgroups of 64: (x, y) with x ≤ 65535.
pub(crate) fn dispatch_2d(n: u32) -> (u32, u32) {
    let groups = n.div_ceil(WORKGROUP).max(1);
    let x = groups.min(MAX_GROUPS);
    (x, groups.div_ceil(x))
}

/// The trace pipeline (`trace_rays.wgsl` over `bvh.wgsl`).
pub struct GpuRayTrace {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

/// Rays and hits resident on the device, for repeated traces of one batch.
pub struct GpuRayBatch {
    /// Rays in the batch.
    pub ray_count: u32,
    /// Rays its buffers hold (≥ `ray_count`: a batch reused for fewer rays,
    /// [`Self::reused_for`]).
    capacity: u32,
    any_hit: bool,
    rays: wgpu::Buffer,
    hits: wgpu::Buffer,
    params: wgpu::Buffer,
    /// What `params` holds once every write recorded so far has landed
    /// ([`Self::configure`] skips a write that would not change it).
    params_written: std::sync::Mutex<TraceParams>,
    bind_group: wgpu::BindGroup,
}

impl GpuRayBatch {
    /// Whether a pass may write a batch of `ray_count` rays (`any_hit` or
    /// closest) into this one's buffers, as [`GpuRayTrace::empty_batch`]
    /// would have made them.
    /// Its buffers hold `ray_count` rays and at most twice as many (a batch
    /// much larger than the frame's is let go rather than held).
    pub(crate) fn reusable_for(&self, ray_count: u32, any_hit: bool) -> bool {
        self.any_hit == any_hit && self.capacity >= ray_count && self.capacity / 2 <= ray_count
    }

    /// This batch's buffers for a batch of `ray_count` rays
    /// ([`Self::reusable_for`]); the passes run over the first `ray_count`
    /// (its trace parameters are written by the next [`Self::configure`]).
    pub(crate) fn reused_for(mut self, ray_count: u32) -> Self {
        self.ray_count = ray_count;
        self
    }

    /// Rays its buffers hold.
    pub(crate) fn capacity(&self) -> u32 {
        self.capacity
    }

    pub(crate) fn rays_buffer(&self) -> &wgpu::Buffer {
        &self.rays
    }

    pub(crate) fn hits_buffer(&self) -> &wgpu::Buffer {
        &self.hits
    }

    /// An error when rays `first..first + count` are not all in the batch.
    pub(crate) fn check_rays(&self, first: u32, count: u32) -> Result<(), GpuError> {
        let end = first as u64 + count as u64;
        if end > self.ray_count as u64 {
            return Err(GpuError::Input(format!(
                "a probe's rays {first}..{end} lie past the batch's {} rays",
                self.ray_count
            )));
        }
        Ok(())
    }

    /// With `static_only`, the batch's next traces leave moving objects out
    /// (initialisation rounds see static geometry only, as on the CPU).
    pub fn set_static_only(&self, ctx: &GpuContext, static_only: bool) {
        self.configure(ctx, static_only, &[]);
    }

    /// The batch's next traces: with `static_only` without moving objects, and
    /// the rays of each of `segments` (the first [`TRACE_MAX_SEGMENTS`]) in
    /// direction-major thread order ([`TraceSegment`]). A segment that starts
    /// before the previous one ends, or leaves the batch, is traced in batch order.
    pub fn configure(&self, ctx: &GpuContext, static_only: bool, segments: &[TraceSegment]) {
        let (groups_x, _) = dispatch_2d(self.ray_count);
        let skip = if static_only { BVH_INSTANCE_MOVING } else { 0 };
        let mut params = TraceParams {
            ray_count: self.ray_count,
            groups_x,
            any_hit: self.any_hit as u32,
            skip,
            ..Default::default()
        };
        let mut end = 0u64;
        for s in segments.iter().take(TRACE_MAX_SEGMENTS) {
            let rays = s.probe_count as u64 * s.rays_per_probe as u64;
            // Kept only in order, disjoint and inside the batch; others trace in batch order.
            if (s.first_ray as u64) < end || s.first_ray as u64 + rays > self.ray_count as u64 || rays == 0 {
                continue;
            }
            end = s.first_ray as u64 + rays;
            params.segments[params.segment_count as usize] = [s.first_ray, s.probe_count, s.rays_per_probe, 0];
            params.segment_count += 1;
        }
        // A batch reused for the same kind of trace (a still field's updates,
        // `WgpuProbeTracer::spare_batch`) holds these parameters already.
        // A batch reused for another count (the screen scheme's) is rewritten
        // in order: the traces recorded before read the old parameters.
        let mut written = self.params_written.lock().unwrap_or_else(|e| e.into_inner());
        if bytemuck::bytes_of(&*written) == bytemuck::bytes_of(&params) {
            ctx.count_kept(std::mem::size_of::<TraceParams>() as u64);
            return;
        }
        ctx.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        *written = params;
    }

    /// Device memory of the rays and hits.
    pub fn bytes(&self) -> u64 {
        self.rays.size() + self.hits.size()
    }
}

impl GpuRayTrace {
    /// The trace pipeline on `ctx` (rays and hits in group 0, the BVH in group 1).
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("trace rays", &[true, false]);
        let bvh_layout = bvh_bind_group_layout(&ctx.device);
        let [pipeline] = ctx.compute_pipelines(&TRACE_RAYS, &[Some(&layout), Some(&bvh_layout)], ["trace_rays"]);
        Self { layout, pipeline }
    }

    /// The most rays one batch may hold on this device (its largest storage binding).
    pub fn max_batch_rays(ctx: &GpuContext) -> usize {
        let l = ctx.device.limits();
        let limit = l.max_storage_buffer_binding_size.min(l.max_buffer_size) as usize;
        (limit / std::mem::size_of::<GpuRay>()).min(u32::MAX as usize)
    }

    /// Uploads `rays` into a device-resident batch.
    pub fn batch(&self, ctx: &GpuContext, rays: &[GpuRay], any_hit: bool) -> Result<GpuRayBatch, GpuError> {
        if rays.len() > Self::max_batch_rays(ctx) {
            return Err(GpuError::Input(format!(
                "{} rays exceed this adapter's largest batch of {}",
                rays.len(),
                Self::max_batch_rays(ctx)
            )));
        }
        let ray_bytes: &[u8] = if rays.is_empty() { &[0; 32] } else { bytemuck::cast_slice(rays) };
        let ray_buffer = ctx.buffer_with(
            "rays",
            ray_bytes,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        );
        Ok(self.bind_batch(ctx, ray_buffer, rays.len() as u32, rays.len() as u32, any_hit))
    }

    /// A batch around `rays`: its parameters, a hit buffer and the bind group.
    fn bind_batch(&self, ctx: &GpuContext, rays: wgpu::Buffer, n: u32, capacity: u32, any_hit: bool) -> GpuRayBatch {
        ctx.count_ray_batch();
        let (groups_x, _) = dispatch_2d(n);
        let first_params = TraceParams { ray_count: n, groups_x, any_hit: any_hit as u32, ..Default::default() };
        let params = ctx.buffer_with(
            "trace params",
            bytemuck::bytes_of(&first_params),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let hits = ctx.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ray hits"),
            size: (capacity.max(1) as usize * std::mem::size_of::<GpuRayHit>()) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind_group = ctx.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("trace rays"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: rays.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: hits.as_entire_binding() },
            ],
        });
        let params_written = std::sync::Mutex::new(first_params);
        GpuRayBatch { ray_count: n, capacity, any_hit, rays, hits, params, params_written, bind_group }
    }

    /// A batch of `ray_count` rays left for a pass on the device to write
    /// (`probe_ray_gen`).
    pub fn empty_batch(&self, ctx: &GpuContext, ray_count: u32, any_hit: bool) -> Result<GpuRayBatch, GpuError> {
        self.empty_batch_holding(ctx, ray_count, ray_count, any_hit)
    }

    /// [`Self::empty_batch`] with buffers for `capacity` rays (at least
    /// `ray_count`): room for the later batches of a field whose batch
    /// size moves from frame to frame (the screen scheme's).
    pub(crate) fn empty_batch_holding(
        &self,
        ctx: &GpuContext,
        ray_count: u32,
        capacity: u32,
        any_hit: bool,
    ) -> Result<GpuRayBatch, GpuError> {
        let capacity = capacity.max(ray_count);
        let bytes = capacity.max(1) as u64 * std::mem::size_of::<GpuRay>() as u64;
        ctx.check_buffer(bytes, "a ray batch")?;
        let rays = ctx.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rays"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Ok(self.bind_batch(ctx, rays, ray_count, capacity, any_hit))
    }

    /// The rays of a batch, read back.
    pub fn download_rays(&self, ctx: &GpuContext, batch: &GpuRayBatch) -> Result<Vec<GpuRay>, GpuError> {
        let bytes = ctx.read_back(&batch.rays)?;
        Ok(bytemuck::cast_slice::<u8, GpuRay>(&bytes)[..batch.ray_count as usize].to_vec())
    }

    /// Records the trace of `batch` into `encoder`, with optional timestamps.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bvh: &GpuBvh,
        batch: &GpuRayBatch,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let (x, y) = dispatch_2d(batch.ray_count);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(if batch.any_hit { "trace any hit" } else { "trace closest hit" }),
            timestamp_writes: timestamps,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &batch.bind_group, &[]);
        pass.set_bind_group(1, bvh.bind_group(), &[]);
        if batch.ray_count > 0 {
            pass.dispatch_workgroups(x, y, 1);
        }
    }

    /// Reads a traced batch's hits back.
    pub fn download(&self, ctx: &GpuContext, batch: &GpuRayBatch) -> Result<Vec<GpuRayHit>, GpuError> {
        let bytes = ctx.read_back(&batch.hits)?;
        Ok(bytemuck::cast_slice::<u8, GpuRayHit>(&bytes)[..batch.ray_count as usize].to_vec())
    }

    /// Traces `rays` (closest hit, or any hit for shadow rays) and reads the hits back,
    /// in batches that fit the adapter's storage bindings.
    pub fn trace(
        &self,
        ctx: &GpuContext,
        bvh: &GpuBvh,
        rays: &[GpuRay],
        any_hit: bool,
    ) -> Result<Vec<GpuRayHit>, GpuError> {
        self.trace_static_only(ctx, bvh, rays, any_hit, false)
    }

    /// [`Self::trace`], with moving objects left out where `static_only`
    /// (initialisation rounds).
    pub fn trace_static_only(
        &self,
        ctx: &GpuContext,
        bvh: &GpuBvh,
        rays: &[GpuRay],
        any_hit: bool,
        static_only: bool,
    ) -> Result<Vec<GpuRayHit>, GpuError> {
        let mut out = Vec::with_capacity(rays.len());
        for chunk in rays.chunks(Self::max_batch_rays(ctx).max(1)) {
            let batch = self.batch(ctx, chunk, any_hit)?;
            if static_only {
                batch.set_static_only(ctx, true);
            }
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            self.record(&mut encoder, bvh, &batch, None);
            ctx.submit(encoder.finish());
            out.extend(self.download(ctx, &batch)?);
        }
        Ok(out)
    }
}
