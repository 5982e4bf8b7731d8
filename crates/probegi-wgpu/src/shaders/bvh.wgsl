// Closest-hit and any-hit traversal of obvhs's compressed-wide BVH (CWBVH, Ylitie
// et al. 2017, "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide
// BVHs"), mirroring what the CPU runs: obvhs 0.4 `CwBvhNode::intersect_ray_basic`,
// `CwBvh::ray_traverse` / `ray_traverse_miss` (the `traverse!` loop),
// `RtTriangle::intersect` and `compute_barycentric`, and probegi-scene's alpha
// cutouts (probegi-scene `bvh/blas.rs` `Blas::intersect`, `texture.rs` `Footprint`).
// With a top level (moving objects, instanced meshes: probegi-scene's `BvhTracer`
// `closest_in` / `occluded_in`), one loop walks both levels: at a top-level leaf
// the ray moves into the instance's space (unnormalised direction, so t is the
// same in both) and the walk goes on in its bottom level on the same stack, then
// back up where it left the top level, so the nodes come in the CPU's order.
// The buffers are `probegi_scene::BvhExport`, uploaded by `probegi_wgpu::bvh_trace::GpuBvh`:
//   bvh_nodes:     20 words per node (the `CwBvhNode` layout, documented on `BvhExport::node_words`):
//                  every bottom level (indices rebased), then the top level's nodes (rewritten
//                  each frame by `GpuBvh::place`);
//   bvh_triangles: 4 × vec4 per leaf: (v0, triangle id bits), (e1, cutout index bits), (e2, 0), (ng, 0);
//   bvh_cutouts:   [mask count, cut-triangle offset, coverage offset, 0,
//                   per mask: width, height, coverage word offset, factor bits, cutoff bits, 0,
//                   per cut triangle: mask, uv0.x, uv0.y, uv1.x, uv1.y, uv2.x, uv2.y,
//                   coverage bytes packed 4 per word, little-endian];
//   bvh_instances: vec4 header (instance count bits, top-level root node bits, 0, 0); per instance
//                  in top-level leaf order 4 × vec4: the columns of local-from-world (xyz) with
//                  w = bottom-level root node bits, scene instance bits (`RayHit::instance`),
//                  flag bits (BVH_INSTANCE_*), and the translation (xyz). A count of 0: no top
//                  level, rays go straight to the bottom level at node 0.
//   bvh_guards:    [rays refused, walks cut short] (probegi-scene `TraceGuardCounts`),
//                  read back by `GpuBvh::trace_guard_counts`.
// The ray rule and the walk bound are probegi-scene's `bvh_walk` (its module docs):
// denormal direction components flush to zero; a ray with a non-finite origin or
// direction, a zero direction, a non-finite t_min, a NaN t_max or t_min > t_max is
// a miss (counted); a walk of one level that would enter more nodes than the
// whole export holds (the CPU bounds each level by its own count) returns a miss
// for the whole ray (counted). Finiteness is tested on the bits: WGSL
// lets a compiler assume that floats are never NaN or infinite.

@group(1) @binding(0) var<storage, read> bvh_nodes: array<u32>;
@group(1) @binding(1) var<storage, read> bvh_triangles: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> bvh_cutouts: array<u32>;
@group(1) @binding(3) var<storage, read> bvh_instances: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> bvh_guards: array<atomic<u32>, 2>;

const BVH_NODE_WORDS: u32 = 20u;
// obvhs `cwbvh::node::EPSILON`: the nodes' near plane.
const BVH_NODE_EPSILON: f32 = 0.0001;
const BVH_NO_HIT: u32 = 0xffffffffu;
// A leaf test's miss (hits have t ≥ t_min ≥ 0). Usable rays carry a finite
// t_max (the host stores +∞ as f32::MAX); a refused ray's miss keeps its t_max.
const BVH_MISS: f32 = -1.0;
// obvhs `CwBvh::validate` keeps trees shallower than 32; a bottom level's walk
// stacks on top of its top level's.
const BVH_STACK_SIZE: u32 = 64u;
// bvh_instances flags: the identity transform (the static part); a moving object.
// BVH_INSTANCE_IDENTITY and BVH_INSTANCE_MOVING: the prelude's (probegi_wgpu::shader_registry).

