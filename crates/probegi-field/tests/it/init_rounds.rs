//! Start-up through the seam (`ddgi_volume::init_rounds`): the classification
//! round reads the relocation rounds' hits of the probes that settled, which
//! the host keeps, and traces only the probes that moved in their last
//! round. Its states and offsets equal those of a classification round
//! traced for every probe (the path of a caller that gives no normals on
//! request, `submit_hits`), for fewer rays.
//!
//! The scene is analytic, so every hit is exact on both paths: a closed room
//! (inward faces), a solid block standing on its floor (outward faces: a probe
//! inside it sees back faces) and a thin free-standing wall.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_classification::ProbeState;
use probegi_field::ddgi_field_set::HostHits;
use probegi_field::ddgi_field_set::ProbeRayBatchKind;
use probegi_field::{DdgiFieldSet, DdgiVolume, ProbeRayHit};

const ROOM_M: Vec3 = Vec3::new(8.0, 4.0, 8.0);

/// An axis-aligned box: `inward` faces (a room seen from inside) or outward
/// ones (a solid).
struct AaBox {
    min: Vec3,
    max: Vec3,
    inward: bool,
}

/// The scene's boxes: the room, a solid block and a wall 0.1 m thick.
fn boxes() -> [AaBox; 3] {
    [
        AaBox { min: Vec3::ZERO, max: ROOM_M, inward: true },
        AaBox { min: Vec3::new(1.2, 0.0, 1.3), max: Vec3::new(3.4, 1.7, 3.1), inward: false },
        AaBox { min: Vec3::new(4.95, 0.0, 0.0), max: Vec3::new(5.05, 3.0, 6.0), inward: false },
    ]
}

/// The slab test: entry and exit distances, and the axis each is on.
fn slabs(b: &AaBox, o: Vec3, d: Vec3) -> Option<(f32, usize, f32, usize)> {
    let (mut t0, mut a0, mut t1, mut a1) = (f32::NEG_INFINITY, 0, f32::INFINITY, 0);
    for a in 0..3 {
        let inv = 1.0 / d[a];
        let (mut near, mut far) = ((b.min[a] - o[a]) * inv, (b.max[a] - o[a]) * inv);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        if near > t0 {
            (t0, a0) = (near, a);
        }
        if far < t1 {
            (t1, a1) = (far, a);
        }
    }
    (t0 <= t1 && t1 > 0.0).then_some((t0, a0, t1, a1))
}

/// The closest hit of a ray: signed distance (negative on a back face) and
/// the normal facing the origin.
fn trace(o: Vec3, d: Vec3, max_m: f32) -> ProbeRayHit {
    let mut best = ProbeRayHit::MISS;
    for b in boxes() {
        let Some((t0, a0, t1, a1)) = slabs(&b, o, d) else { continue };
        let inside = t0 <= 0.0;
        // From inside a solid, or toward a room's wall from outside it, the face is a back face.
        let (t, axis, front) = if inside { (t1, a1, b.inward) } else { (t0, a0, !b.inward) };
        if t <= 0.0 || t >= max_m || t >= best.distance_m.abs() {
            continue;
        }
        let mut normal = Vec3::ZERO;
        normal[axis] = -d[axis].signum();
        best = ProbeRayHit { distance_m: if front { t } else { -t }, normal };
    }
    best
}

fn settings(relocation_rounds: u32) -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_counts: UVec3::new(9, 4, 9),
        probe_states: ProbeStatesMode::Jcgt,
        probe_relocation_iterations: relocation_rounds,
        ..Default::default()
    }
}

/// Every ray of the current batch traced.
fn batch_hits(set: &mut DdgiFieldSet) -> Vec<ProbeRayHit> {
    set.fill_ray_arrays();
    let b = set.ray_batch();
    (0..b.len()).map(|r| trace(b.origins_m[r], b.directions[r], b.max_distances_m[r])).collect()
}

/// Runs frame 0's initialisation rounds. With `keep_hits` the hits go
/// through `submit_init_hits` (relocation rounds without normals; the set asks
/// for those it keeps), otherwise through `submit_hits`, which keeps none, so
/// the classification round traces every probe. Returns the rays each round traced.
fn start_up(set: &mut DdgiFieldSet, keep_hits: bool) -> Vec<usize> {
    let mut rounds = Vec::new();
    set.begin_update(3, 0);
    while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
        rounds.push(set.ray_batch().len());
        let hits = batch_hits(set);
        if keep_hits {
            let relocation = set.hits_needed_on_host() == HostHits::Relocation;
            let bare: Vec<ProbeRayHit> =
                hits.iter().map(|h| if relocation { ProbeRayHit { normal: Vec3::ZERO, ..*h } } else { *h }).collect();
            set.submit_init_hits(&bare, &|r| hits[r].normal).expect("init round");
        } else {
            set.submit_hits(&hits).expect("init round");
        }
    }
    rounds
}

