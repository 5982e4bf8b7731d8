//! `volume_tracking_bounds_m`: a tracking window follows the camera only as
//! far as its probe box stays half a cell inside the bounds, and sits at their centre on
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
    // Camera near the low x end: the 4 m box's first plane sits half a cell
    // inside the bounds on x (as a fitted grid's would, off the outer walls).
    // On y (4 m box, 4 m bounds) and z (8 m box, 4 m bounds) it is larger than
    // the bounds less a cell: centred on them exactly.
    let (lo, hi) = box_of(&placed(Vec3::new(-9.5, 1.0, 1.5)));
    assert_eq!((lo, hi), (Vec3::new(-9.5, 0.0, -4.0), Vec3::new(-5.5, 4.0, 4.0)));
    // Followed along x to the far end: never closer than half a cell to the
    // bounds, and stopped within one cell (the scroll's hysteresis) of that.
    let mut set = DdgiFieldSet::single(placed(Vec3::new(-9.5, 1.0, 1.5)));
    for x in -9..=12 {
        set.set_tracking_target(Vec3::new(x as f32, 1.0, 1.5));
        let (lo, hi) = box_of(&set.volumes()[0]);
        assert!(lo.x >= -9.5 && hi.x <= 9.5, "camera x {x}: box x [{}, {}]", lo.x, hi.x);
    }
    let (lo, hi) = box_of(&set.volumes()[0]);
    assert!(hi.x >= 8.5, "box x [{}, {}]", lo.x, hi.x);
    assert_eq!((lo.y, lo.z), (0.0, -4.0), "y and z stay put");
    // Without bounds it follows the camera past them.
    let free = DdgiVolumeSettings { volume_tracking_bounds_m: None, ..settings.clone() };
    let mut set = DdgiFieldSet::single(DdgiVolume::placed(free, (bounds[0], bounds[1]), Some(Vec3::ZERO)));
    for x in 0..=14 {
        set.set_tracking_target(Vec3::new(x as f32, 1.0, 1.5));
    }
    assert!(box_of(&set.volumes()[0]).1.x > 14.0);
}