struct BvhRay {
    origin: vec3<f32>,
    dir: vec3<f32>,
    inv_dir: vec3<f32>,
    t_min: f32,
    t_max: f32,
    // obvhs `ray_get_octant_inv4`, one byte (the same in all four).
    oct_inv: u32,
};

struct BvhHit {
    t: f32,
    // Leaf index (BVH_NO_HIT for a miss).
    leaf: u32,
    // Weights of vertices 1 and 2.
    bary: vec2<f32>,
    // `Scene::instances` index of the hit copy, BVH_NO_HIT for the scene's own mesh.
    instance: u32,
    // The ray met the clockwise side (in the instance's space, which has the
    // same sides: instance transforms keep handedness).
    backface: bool,
};

// obvhs `ray::safe_inverse` (f32::EPSILON); directions carry no negative zeros.
fn bvh_safe_inverse(x: f32) -> f32 {
    let eps = 1.1920929e-7;
    if (abs(x) <= eps) {
        return select(1.0, -1.0, x < 0.0) / eps;
    }
    return 1.0 / x;
}

const BVH_EXPONENT_BITS: u32 = 0x7f800000u;

// Whether `x` is finite, from its bits (not NaN, not ±∞).
fn bvh_is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & BVH_EXPONENT_BITS) != BVH_EXPONENT_BITS;
}

fn bvh_is_finite3(v: vec3<f32>) -> bool {
    return bvh_is_finite(v.x) && bvh_is_finite(v.y) && bvh_is_finite(v.z);
}

// Zeros and denormals to +0 (`bvh_walk::usable_ray`'s flush), from the bits.
fn bvh_flush(x: f32) -> f32 {
    return select(x, 0.0, (bitcast<u32>(x) & BVH_EXPONENT_BITS) == 0u);
}

// probegi-scene `bvh_walk::usable_ray`: whether the rule traces `ray` at all.
fn bvh_ray_usable(ray: BvhRay) -> bool {
    let t_max_nan = !bvh_is_finite(ray.t_max) && (bitcast<u32>(ray.t_max) & 0x007fffffu) != 0u;
    let dir_zero = ray.dir.x == 0.0 && ray.dir.y == 0.0 && ray.dir.z == 0.0;
    return bvh_is_finite3(ray.origin) && bvh_is_finite3(ray.dir) && !dir_zero && bvh_is_finite(ray.t_min)
        && !t_max_nan && ray.t_min <= ray.t_max;
}

fn bvh_make_ray(origin: vec3<f32>, dir_in: vec3<f32>, t_min: f32, t_max: f32) -> BvhRay {
    // Denormals flushed and negative zeros cleared, as probegi-scene's `usable_ray` does.
    let dir = vec3<f32>(bvh_flush(dir_in.x), bvh_flush(dir_in.y), bvh_flush(dir_in.z)) + vec3<f32>(0.0);
    let inv = vec3<f32>(bvh_safe_inverse(dir.x), bvh_safe_inverse(dir.y), bvh_safe_inverse(dir.z));
    var oct = 0u;
    if (dir.x >= 0.0) { oct |= 4u; }
    if (dir.y >= 0.0) { oct |= 2u; }
    if (dir.z >= 0.0) { oct |= 1u; }
    return BvhRay(origin, dir, inv, t_min, t_max, oct);
}

fn bvh_byte(w: u32, b: u32) -> u32 {
    return (w >> (b * 8u)) & 0xffu;
}

