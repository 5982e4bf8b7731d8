//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// The path of `rel` under the shared scenes (`../shared/scenes` beside the
/// repository); a missing file fails the test with the reason.
pub fn shared(rel: &str) -> String {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes").join(rel);
    assert!(
        p.exists(),
        "{} is missing: the tests read the shared scenes from ../shared beside the repository",
        p.display()
    );
    p.to_string_lossy().into_owned()
}
