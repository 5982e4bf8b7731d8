#!/usr/bin/env bash
# Runs probegi-wgpu's GPU test binaries on a GPU machine that has no toolchain.
#
#   bash scripts/gpu-tests.sh pack [MODULE...]   (here, from the project root)
#     Builds the release test binaries of probegi-wgpu (its unit tests and `it`,
#     the integration tests, one module per former test file), takes their
#     paths from cargo's JSON messages, strips them and packs them into
#     .device/tests/probegi-wgpu-tests.tar.xz, printing its size and the size of
#     .device/ (all that travels must stay under 64 MiB). Run
#     ../shared/device/prepare.sh first: it empties .device/.
#   bash scripts/gpu-tests.sh run              (on the device, from the project root)
#     After .device/on-device.sh has laid ../shared and the Vulkan loader, e.g.
#       bash .device/on-device.sh 'bash scripts/gpu-tests.sh run'
#     unpacks the binaries and runs each with PROBEGI_REQUIRE_GPU=1 (no adapter
#     is a failure, not a skip) and PROBEGI_SHARED_DIR=<absolute ../shared>,
#     prints a Markdown table (test binary or `it` module | passed | failed |
#     seconds; only the MODULEs given to pack, when any were), keeps each
#     one's output under .device/tests/logs (and, where the device tool
#     sets $OUT, which brings back at most 8 files: the table and all outputs in
#     one file each there) and exits non-zero when any binary failed.
# GPU_TESTS_DIR moves .device/tests elsewhere (a folder git ignores, to travel).
set -euo pipefail

usage() {
    sed -n '2,19p' "$0" >&2
    exit 2
}

pack_dir=${GPU_TESTS_DIR:-.device/tests}
tarball=$pack_dir/probegi-wgpu-tests.tar.xz