// obvhs `CwBvhNode::intersect_ray_basic` with `get_child_and_index_bits`: the hit
// mask (inner children in the high byte, leaf primitives in the low 24 bits).
// Each node word is read once: the eight children in two halves of four, whose
// bytes share a word in every 8-byte field.
fn bvh_intersect_node(node: u32, ray: BvhRay) -> u32 {
    let base = node * BVH_NODE_WORDS;
    let p = vec3<f32>(bitcast<f32>(bvh_nodes[base]), bitcast<f32>(bvh_nodes[base + 1u]), bitcast<f32>(bvh_nodes[base + 2u]));
    let ew = bvh_nodes[base + 3u];
    let extent = vec3<f32>(
        bitcast<f32>((ew & 0xffu) << 23u),
        bitcast<f32>(((ew >> 8u) & 0xffu) << 23u),
        bitcast<f32>(((ew >> 16u) & 0xffu) << 23u),
    );
    let adj_dir_inv = extent * ray.inv_dir;
    let adj_origin = (p - ray.origin) * ray.inv_dir;
    let neg = ray.dir < vec3<f32>(0.0);
    var hit_mask = 0u;
    for (var half = 0u; half < 2u; half++) {
        let w = base + half;
        let metas = bvh_nodes[w + 6u];
        if (metas == 0u) {
            continue; // four empty slots
        }
        // Near and far planes per axis for the ray's octant, four children per word.
        let lo_x = bvh_nodes[w + 8u];
        let hi_x = bvh_nodes[w + 10u];
        let lo_y = bvh_nodes[w + 12u];
        let hi_y = bvh_nodes[w + 14u];
        let lo_z = bvh_nodes[w + 16u];
        let hi_z = bvh_nodes[w + 18u];
        let near = vec3<u32>(select(lo_x, hi_x, neg.x), select(lo_y, hi_y, neg.y), select(lo_z, hi_z, neg.z));
        let far = vec3<u32>(select(hi_x, lo_x, neg.x), select(hi_y, lo_y, neg.y), select(hi_z, lo_z, neg.z));
        for (var b = 0u; b < 4u; b++) {
            let child_meta = bvh_byte(metas, b);
            if (child_meta == 0u) {
                continue; // empty slot
            }
            let sh = b * 8u;
            let q_near = vec3<f32>((near >> vec3<u32>(sh)) & vec3<u32>(0xffu));
            let q_far = vec3<f32>((far >> vec3<u32>(sh)) & vec3<u32>(0xffu));
            let t_lo = q_near * adj_dir_inv + adj_origin;
            let t_hi = q_far * adj_dir_inv + adj_origin;
            let t_near = max(max(max(t_lo.x, t_lo.y), t_lo.z), BVH_NODE_EPSILON);
            let t_far = min(min(min(t_hi.x, t_hi.y), t_hi.z), ray.t_max);
            if (t_near <= t_far) {
                // Inner children have child_meta 24..31: bits 3 and 4 both set.
                let inner = ((child_meta & (child_meta << 1u)) & 0x10u) != 0u;
                let bit_index = (child_meta ^ select(0u, ray.oct_inv, inner)) & 0x1fu;
                let child_bits = (child_meta >> 5u) & 7u;
                hit_mask |= child_bits << bit_index;
            }
        }
    }
    return hit_mask;
}

// probegi-scene `texture.rs` `Footprint::at`: the four texels (row-major indices
// in a width × height image, wrap addressing, texel centres at half-integers) and
// the bilinear fractions; a non-finite uv reads texel (0, 0). The one WGSL owner
// of it: scene.wgsl's texture lookups use it too.
struct WrapFootprint {
    texel: vec4<u32>,
    f: vec2<f32>,
};

fn wrap_footprint(width: u32, height: u32, uv_in: vec2<f32>) -> WrapFootprint {
    var fx = 0.0;
    var fy = 0.0;
    var x0 = 0i;
    var y0 = 0i;
    if (all(abs(uv_in) <= vec2<f32>(3.4028235e38))) {
        let uv = uv_in - floor(uv_in);
        let x = uv.x * f32(width) - 0.5;
        let y = uv.y * f32(height) - 0.5;
        let fx0 = floor(x);
        let fy0 = floor(y);
        fx = x - fx0;
        fy = y - fy0;
        x0 = i32(fx0);
        y0 = i32(fy0);
    }
    let w = i32(width);
    let h = i32(height);
    let c0 = u32(((x0 % w) + w) % w);
    let c1 = u32((((x0 + 1) % w) + w) % w);
    let r0 = u32(((y0 % h) + h) % h) * width;
    let r1 = u32((((y0 + 1) % h) + h) % h) * width;
    return WrapFootprint(vec4<u32>(r0 + c0, r0 + c1, r1 + c0, r1 + c1), vec2<f32>(fx, fy));
}

