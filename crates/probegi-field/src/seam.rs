//! The seam's vocabulary: what a field set and its caller (an engine, a
//! backend) hand each other during one update (see `ddgi_field_set` for the
//! exchange): the ray batch, the caller's hits, the next step and what can go
//! wrong.

use glam::Vec3;

/// What a device that keeps an update batch's hits must read back for the set
/// ([`DdgiFieldSet::hits_needed_on_host`](crate::DdgiFieldSet::hits_needed_on_host)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HostHits {
    /// Every hit, through [`DdgiFieldSet::submit_hits`](crate::DdgiFieldSet::submit_hits) (the classification
    /// round of initialisation reads the hit points). A device that keeps the
    /// field runs every initialisation round itself instead
    /// ([`DdgiFieldSet::device_init_plan`](crate::DdgiFieldSet::device_init_plan)).
    All,
    /// An initialisation round that is a relocation iteration for every volume
    /// in it: the hits' distances, with normals only where the set asks for
    /// them ([`DdgiFieldSet::submit_init_hits`](crate::DdgiFieldSet::submit_init_hits)).
    Relocation,
    /// Per probe of the batch, seed 003's usage counts, through
    /// [`DdgiFieldSet::submit_device_hits`](crate::DdgiFieldSet::submit_device_hits) (a volume under the usage scheme).
    ProbeUsage,
    /// Nothing: call [`DdgiFieldSet::submit_device_hits`](crate::DdgiFieldSet::submit_device_hits) with no counts.
    None,
}

/// Which seam call comes next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpdateStep {
    /// Trace [`DdgiFieldSet::ray_batch`](crate::DdgiFieldSet::ray_batch) and call [`DdgiFieldSet::submit_hits`](crate::DdgiFieldSet::submit_hits).
    TraceRays,
    /// Shade the rays with `needs_radiance` and call [`DdgiFieldSet::submit_radiance`](crate::DdgiFieldSet::submit_radiance).
    ShadeRays,
    /// The frame's update is complete.
    Done,
}

/// What a batch is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ProbeRayBatchKind {
    /// Distance-only rays of initialisation (relocation, classification) against
    /// static geometry; no shading follows.
    Initialization,
    /// The frame's update rays of every volume.
    #[default]
    Update,
}

/// One probe's rays in a batch. `#[repr(C)]` + `Pod` (16 bytes) so a device
/// uploads a batch's probes as they are: must match `UsageProbe` in
/// probegi-wgpu's `probe_usage.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BatchProbe {
    /// The probe's volume (its index in the field set).
    pub volume: u32,
    /// The probe's storage index in its volume.
    pub probe: u32,
    /// The probe's first ray in the batch.
    pub first_ray: u32,
    /// The probe's rays in the batch, consecutive from `first_ray`.
    pub ray_count: u32,
}
const _: () = assert!(std::mem::size_of::<BatchProbe>() == 16);

/// How one volume's update rays in a batch were made: each probe of
/// `probes[first_probe..first_probe + probe_count]` casts `rays_per_probe`
/// rays from its origin along the spherical Fibonacci set rotated by
/// `rotation` (`probe_ray_gen::probe_ray_directions`), up to `max_distance_m`.
/// A device that traces the batch can make them where it traces instead of
/// receiving them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneratedProbeRays {
    /// The volume whose rays these are.
    pub volume: u32,
    /// The volume's first entry in the batch's `probes`.
    pub first_probe: u32,
    /// The volume's entries in the batch's `probes`, consecutive.
    pub probe_count: u32,
    /// Rays each probe casts.
    pub rays_per_probe: u32,
    /// The frame's rotation of the spherical Fibonacci set (`probe_ray_gen::probe_ray_rotation`).
    pub rotation: glam::Quat,
    /// Hits beyond this distance are misses (the volume's trace limit).
    pub max_distance_m: f32,
    /// The records' identity, where the field set made them
    /// (`device_plans::next_plan_id`, unique in the process): two batches
    /// whose entries carry the same `Some` id hold the same probes, origins,
    /// first rays, counts and max distance for it (a steady frame or a kept
    /// trace plan keeps them; the rotation may turn), so a device may keep
    /// what it made of them (the ray generation's, the usage pass's and the
    /// shade's per-probe records). The `probe_needs_radiance` flags have an
    /// identity of their own ([`ProbeRayBatch::probe_needs_radiance_id`]): a
    /// kept trace plan keeps this id while they change.
    /// `None`: no identity (a device packs the records again).
    pub plan_id: Option<u64>,
}

