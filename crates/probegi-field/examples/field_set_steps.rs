//! The field set's host steps of a device-driven update, timed one by one:
//! `cargo run --release -p probegi-field --example field_set_steps [N] [RAYS]`.
//!
//! An N³ volume (32 by default, 32 rays a probe) over a 4 m box, every
//! initialisation ray a miss, driven as a device that keeps the hits and the
//! atlases drives it (`set_update_rays_on_device`): planning (`begin_update`),
//! taking the device's hits, the blend plan and the bookkeeping after the
//! blend, in ms an update over updates 10 to 39, with every probe active and
//! under jcgt states (where every probe sleeps: none traces), with and
//! without the kept plan of a steady frame (`DdgiFieldSet::set_steady_plans`),
//! under the screen scheme (no camera: every probe Idle, an eighth of
//! them tracing each frame in its phase), which plans in full every frame,
//! and under the usage scheme (every probe traces every frame; the counts a
//! device would read back, two batches late, alternate the probes between
//! ALIVE and SLEEPING by probe parity), with and without its kept trace plan.
//! The `bench --backend wgpu` figure `field_set_ms` is these steps' sum in
//! the real loop; this separates them.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_field::ddgi_field_set::ProbeRayBatchKind;
use probegi_field::{DdgiFieldSet, DdgiVolume, ProbeRayHit};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<u32> = std::env::args().skip(1).map(|a| a.parse()).collect::<Result<_, _>>()?;
    let (n, rays) = (args.first().copied().unwrap_or(32), args.get(1).copied().unwrap_or(32));
    println!("{n}³ probes × {rays} rays, ms an update: begin / hits / blend plan / after the blend = sum");
    for states in [ProbeStatesMode::AllActive, ProbeStatesMode::Jcgt, ProbeStatesMode::Screen, ProbeStatesMode::Usage] {
        // The screen scheme plans in full every frame (its states move); the
        // usage scheme keeps its trace plan alone.
        let keeps: &[bool] = if states == ProbeStatesMode::Screen { &[false] } else { &[false, true] };
        for &keep in keeps {
            let ms = time_steps(states, keep, n, rays)?;
            let label = match (keep, states) {
                (false, _) => "full plan",
                (true, ProbeStatesMode::Usage) => "kept trace",
                (true, _) => "kept plan",
            };
            let steps = ms.map(|m| format!("{m:.3}")).join(" / ");
            println!("{states:?}, {label}: {steps} = {:.3}", ms.iter().sum::<f64>());
        }
    }
    Ok(())
}

/// Milliseconds an update of each step, over updates 10 to 39.
fn time_steps(states: ProbeStatesMode, keep: bool, n: u32, rays: u32) -> Result<[f64; 4], Box<dyn std::error::Error>> {
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::splat(n),
        probe_rays_per_probe: rays,
        probe_states: states,
        probe_relocation: false,
        ..Default::default()
    };
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, (Vec3::ZERO, Vec3::splat(4.0))));
    set.set_update_rays_on_device(true);
    set.set_steady_plans(keep);
    let (mut ms, timed) = ([0.0f64; 4], 30);
    let mut on_device = std::collections::VecDeque::new();
    for frame in 0..10 + timed {
        let t0 = Instant::now();
        set.begin_update(5, frame);
        while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
            let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
            set.submit_hits(&misses)?;
        }
        // The counts a device reads back under the usage scheme: this batch's
        // made now (outside the timing), the one two batches back handed over.
        let due = match set.device_usage_request() {
            Some(request) => {
                let counts = (0..set.ray_batch().probes.len()).map(|k| (k as i32 % 2, 1, 0)).collect();
                on_device.push_back(probegi_field::DeviceUsageCounts { batch: request.batch, counts });
                let lag = request.lag_updates as usize;
                if on_device.len() > lag { on_device.pop_front().into_iter().collect() } else { vec![] }
            }
            None => vec![],
        };
        let t1 = Instant::now();
        set.submit_device_hits(&due)?;
        let t2 = Instant::now();
        drop(set.device_blend_plan()?);
        let t3 = Instant::now();
        set.submit_device_blend(&[])?;
        let t4 = Instant::now();
        if frame >= 10 {
            for (m, (a, b)) in ms.iter_mut().zip([(t0, t1), (t1, t2), (t2, t3), (t3, t4)]) {
                *m += (b - a).as_secs_f64() * 1e3 / timed as f64;
            }
        }
    }
    Ok(ms)
}