/// Both paths' start-up with `relocation_rounds`; returns the rays the kept
/// path's classification round traced and the probes that moved in the last
/// relocation round.
fn compare_paths(relocation_rounds: u32) -> (usize, usize) {
    let set = || DdgiFieldSet::single(DdgiVolume::new(settings(relocation_rounds), (Vec3::ZERO, ROOM_M)));
    let (mut kept, mut full) = (set(), set());
    let kept_rounds = start_up(&mut kept, true);
    let full_rounds = start_up(&mut full, false);
    let (k, f) = (&kept.volumes()[0], &full.volumes()[0]);
    let probes = k.grid.probe_count();
    let rays = k.settings.probe_init_rays_per_probe as usize;

    // The same relocation rounds on both paths (a round nobody traces is not
    // in either list); the full path's classification round traces every
    // probe from where it is.
    let (full_relocation, full_classification) = full_rounds.split_at(full_rounds.len() - 1);
    assert_eq!(full_classification, [probes * rays], "a full classification round");
    assert_eq!(full_relocation[0], probes * rays, "every probe traces the first relocation round");
    assert_eq!(kept_rounds[..full_relocation.len()], *full_relocation);
    let moved = f.probe_offsets.iter().filter(|o| **o != Vec3::ZERO).count();
    assert!(moved > 0 && moved < probes / 4, "the scene moves some probes, not most: {moved} of {probes}");
    // Kept hits: only the probes that moved in the last relocation round trace again.
    let kept_classification = kept_rounds.get(full_relocation.len()).copied().unwrap_or(0);
    let moved_last = full_relocation.last().expect("a relocation round") / rays;
    assert!(kept_classification <= moved_last * rays, "{kept_classification} rays, {moved_last} moved last");

    assert_eq!(k.probe_offsets, f.probe_offsets);
    assert_eq!(k.probe_states, f.probe_states);
    let count = |s: ProbeState| k.probe_states.iter().filter(|&&x| x == s).count();
    let (off, sleeping) = (count(ProbeState::Off), count(ProbeState::Sleeping));
    assert!(off > 0 && sleeping > 0 && off + sleeping < probes, "off {off}, sleeping {sleeping} of {probes}");
    (kept_classification / rays, moved_last)
}

#[test]
fn the_classification_round_reads_settled_probes_hits_and_classifies_as_a_full_round() {
    // The default five rounds: every probe has settled, nothing traces again.
    assert_eq!(compare_paths(5).0, 0);
    // Two rounds: probes still moving trace from where they end, the rest are read.
    let (traced, moved_last) = compare_paths(2);
    assert!(traced > 0 && traced <= moved_last, "{traced} probes traced, {moved_last} moved last");
}

#[test]
fn a_device_init_result_must_carry_the_classification_its_plan_asked_for() {
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings(5), (Vec3::ZERO, ROOM_M)));
    set.begin_update(3, 0);
    let plan = set.device_init_plan().expect("the first round");
    let chain = plan[0].as_ref().expect("a pending volume");
    assert_eq!((chain.relocation_rounds, chain.classification.is_some()), (5, true));
    let probes = chain.grid.probe_count();
    let result = |classification: Option<Vec<(bool, bool)>>| probegi_field::device_plans::DeviceInitResult {
        offsets_m: vec![Vec3::ZERO; probes],
        classification,
        rays_traced: 0,
    };
    drop(plan);
    assert!(set.submit_device_init(&[Some(result(None))]).is_err(), "jcgt states without their classification");
    assert!(set.submit_device_init(&[Some(result(Some(vec![(false, true); probes - 1])))]).is_err(), "one short");
    let step = set.submit_device_init(&[Some(result(Some(vec![(false, true); probes])))]).expect("a whole result");
    assert_eq!(step, probegi_field::UpdateStep::TraceRays);
    assert_eq!(set.ray_batch().kind, ProbeRayBatchKind::Update);
    assert!(set.volumes()[0].probe_states.iter().all(|s| *s == ProbeState::NewlyVigilant));
}