pack() {
    local args=(test --release -p probegi-wgpu --no-run --locked --message-format=json)
    local json stage
    json=$(mktemp)
    stage=$(mktemp -d)
    cargo "${args[@]}" >"$json"
    # Test executables of probegi-wgpu: compiler-artifact messages with a test
    # profile and an executable, named after their target (the hash dropped).
    python3 - "$json" "$stage" <<'PY'
import json, shutil, sys, os
found = 0
for line in open(sys.argv[1]):
    try:
        m = json.loads(line)
    except ValueError:
        continue
    if m.get("reason") != "compiler-artifact" or not m.get("executable"):
        continue
    if not m.get("profile", {}).get("test"):
        continue
    if "probegi-wgpu" not in m["package_id"]:
        continue
    name = m["target"]["name"]
    if "lib" in m["target"]["kind"]:
        name += "-unit"
    shutil.copy(m["executable"], os.path.join(sys.argv[2], name))
    found += 1
if not found:
    sys.exit("gpu-tests: cargo reported no test executables of probegi-wgpu")
PY
    strip "$stage"/*
    # The modules of `it` to run on the device (none named: all of them).
    printf '%s\n' "$@" | grep . >"$stage/modules" || : >"$stage/modules"
    # .device/ stays out of git, as prepare.sh keeps it.
    if [ -d .git ]; then
        grep -qx '/.device/' .git/info/exclude 2>/dev/null || echo '/.device/' >>.git/info/exclude
    fi
    mkdir -p "$pack_dir"
    # -9e: a 64 MiB dictionary spans the binaries, which share most of their
    # code (115 MB stripped packs to 9 MB, against 23 MB at xz's default -6).
    tar -C "$stage" -cf - . | xz -9e -T0 >"$tarball"
    echo "gpu-tests: packed $(ls "$stage" | wc -l) binaries ($(du -ch "$stage"/* | tail -1 | cut -f1) stripped)" \
        "into $tarball: $(du -h "$tarball" | cut -f1)"
    # What travels: the checkout's files git does not ignore, and .device/.
    local checkout device
    checkout=$({ git ls-files -z; git ls-files -z -o --exclude-standard; } | du -cb --files0-from=- | tail -1 | cut -f1)
    device=$(du -sbc .device "$pack_dir" 2>/dev/null | tail -1 | cut -f1)
    case "$pack_dir" in .device/*) device=$(du -sb .device | cut -f1) ;; esac
    awk -v c="$checkout" -v d="$device" 'BEGIN {
        printf "gpu-tests: .device is %.1f MiB, the checkout %.1f MiB: %.1f MiB travel (at most 64)\n",
            d / 1048576, c / 1048576, (c + d) / 1048576
        if (c + d > 64 * 1048576) print "gpu-tests: too much: the tests do not need .device/bin/probegi" > "/dev/stderr"
    }'
    rm -rf "$json" "$stage"
}

run() {
    [ -f "$tarball" ] || { echo "gpu-tests: no $tarball: run 'pack' first" >&2; exit 2; }
    [ -d ../shared/scenes ] || { echo "gpu-tests: no ../shared/scenes: run .device/on-device.sh first" >&2; exit 2; }
    local shared
    bin=$pack_dir/bin
    logs=$pack_dir/logs
    shared=$(cd ../shared && pwd -P)
    rm -rf "$bin" "$logs"
    mkdir -p "$bin" "$logs"
    tar -C "$bin" -xJf "$tarball"
    table
    if [ -n "${OUT:-}" ] && [ -d "$OUT" ]; then
        cp "$logs/table.md" "$OUT/gpu-tests.md"
        for f in "$logs"/*.log; do printf '==== %s\n' "$(basename "$f")"; cat "$f"; done >"$OUT/gpu-tests.log"
    fi
    if grep -q '^FAILED$' "$logs/status"; then
        echo "gpu-tests: failures; outputs in $logs" >&2
        exit 1
    fi
}

# Runs every unpacked binary, `it` one module at a time (each module is a
# former test binary); the table on stdout and in $logs/table.md.
table() {
    local b m
    echo ok >"$logs/status"
    {
        echo "| test binary | passed | failed | seconds |"
        echo "|---|---:|---:|---:|"
    } | tee "$logs/table.md"
    for b in "$bin"/*; do
        [ -x "$b" ] || continue
        if [ "$(basename "$b")" != it ]; then
            run_one "$b" "$(basename "$b")"
            continue
        fi
        local modules
        modules=$(cat "$bin/modules" 2>/dev/null)
        # libtest's list: "module::test: test", one a line.
        [ -n "$modules" ] || modules=$("$b" --list --format terse | sed -n 's/::.*: test$//p' | sort -u)
        for m in $modules; do run_one "$b" "$m" "$m::"; done
    done
}

# One row of the table: binary, row name, then libtest's arguments.
run_one() {
    local b=$1 name=$2 start end status passed failed
    shift 2
    start=$(date +%s.%N)
    status=0
    PROBEGI_REQUIRE_GPU=1 PROBEGI_SHARED_DIR=$shared "$b" "$@" >"$logs/$name.log" 2>&1 || status=$?
    end=$(date +%s.%N)
    # libtest's summary: "test result: ok. 3 passed; 0 failed; ...".
    passed=$(grep '^test result:' "$logs/$name.log" | grep -o '[0-9][0-9]* passed' | awk '{s += $1} END {print s + 0}')
    failed=$(grep '^test result:' "$logs/$name.log" | grep -o '[0-9][0-9]* failed' | awk '{s += $1} END {print s + 0}')
    if [ "$status" -ne 0 ]; then
        echo FAILED >"$logs/status"
        # A binary that died before its summary still counts as a failure.
        [ "$failed" -gt 0 ] || failed="exit $status"
    fi
    printf '| %s | %s | %s | %s |\n' "$name" "$passed" "$failed" \
        "$(awk -v a="$start" -v b="$end" 'BEGIN {printf "%.1f", b - a}')" | tee -a "$logs/table.md"
}

[ $# -ge 1 ] || usage
root=$(git rev-parse --show-toplevel 2>/dev/null || pwd)
cd "$root"
cmd=$1
shift
case "$cmd" in
    pack) pack "$@" ;;
    run) [ $# -eq 0 ] || usage; run ;;
    *) usage ;;
esac