/// One frame's probe rays for every volume: structure of arrays, probe-major.
///
/// **The ray rule at the seam** (`probegi_scene::bvh_walk`, the same in
/// `bvh.wgsl`): a ray whose origin or direction is NaN or infinite, whose
/// direction is zero (denormal components count as zero), or whose max
/// distance is NaN or negative, is a miss on both backends — never an error,
/// never a hang — and the tracers count it (`--stats`: `trace_guards_*`). Every
/// walk is bounded by its BVH's node count. A batch a tracer hands back must
/// keep that rule for the rays an engine puts here itself.
///
/// **Per-ray or per-probe.** Every batch holds its probes (`probes`,
/// `probe_origins_m`); the per-ray arrays (`origins_m`, `directions`,
/// `max_distances_m`) are filled unless the set was told that a device makes
/// the update rays itself
/// ([`DdgiFieldSet::set_update_rays_on_device`](crate::DdgiFieldSet::set_update_rays_on_device)):
/// then an update batch is O(probes) on the host, its rays described by
/// `generated`, and [`Self::has_ray_arrays`] is false. [`Self::expanded`]
/// gives a copy with the arrays for a caller that needs them.
#[derive(Clone, Debug, Default)]
pub struct ProbeRayBatch {
    /// What the batch is for (initialisation or the frame's update).
    pub kind: ProbeRayBatchKind,
    /// Ray origins in world space: the probes' positions with their relocation offsets
    /// (empty when [`Self::has_ray_arrays`] is false).
    pub origins_m: Vec<Vec3>,
    /// Unit directions (empty when [`Self::has_ray_arrays`] is false).
    pub directions: Vec<Vec3>,
    /// Hits beyond this distance are misses (empty when [`Self::has_ray_arrays`] is false).
    pub max_distances_m: Vec<f32>,
    /// Set by [`DdgiFieldSet::submit_hits`](crate::DdgiFieldSet::submit_hits) on update batches: the rays whose
    /// radiance the caller must supply (others are ignored). Empty after
    /// [`DdgiFieldSet::submit_device_hits`](crate::DdgiFieldSet::submit_device_hits),
    /// whose device reads [`Self::probe_needs_radiance`] instead.
    pub needs_radiance: Vec<bool>,
    /// The probes that trace in this batch and their ray ranges, volume by volume.
    pub probes: Vec<BatchProbe>,
    /// Per entry of `probes`: the origin of its rays (the probe's relocated position).
    pub probe_origins_m: Vec<Vec3>,
    /// Per entry of `probes`, set with the hits on update batches: whether the
    /// probe blends this frame, so that its rays' radiance is needed (back-face
    /// hits aside, whose radiance is zero by rule).
    pub probe_needs_radiance: Vec<bool>,
    /// How each volume's rays were made (see [`GeneratedProbeRays`]): update batches and initialisation rounds.
    pub generated: Vec<GeneratedProbeRays>,
    /// Rays in the batch (the per-ray arrays' length when they are filled).
    ray_count: usize,
    /// Whether `push_probe` fills the per-ray arrays.
    ray_arrays: bool,
    /// [`Self::probe_needs_radiance_id`].
    radiance_id: u64,
}

impl ProbeRayBatch {
    /// Rays in the batch: those planned, or those an engine put in the per-ray
    /// arrays itself.
    pub fn len(&self) -> usize {
        self.ray_count.max(self.origins_m.len())
    }

    /// Whether the batch has no rays.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether the per-ray arrays (`origins_m`, `directions`,
    /// `max_distances_m`) hold every ray of the batch.
    pub fn has_ray_arrays(&self) -> bool {
        self.origins_m.len() == self.len()
    }

    /// Initialisation rays see static geometry only (moving objects wake probes instead).
    pub fn static_geometry_only(&self) -> bool {
        self.kind == ProbeRayBatchKind::Initialization
    }

