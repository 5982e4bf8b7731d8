//! The README's library quick starts are the examples' code, not a sketch of it:
//! each ```rust block under a quick-start heading must equal, line for line, the
//! example's `use` lines, a blank line, and the example's region between
//! `// README: <name> begin` and `// README: <name> end` (dedented). The examples
//! themselves are compiled and run by their crates' tests (`embed_example.rs`,
//! `wgpu_embed_example.rs`, probegi-bevy's `examples.rs`), so the README's code
//! compiles and converges too.

use std::path::Path;

/// (README heading, example file under the repository root, region name).
const QUICK_STARTS: &[(&str, &str, &str)] = &[
    ("### CPU field", "crates/probegi-cpu/examples/embed_ddgi.rs", "cpu-field"),
    ("### Bevy", "crates/probegi-bevy/examples/bevy_cornell.rs", "bevy-plugin"),
];

fn repo_file(path: &str) -> String {
    let full = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(path);
    std::fs::read_to_string(&full).unwrap_or_else(|e| panic!("reading {}: {e}", full.display()))
}

/// The first ```rust block after `heading`.
fn readme_block(readme: &str, heading: &str) -> String {
    let after = &readme[readme.find(heading).unwrap_or_else(|| panic!("README has no {heading:?}"))..];
    let body = &after[after.find("```rust\n").unwrap_or_else(|| panic!("no rust block after {heading:?}")) + 8..];
    body[..body.find("```").expect("unterminated block")].to_string()
}

/// The example's `use` lines, a blank line, then its marked region dedented.
fn example_block(source: &str, region: &str) -> String {
    let uses: Vec<&str> = source.lines().filter(|l| l.starts_with("use ")).collect();
    let (begin, end) = (format!("// README: {region} begin"), format!("// README: {region} end"));
    let lines: Vec<&str> = source.lines().collect();
    let first = lines.iter().position(|l| l.trim() == begin).unwrap_or_else(|| panic!("no {begin:?}"));
    let last = lines.iter().position(|l| l.trim() == end).unwrap_or_else(|| panic!("no {end:?}"));
    let body = &lines[first + 1..last];
    let indent =
        body.iter().filter(|l| !l.trim().is_empty()).map(|l| l.len() - l.trim_start().len()).min().unwrap_or(0);
    let mut out: Vec<String> = uses.iter().map(|s| s.to_string()).collect();
    out.push(String::new());
    out.extend(body.iter().map(|l| l.get(indent..).unwrap_or("").to_string()));
    out.join("\n") + "\n"
}

#[test]
fn readme_quick_starts_are_the_examples_code() {
    let readme = repo_file("README.md");
    for &(heading, example, region) in QUICK_STARTS {
        let (shown, real) = (readme_block(&readme, heading), example_block(&repo_file(example), region));
        assert_eq!(shown, real, "README {heading} differs from {example} ({region}): paste the region in");
    }
}
