//! `volume_tracking_bounds_m`: a tracking window follows the camera only as
//! far as its probe box stays inside the bounds, and sits at their centre on
//! an axis where it is larger than them.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_field::{DdgiFieldSet, DdgiVolume};

#[test]
fn a_window_stays_inside_its_tracking_bounds() {
    let bounds = [Vec3::new(-10.0, 0.0, -2.0), Vec3::new(10.0, 4.0, 2.0)];
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::new(5, 5, 9),
        probe_spacing_m: Some(Vec3::ONE),
        volume_tracks_camera: true,
        volume_tracking_bounds_m: Some(bounds),
        ..Default::default()
    };
    let placed = |camera: Vec3| DdgiVolume::placed(settings.clone(), (bounds[0], bounds[1]), Some(camera));
    let box_of =
        |v: &DdgiVolume| (v.grid.origin_m, v.grid.origin_m + v.grid.spacing_m * 4.0 * Vec3::new(1.0, 1.0, 2.0));
    // Camera near the low x end: the 4 m box starts at the bounds (x), fills
    // y (4 m = the bounds), and is centred on z (8 m > 4 m of bounds).
    let (lo, hi) = box_of(&placed(Vec3::new(-9.5, 1.0, 1.5)));
    assert_eq!((lo, hi), (Vec3::new(-10.0, 0.0, -4.0), Vec3::new(-6.0, 4.0, 4.0)));
    // Followed along x to the far end: stops at the bounds.
    let mut set = DdgiFieldSet::single(placed(Vec3::new(-9.5, 1.0, 1.5)));
    for x in -9..=12 {
        set.set_tracking_target(Vec3::new(x as f32, 1.0, 1.5));
    }
    let (lo, hi) = box_of(&set.volumes()[0]);
    assert_eq!((lo, hi), (Vec3::new(6.0, 0.0, -4.0), Vec3::new(10.0, 4.0, 4.0)));
    // Without bounds it follows the camera past them.
    let free = DdgiVolumeSettings { volume_tracking_bounds_m: None, ..settings.clone() };
    let mut set = DdgiFieldSet::single(DdgiVolume::placed(free, (bounds[0], bounds[1]), Some(Vec3::ZERO)));
    for x in 0..=14 {
        set.set_tracking_target(Vec3::new(x as f32, 1.0, 1.5));
    }
    assert!(box_of(&set.volumes()[0]).1.x > 14.0);
}