// Footprint::blend of four scalars.
fn wrap_blend(v: vec4<f32>, f: vec2<f32>) -> f32 {
    return (v.x * (1.0 - f.x) + v.y * f.x) * (1.0 - f.y) + (v.z * (1.0 - f.x) + v.w * f.x) * f.y;
}

// The cutout rule (probegi-scene `bvh/cutouts.rs` `CoverageMask::opaque_at`'s left side):
// factor × the bilinear coverage.
fn bvh_coverage(mask: u32, uv: vec2<f32>) -> f32 {
    let m = 4u + mask * 6u;
    let words = bvh_cutouts[m + 2u];
    let factor = bitcast<f32>(bvh_cutouts[m + 3u]);
    if (words == BVH_NO_HIT) {
        return factor; // constant coverage 1
    }
    let fp = wrap_footprint(bvh_cutouts[m], bvh_cutouts[m + 1u], uv);
    let base = bvh_cutouts[2] + words;
    var v = vec4<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        let t = fp.texel[k];
        v[k] = f32(bvh_byte(bvh_cutouts[base + t / 4u], t % 4u)) * (1.0 / 255.0);
    }
    return factor * wrap_blend(v, fp.f);
}

// Distance to leaf `leaf` along `ray` within [t_min, t_max] (obvhs
// `RtTriangle::intersect`, both faces), BVH_MISS for a miss or a cut-out point;
// the barycentrics in `bary`.
fn bvh_intersect_leaf(leaf: u32, ray: BvhRay, bary: ptr<function, vec2<f32>>) -> f32 {
    let a = bvh_triangles[leaf * 4u];
    let b = bvh_triangles[leaf * 4u + 1u];
    let e2 = bvh_triangles[leaf * 4u + 2u].xyz;
    let ng = bvh_triangles[leaf * 4u + 3u].xyz;
    let v0 = a.xyz;
    let e1 = b.xyz;
    let det = dot(ng, ray.dir);
    if (det == 0.0) {
        return BVH_MISS;
    }
    let c = v0 - ray.origin;
    let r = cross(ray.dir, c);
    let inv_det = 1.0 / det;
    let u = dot(r, e2) * inv_det;
    let v = dot(r, e1) * inv_det;
    let w = 1.0 - u - v;
    // Sign bits, so that −0.0 misses as on the CPU.
    if (((bitcast<u32>(u) | bitcast<u32>(v) | bitcast<u32>(w)) & 0x80000000u) != 0u) {
        return BVH_MISS;
    }
    let t = dot(ng, c) * inv_det;
    if (!(t >= ray.t_min && t <= ray.t_max)) {
        return BVH_MISS;
    }
    let cut = bitcast<u32>(b.w);
    if (cut != BVH_NO_HIT) {
        let o = bvh_cutouts[1] + cut * 7u;
        let mask = bvh_cutouts[o];
        let uv0 = vec2<f32>(bitcast<f32>(bvh_cutouts[o + 1u]), bitcast<f32>(bvh_cutouts[o + 2u]));
        let uv1 = vec2<f32>(bitcast<f32>(bvh_cutouts[o + 3u]), bitcast<f32>(bvh_cutouts[o + 4u]));
        let uv2 = vec2<f32>(bitcast<f32>(bvh_cutouts[o + 5u]), bitcast<f32>(bvh_cutouts[o + 6u]));
        let uv = uv0 * (1.0 - u - v) + uv1 * u + uv2 * v;
        let cutoff = bitcast<f32>(bvh_cutouts[4u + mask * 6u + 4u]);
        if (!(bvh_coverage(mask, uv) >= cutoff)) {
            return BVH_MISS;
        }
    }
    *bary = vec2<f32>(u, v);
    return t;
}