    /// Rays per volume (`volumes` entries).
    pub fn rays_per_volume(&self, volumes: usize) -> Vec<u64> {
        let mut v = vec![0u64; volumes];
        for p in &self.probes {
            v[p.volume as usize] += p.ray_count as u64;
        }
        v
    }

    /// The batch with its per-ray arrays: itself when it has them, else a copy
    /// whose rays are made from `generated` as the device makes them
    /// (`probe_ray_gen::probe_ray_directions`, bit for bit the host's).
    pub fn expanded(&self) -> std::borrow::Cow<'_, ProbeRayBatch> {
        if self.has_ray_arrays() {
            return std::borrow::Cow::Borrowed(self);
        }
        let mut out = self.clone();
        out.fill_ray_arrays();
        std::borrow::Cow::Owned(out)
    }

    /// Fills the per-ray arrays from the probes and `generated` (see [`Self::expanded`]).
    pub(crate) fn fill_ray_arrays(&mut self) {
        if self.has_ray_arrays() {
            return;
        }
        self.origins_m.clear();
        self.directions.clear();
        self.max_distances_m.clear();
        for g in &self.generated {
            let dirs = crate::probe_ray_gen::rotated_fibonacci(g.rotation, g.rays_per_probe);
            let probes = g.first_probe as usize..(g.first_probe + g.probe_count) as usize;
            for (bp, &origin) in self.probes[probes.clone()].iter().zip(&self.probe_origins_m[probes]) {
                debug_assert_eq!(bp.first_ray as usize, self.origins_m.len());
                self.origins_m.extend(std::iter::repeat_n(origin, dirs.len()));
                self.directions.extend_from_slice(&dirs);
                self.max_distances_m.extend(std::iter::repeat_n(g.max_distance_m, dirs.len()));
            }
        }
        debug_assert_eq!(self.origins_m.len(), self.len());
    }

    pub(crate) fn clear(&mut self, kind: ProbeRayBatchKind, ray_arrays: bool) {
        self.kind = kind;
        self.origins_m.clear();
        self.directions.clear();
        self.max_distances_m.clear();
        self.needs_radiance.clear();
        self.probes.clear();
        self.probe_origins_m.clear();
        self.probe_needs_radiance.clear();
        self.generated.clear();
        self.ray_count = 0;
        self.ray_arrays = ray_arrays;
        self.renew_radiance_id();
    }

    /// An identity of `probe_needs_radiance` within the batch's plan: a
    /// device's shade keeps the flags it uploaded (one bit a probe, apart
    /// from its per-probe records, which it keeps by the plans' identities,
    /// `GeneratedProbeRays::plan_id`) while this repeats: equal identities
    /// mean equal flags. Drawn anew (`device_plans::next_plan_id`) whenever the set
    /// writes other flags (a kept trace plan's batch keeps its probes and
    /// record identities while the flags move with the states). It holds for
    /// batches as the set made them: a caller that writes the public flags
    /// of a batch it holds, or builds one (`Default`: 0), gives its device
    /// no identity to trust.
    pub fn probe_needs_radiance_id(&self) -> u64 {
        self.radiance_id
    }

    /// Draws [`Self::probe_needs_radiance_id`] anew.
    pub(crate) fn renew_radiance_id(&mut self) {
        self.radiance_id = crate::device_plans::next_plan_id();
    }

    /// A kept update plan's next frame (`ddgi_volume::steady_frames`): the
    /// same probes and first rays, the per-ray arrays and the rays to shade
    /// dropped (the rotation turned), `probe_needs_radiance` kept.
    pub(crate) fn renew_rays(&mut self) {
        debug_assert!(!self.ray_arrays && self.kind == ProbeRayBatchKind::Update);
        self.origins_m.clear();
        self.directions.clear();
        self.max_distances_m.clear();
        self.needs_radiance.clear();
    }

    /// Whether the batch was planned with per-ray arrays (a host makes the rays).
    pub(crate) fn planned_with_ray_arrays(&self) -> bool {
        self.ray_arrays
    }

    /// Appends rays that belong to no probe entry (the shadow field's shadow
    /// rays, seed 003 §5.1) after the probes' rays; the batch keeps per-ray arrays.
    pub(crate) fn push_rays(&mut self, origins: &[Vec3], dirs: &[Vec3], max_m: &[f32]) {
        if origins.is_empty() {
            return;
        }
        debug_assert!(self.ray_arrays && self.has_ray_arrays());
        self.origins_m.extend_from_slice(origins);
        self.directions.extend_from_slice(dirs);
        self.max_distances_m.extend_from_slice(max_m);
        self.ray_count += origins.len();
    }

    /// Appends one probe's rays (to the per-ray arrays where the batch keeps
    /// them); returns its first ray index.
    pub(crate) fn push_probe(&mut self, volume: u32, probe: u32, origin: Vec3, dirs: &[Vec3], max_m: f32) -> u32 {
        let first = self.ray_count as u32;
        if self.ray_arrays {
            self.origins_m.extend(std::iter::repeat_n(origin, dirs.len()));
            self.directions.extend_from_slice(dirs);
            self.max_distances_m.extend(std::iter::repeat_n(max_m, dirs.len()));
        }
        self.ray_count += dirs.len();
        self.probes.push(BatchProbe { volume, probe, first_ray: first, ray_count: dirs.len() as u32 });
        self.probe_origins_m.push(origin);
        first
    }
}

