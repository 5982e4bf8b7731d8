//! A bounded mutation fuzzer over the argument parser and the commands behind
//! it: seed command lines (small and fast when valid) have tokens replaced by
//! extreme values, dropped, duplicated or swapped, and each run of the real
//! binary must end with success (0) or a clear error (1, or 2 for usage) —
//! never a panic (101) or a signal. A run still going after a few seconds (a
//! mutation can ask for 4 billion frames) is stopped and counted as slow, which
//! is allowed. The suite runs it for `PROBEGI_FUZZ_ARGS_SECONDS` (default 5);
//! `scripts/long-checks.sh` for 5 minutes.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use probegi_core::rng::Pcg32;

fn seeds(out: &str) -> Vec<Vec<String>> {
    let lines = [
        format!("render --width 4 --height 4 --frames 1 --out {out}/r.png"),
        format!(
            "render --gi ddgi --probes 2,2,2 --rays-per-probe 8 --width 4 --height 4 --frames 1 --set hysteresis=0.9 --out {out}/d.exr"
        ),
        format!("render --gi sh --width 4 --height 4 --frames 1 --set sh_occlusion=true --out {out}/s.png"),
        format!("reference --width 4 --height 4 --spp 1 --set alpha_cutouts=false --out {out}/ref.exr"),
        format!("compare {out}/ref.exr {out}/d.exr --out {out}/sheet.png"),
        "bench --probes 2,2,2 --rays-per-probe 4 --repeat 1".to_string(),
        format!(
            "render --scene builtin:furnace-box --width 4 --height 4 --frames 1 --camera-pos 0,1,3 --camera-target 0,1,0 --fov-y 40 --sky 1,1,1 --out {out}/f.png"
        ),
    ];
    lines.iter().map(|l| l.split_whitespace().map(str::to_string).collect()).collect()
}

const EXTREMES: &[&str] = &[
    "0",
    "-1",
    "4294967296",
    "1e30",
    "-1e30",
    "nan",
    "inf",
    "",
    "1,2",
    "1,2,3,4",
    "0,0,0",
    "nan,0,0",
    "65536",
    "4096",
    "é",
    "--",
    "-",
    "builtin:",
    "builtin:nope",
    "/nonexistent/x.obj",
    "x.jpg",
    "hysteresis=2",
    "probe_states=bogus",
    "normal_maps=maybe",
    "=",
    "--set",
    "--gi",
    "ddgi",
    "none",
];

fn mutate(rng: &mut Pcg32, seed: &[String]) -> Vec<String> {
    let mut a = seed.to_vec();
    for _ in 0..1 + rng.next_u32() % 3 {
        let at = rng.next_u32() as usize % a.len().max(1);
        match rng.next_u32() % 4 {
            0 if !a.is_empty() => a[at] = EXTREMES[rng.next_u32() as usize % EXTREMES.len()].to_string(),
            1 if a.len() > 1 => {
                a.remove(at);
            }
            2 if !a.is_empty() => {
                let t = a[at].clone();
                a.insert(at, t);
            }
            _ if a.len() > 1 => {
                let b = rng.next_u32() as usize % a.len();
                a.swap(at, b);
            }
            _ => {}
        }
    }
    a
}

#[test]
fn mutated_command_lines_end_in_success_or_a_clear_error() {
    let out = std::env::temp_dir().join(format!("probegi-fuzz-args-{}", std::process::id()));
    std::fs::create_dir_all(&out).expect("mkdir");
    let seeds = seeds(&out.to_string_lossy());
    // The seeds themselves must work, and leave ref.exr / d.exr for `compare`.
    for s in &seeds {
        let o = Command::new(env!("CARGO_BIN_EXE_probegi")).args(s).output().expect("spawn");
        assert!(o.status.success(), "seed {s:?} failed:\n{}", String::from_utf8_lossy(&o.stderr));
    }
    let secs = std::env::var("PROBEGI_FUZZ_ARGS_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(5u64);
    let seed = std::env::var("PROBEGI_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(1u64);
    let mut rng = Pcg32::new(seed, 23);
    let start = Instant::now();
    let (mut runs, mut ok, mut errors, mut slow) = (0u32, 0u32, 0u32, 0u32);
    let mut bad = vec![];
    while start.elapsed() < Duration::from_secs(secs) {
        let args = mutate(&mut rng, &seeds[runs as usize % seeds.len()]);
        let mut child = Command::new(env!("CARGO_BIN_EXE_probegi"))
            .args(&args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn");
        let begun = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().expect("wait") {
                break Some(s);
            }
            if begun.elapsed() > Duration::from_secs(4) {
                child.kill().ok();
                child.wait().ok();
                break None;
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        runs += 1;
        match status.map(|s| s.code()) {
            None => slow += 1,
            Some(Some(0)) => ok += 1,
            Some(Some(1 | 2)) => {
                let mut e = String::new();
                std::io::Read::read_to_string(&mut child.stderr.take().expect("stderr"), &mut e).ok();
                if e.contains("panicked") || e.trim().is_empty() {
                    bad.push((args, e));
                } else {
                    errors += 1;
                }
            }
            Some(code) => bad.push((args, format!("exit {code:?}"))),
        }
    }
    eprintln!(
        "fuzzed {runs} command lines in {secs} s (seed {seed}): {ok} ran, {errors} clear errors, {slow} stopped as slow, {} bad",
        bad.len()
    );
    std::fs::remove_dir_all(&out).ok();
    assert!(runs > 20, "only {runs} runs");
    assert!(bad.is_empty(), "{} runs panicked, crashed or failed silently; first: {:?}", bad.len(), bad[0]);
}