// One walk's state over both levels (`bvh_trace_skipping` and its steps below).
struct BvhWalk {
    hit: BvhHit,
    // The world ray (its t_max the closest hit so far) and the ray of the level walked.
    world: BvhRay,
    ray: BvhRay,
    in_bottom: bool,
    // The top-level leaf of the instance walked below (BVH_NO_HIT: none).
    instance: u32,
    stack: array<vec2<u32>, BVH_STACK_SIZE>,
    sp: u32,
    current: vec2<u32>,
    prims: vec2<u32>,
    // Nodes entered in the level walked.
    entered: u32,
    // Where the bottom level's stack starts, and the top level's state left there.
    bottom_floor: u32,
    top_entered: u32,
    top_current: vec2<u32>,
    top_prims: vec2<u32>,
};

// A bottom-level leaf: a closer hit becomes the walk's and shortens both rays
// (true when it hit).
fn bvh_walk_leaf(w: ptr<function, BvhWalk>, leaf: u32) -> bool {
    var bary = vec2<f32>(0.0);
    let t = bvh_intersect_leaf(leaf, (*w).ray, &bary);
    if (t >= 0.0 && t < (*w).ray.t_max) {
        let back = dot(bvh_triangles[leaf * 4u + 3u].xyz, (*w).ray.dir) < 0.0;
        var scene_instance = BVH_NO_HIT;
        if ((*w).instance != BVH_NO_HIT) {
            scene_instance = bitcast<u32>(bvh_instances[1u + (*w).instance * 4u + 1u].w);
        }
        (*w).hit = BvhHit(t, leaf, bary, scene_instance, back);
        (*w).ray.t_max = t;
        (*w).world.t_max = t;
        return true;
    }
    return false;
}

// A top-level leaf, an instance: into its bottom level (BvhTracer::closest_in,
// Instance::to_local) unless its flags share a bit with `skip`; true when the
// walk went down.
fn bvh_walk_enter(w: ptr<function, BvhWalk>, leaf: u32, skip: u32) -> bool {
    let base = 1u + leaf * 4u;
    let c0 = bvh_instances[base];
    let c1 = bvh_instances[base + 1u];
    let c2 = bvh_instances[base + 2u];
    let flags = bitcast<u32>(c2.w);
    let root = bitcast<u32>(c0.w);
    if ((flags & skip) != 0u || root == BVH_NO_HIT) {
        return false;
    }
    if ((flags & BVH_INSTANCE_IDENTITY) != 0u) {
        (*w).ray = (*w).world;
    } else {
        let tr = bvh_instances[base + 3u].xyz;
        let world = (*w).world;
        let o = world.origin;
        let d = world.dir;
        // glam's Affine3A::transform_point3a / transform_vector3a, in its order.
        let origin = ((c0.xyz * o.x + c1.xyz * o.y) + c2.xyz * o.z) + tr;
        let dir = (c0.xyz * d.x + c1.xyz * d.y) + c2.xyz * d.z;
        (*w).ray = bvh_make_ray(origin, dir, world.t_min, world.t_max);
    }
    (*w).instance = leaf;
    (*w).top_entered = (*w).entered;
    (*w).entered = 0u;
    (*w).top_current = (*w).current;
    (*w).top_prims = (*w).prims;
    (*w).bottom_floor = (*w).sp;
    (*w).in_bottom = true;
    (*w).current = vec2<u32>(root, 0x80000000u);
    (*w).prims = vec2<u32>(0u, 0u);
    return true;
}