/// One traced probe ray, as the caller reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeRayHit {
    /// Signed hit distance in metres: `t` on a front face, `−t` on a back face,
    /// `+∞` for a miss (nothing within the ray's max distance).
    pub distance_m: f32,
    /// Unit normal at the hit on the side facing the ray's origin, read only
    /// where [`DdgiFieldSet::hit_normals_needed`](crate::DdgiFieldSet::hit_normals_needed)
    /// says: in an initialisation round the triangle's plane (geometric)
    /// normal, which the jcgt classification's front-side test reads (a
    /// shading normal, interpolated or from a normal map, is not the plane a
    /// probe lies in front of); in an update batch with a host shadowing
    /// field, the shading normal of its surfels. Any finite value (zero) in
    /// other rounds and for a miss.
    pub normal: Vec3,
}

impl ProbeRayHit {
    /// A miss: nothing within the ray's max distance.
    pub const MISS: Self = Self { distance_m: f32::INFINITY, normal: Vec3::ZERO };

    /// A front-face hit at `t` with facing normal `normal`.
    pub fn front(t: f32, normal: Vec3) -> Self {
        Self { distance_m: t, normal }
    }

    /// A back-face hit at `t` (the ray's origin is behind the surface).
    pub fn back(t: f32, normal: Vec3) -> Self {
        Self { distance_m: -t, normal }
    }
}

/// A seam call that does not fit the exchange.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SeamError {
    /// The call does not follow the step the set asked for.
    OutOfOrder {
        /// The step the set asked for.
        expected: UpdateStep,
        /// The seam call that came instead.
        called: &'static str,
    },
    /// A results buffer does not have one entry per batch ray.
    WrongLength {
        /// The buffer (e.g. "hits", "radiance").
        what: &'static str,
        /// The batch's ray count.
        expected: usize,
        /// The buffer's length.
        got: usize,
    },
    /// A host blend while another device holds the current atlases: copy them
    /// back first ([`DdgiFieldSet::accept_host_atlases`](crate::DdgiFieldSet::accept_host_atlases)).
    FieldOnDevice,
    /// Usage counts for an update batch whose counts the set does not wait
    /// for ([`DdgiFieldSet::submit_device_hits`](crate::DdgiFieldSet::submit_device_hits)):
    /// not counted on the device, or already given.
    UnknownBatch {
        /// The batch's number ([`crate::DeviceUsageCounts::batch`]).
        batch: u64,
    },
}

impl std::fmt::Display for SeamError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SeamError::OutOfOrder { expected, called } => {
                write!(f, "{called} called while the field set expects {expected:?}")
            }
            SeamError::WrongLength { what, expected, got } => {
                write!(f, "{what} has {got} entries but the ray batch has {expected}")
            }
            SeamError::FieldOnDevice => {
                write!(f, "the host blend needs the field's atlases, which are on another device")
            }
            SeamError::UnknownBatch { batch } => {
                write!(f, "usage counts of update batch {batch}, whose counts the field set does not wait for")
            }
        }
    }
}

impl std::error::Error for SeamError {}