// Into the next child of the current node group, nearest first (the rest stay
// on the stack); false when the level walked would enter more than `bound` nodes.
fn bvh_walk_node(w: ptr<function, BvhWalk>, bound: u32) -> bool {
    let hits_imask = (*w).current.y;
    let offset = firstLeadingBit(hits_imask);
    (*w).current.y &= ~(1u << offset);
    if (((*w).current.y & 0xff000000u) != 0u && (*w).sp < BVH_STACK_SIZE) {
        (*w).stack[(*w).sp] = (*w).current;
        (*w).sp++;
    }
    let slot = (offset - 24u) ^ (*w).ray.oct_inv;
    let relative = countOneBits(hits_imask & ~(0xffffffffu << slot));
    let node = (*w).current.x + relative;
    (*w).entered++;
    if ((*w).entered > bound) {
        return false;
    }
    let hitmask = bvh_intersect_node(node, (*w).ray);
    let base = node * BVH_NODE_WORDS;
    (*w).current = vec2<u32>(bvh_nodes[base + 4u], (hitmask & 0xff000000u) | (bvh_nodes[base + 3u] >> 24u));
    (*w).prims = vec2<u32>(bvh_nodes[base + 5u], hitmask & 0x00ffffffu);
    return true;
}

// Back up to the top level where the walk left it.
fn bvh_walk_leave(w: ptr<function, BvhWalk>) {
    (*w).in_bottom = false;
    (*w).entered = (*w).top_entered;
    (*w).ray = (*w).world;
    (*w).current = (*w).top_current;
    (*w).prims = (*w).top_prims;
    (*w).bottom_floor = 0u;
}

// The closest hit (`any_hit` false) or the first hit found (`any_hit` true, for
// shadow rays) of `ray`: obvhs's `traverse!` loop with an explicit stack, over
// both levels. Instances whose flags share a bit with `skip` are left out
// (BVH_INSTANCE_MOVING: static geometry only, for initialisation rounds).
fn bvh_trace_skipping(ray_in: BvhRay, any_hit: bool, skip: u32) -> BvhHit {
    let miss = BvhHit(ray_in.t_max, BVH_NO_HIT, vec2<f32>(0.0), BVH_NO_HIT, false);
    if (!bvh_ray_usable(ray_in)) {
        atomicAdd(&bvh_guards[0], 1u);
        return miss;
    }
    if (arrayLength(&bvh_nodes) < BVH_NODE_WORDS) {
        return miss;
    }
    let bound = arrayLength(&bvh_nodes) / BVH_NODE_WORDS;
    let top_level = bitcast<u32>(bvh_instances[0].x) > 0u;
    var w: BvhWalk;
    w.hit = miss;
    w.world = ray_in;
    w.ray = ray_in;
    w.in_bottom = !top_level;
    w.instance = BVH_NO_HIT;
    w.current = vec2<u32>(select(0u, bitcast<u32>(bvh_instances[0].y), top_level), 0x80000000u);
    loop {
        while (w.prims.y != 0u) {
            let local = firstLeadingBit(w.prims.y);
            w.prims.y &= ~(1u << local);
            let leaf = w.prims.x + local;
            if (w.in_bottom) {
                if (bvh_walk_leaf(&w, leaf) && any_hit) {
                    return w.hit;
                }
            } else if (bvh_walk_enter(&w, leaf, skip)) {
                break;
            }
        }
        w.prims = vec2<u32>(0u, 0u);
        if ((w.current.y & 0xff000000u) != 0u) {
            if (!bvh_walk_node(&w, bound)) {
                atomicAdd(&bvh_guards[1], 1u);
                return miss;
            }
        } else {
            w.current = vec2<u32>(0u, 0u);
        }
        if (w.prims.y == 0u && (w.current.y & 0xff000000u) == 0u) {
            if (w.sp == w.bottom_floor) {
                if (w.in_bottom && top_level) {
                    bvh_walk_leave(&w);
                    continue;
                }
                break;
            }
            w.sp--;
            w.current = w.stack[w.sp];
        }
    }
    return w.hit;
}

fn bvh_trace(ray: BvhRay, any_hit: bool) -> BvhHit {
    return bvh_trace_skipping(ray, any_hit, 0u);
}

// The scene triangle of a leaf.
fn bvh_triangle_id(leaf: u32) -> u32 {
    return bitcast<u32>(bvh_triangles[leaf * 4u].w);
}
