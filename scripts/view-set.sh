#!/usr/bin/env bash
# The view set (issue "Converged in 100 frames at any density, from every
# view…", goal 1): DDGI configurations scored against Mitsuba 3 references on
# ten cameras (six in Sponza, two in Sibenik, two in the forest), at frames 30,
# 100 and 300, with the mean and the worst over the views. Not part of CI.
#
#   bash scripts/view-set.sh [OUT_DIR]          (default out/view-set)
#
# Environment:
#   VIEWS="sponza-readme sibenik-nave"  a subset of the views below (default all)
#   CONFIGS="fitted-16x8x16 cascades-3"  a subset of the configurations below
#   FRAMES_AT="30 100 300"               the frames scored (the last is rendered)
#   W=320 H=240 SPP=512                  image size; Mitsuba samples a pixel
#   EXTRA="--set probe_x=..."            appended to every DDGI render (a safeguard on/off)
#   TAG=name                             names this run's renders apart (default: base)
#   BACKEND=cpu|wgpu                     the DDGI backend (default cpu)
#   BIN=path                             a built probegi to use (default: build this checkout)
#
# References: Mitsuba 3 (`scripts/mitsuba-check.py --skip-probegi`, two seeds,
# llvm_ad_rgb where libLLVM is installed, else scalar_rgb), made once per view
# and size into OUT_DIR/ref/VIEW/ and kept: the first seed is the reference,
# FLIP between the two seeds is the view's noise floor. Needs `pip install
# mitsuba numpy` (tested with mitsuba 3.9.1).
#
# Per view and configuration, one `probegi render --sequence --sequence-exr`
# run; frames FRAMES_AT are compared with `probegi compare` (HDR-FLIP, dark
# fraction, per-channel mean ratio test/reference). OUT_DIR/TAG/table.md holds
# the table; OUT_DIR/TAG/VIEW-CONFIG/ the frames scored, contact sheets and
# series.tsv (frame, FLIP, dark fraction, mean ratio every SERIES_STEP=10 frames:
# the convergence curve).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/view-set}
W=${W:-320} H=${H:-240} SPP=${SPP:-512}
FRAMES_AT=${FRAMES_AT:-"30 100 300"} SERIES_STEP=${SERIES_STEP:-10}
TAG=${TAG:-base} BACKEND=${BACKEND:-cpu} EXTRA=${EXTRA:-}
mkdir -p "$out/ref" "$out/$TAG"
# A copy, so a rebuild during the run's hour leaves its binary as it was
# (BIN=path: that binary instead of this checkout's build).
if [ -n "${BIN:-}" ]; then
  cp "$BIN" "$out/$TAG/probegi"
else
  cargo build --release -q
  cp target/release/probegi "$out/$TAG/probegi"
fi
bin=$(cd "$out/$TAG" && pwd)/probegi

sponza=../shared/scenes/dabrovic-sponza/sponza.obj
# The issue's Sponza: a constant sky of 3, no bump maps (as issue 32 ranked it).
sponza_args="--sky 3,3,3 --no-bump"
# name | scene | camera position | camera target | field of view (deg) | scene flags
# (mitsuba-check.py spelling: --no-bump becomes --set normal_maps=false for probegi).
view_table() {
  cat <<EOF
sponza-readme|$sponza|-12,2,0|10,4,0|60|$sponza_args
sponza-east|$sponza|12,2,0|-10,4,0|60|$sponza_args
sponza-gallery|$sponza|-6,6.5,-4.5|4,5,4|60|$sponza_args
sponza-roof|$sponza|-1,1.5,0|0.5,14,0.5|70|$sponza_args
sponza-arcade|$sponza|-9,2,-4.5|0,3,0|60|$sponza_args
sponza-west|$sponza|-10,1.6,-4.5|-3,6,2|60|$sponza_args
sibenik-nave|scenes/sibenik-lamp.toml|-17,-11,0|0,-9,0|60|
sibenik-altar|scenes/sibenik-lamp.toml|14,-10.5,3|-8,-8,-1|60|
forest-edge|builtin:forest|-19,2.5,-21|0,4.5,0|60|
forest-under|builtin:forest|-2,1.6,-6|6,4,4|60|
EOF
}
# name | flags for `probegi render --gi ddgi`
config_table() {
  cat <<EOF
fitted-16x8x16|--probes 16,8,16
fitted-32x16x12|--probes 32,16,12
cascades-3|--cascades 3
EOF
}
VIEWS=${VIEWS:-$(view_table | cut -d'|' -f1 | tr '\n' ' ')}
CONFIGS=${CONFIGS:-$(config_table | cut -d'|' -f1 | tr '\n' ' ')}
last=${FRAMES_AT##* }

variant=scalar_rgb
for lib in /usr/lib/x86_64-linux-gnu/libLLVM-19.so /usr/lib/x86_64-linux-gnu/libLLVM.so.1; do
  [ -e "$lib" ] && variant=llvm_ad_rgb && break
done

# Mitsuba's flags for a view's scene flags (--no-bump is spelled the same).
view_field() { view_table | awk -F'|' -v v="$1" -v f="$2" '$1 == v { print $f }'; }
config_flags() { config_table | awk -F'|' -v c="$1" '$1 == c { print $2 }'; }

reference() {
  local v=$1 dir="$out/ref/$1-${W}x${H}-${SPP}spp"
  if ! ls "$dir"/*-mitsuba-seed1.exr >/dev/null 2>&1; then
    # shellcheck disable=SC2046
    python3 scripts/mitsuba-check.py --skip-probegi --probegi "$bin" --variant "$variant" --out-dir "$dir" \
      --scene "$(view_field "$v" 2)" --camera-pos="$(view_field "$v" 3)" --camera-target="$(view_field "$v" 4)" \
      --fov-y "$(view_field "$v" 5)" --width "$W" --height "$H" --spp "$SPP" $(view_field "$v" 6) >&2
  fi
  ls "$dir"/*-mitsuba-seed1.exr
}
floor_of() { ls "$out/ref/$1-${W}x${H}-${SPP}spp"/*-mitsuba-seed2.exr; }

# `probegi compare`'s three figures, space-separated: flip dark ratio(R G B averaged).
score() {
  "$bin" compare "$1" "$2" ${3:+--out "$3"} 2>/dev/null | awk '
    /^mean_flip:/ { f = $2 } /^dark_fraction:/ { d = $2 } /^mean_ratio:/ { r = ($2 + $3 + $4) / 3 }
    END { printf "%.3f %.3f %.3f\n", f, d, r }'
}

# A render that fails stops the run (set -e): its frames go with it.
seq_dir=""
trap '[ -n "$seq_dir" ] && rm -rf "$seq_dir"' EXIT

table="$out/$TAG/table.md"
raw="$out/$TAG/scores.tsv"
: >"$raw"
for v in $VIEWS; do
  ref=$(reference "$v")
  floor=$(score "$ref" "$(floor_of "$v")" | cut -d' ' -f1)
  for c in $CONFIGS; do
    dir="$out/$TAG/$v-$c"
    mkdir -p "$dir"
    if [ ! -e "$dir/frame-$last.exr" ]; then
      seq_dir=$(mktemp -d "$out/$TAG/seq.XXXX")
      # shellcheck disable=SC2046,SC2086
      "$bin" render --gi ddgi --backend "$BACKEND" --scene "$(view_field "$v" 2)" \
        --camera-pos="$(view_field "$v" 3)" --camera-target="$(view_field "$v" 4)" --fov-y "$(view_field "$v" 5)" \
        --width "$W" --height "$H" --frames "$last" $(view_field "$v" 6 | sed 's/--no-bump/--set normal_maps=false/') \
        $(config_flags "$c") $EXTRA --sequence "$seq_dir" --sequence-exr --stats "$dir/stats.json" \
        --out "$dir/final.exr" >/dev/null 2>"$dir/render.log"
      for f in $FRAMES_AT; do
        cp "$(printf '%s/frame-%04d.exr' "$seq_dir" $((f - 1)))" "$dir/frame-$f.exr"
      done
      # The convergence series: FLIP and mean ratio every SERIES_STEP frames.
      for ((f = SERIES_STEP; f <= last; f += SERIES_STEP)); do
        printf '%s\t%s\n' "$f" "$(score "$ref" "$(printf '%s/frame-%04d.exr' "$seq_dir" $((f - 1)))")"
      done >"$dir/series.tsv"
      rm -rf "$seq_dir"
      seq_dir=""
    fi
    for f in $FRAMES_AT; do
      sheet=""
      [ "$f" = "$last" ] && sheet="$dir/sheet-$f.png"
      printf '%s\t%s\t%s\t%s\t%s\n' "$v" "$c" "$f" "$floor" "$(score "$ref" "$dir/frame-$f.exr" "$sheet")" >>"$raw"
    done
  done
done

# The table: per view and configuration, FLIP at each scored frame, then the
# dark fraction and mean ratio at the last; the mean and the worst per column.
python3 - "$raw" "$FRAMES_AT" "$TAG" >"$table" <<'PY'
import sys
from collections import defaultdict
raw, frames, tag = sys.argv[1], sys.argv[2].split(), sys.argv[3]
rows = defaultdict(dict)
floors, order_v, order_c = {}, [], []
for line in open(raw):
    v, c, f, floor, s = line.rstrip("\n").split("\t")
    flip, dark, ratio = (float(x) for x in s.split())
    rows[(v, c)][f] = (flip, dark, ratio)
    floors[v] = float(floor)
    order_v += [v] if v not in order_v else []
    order_c += [c] if c not in order_c else []
last = frames[-1]
print(f"View set, run `{tag}`: HDR-FLIP against Mitsuba 3 at frames {', '.join(frames)};")
print(f"dark fraction and mean ratio (test / reference, RGB mean) at frame {last}.\n")
head = " | ".join(f"FLIP {f}" for f in frames)
for c in order_c:
    print(f"**{c}**\n")
    print(f"| view | Mitsuba floor | {head} | {last} − 100 | dark {last} | ratio {last} |")
    print("|---|---|" + "---|" * (len(frames) + 3))
    cols = defaultdict(list)
    for v in order_v:
        r = rows.get((v, c))
        if not r:
            continue
        flips = [r[f][0] for f in frames]
        gap = r[last][0] - r["100"][0] if "100" in r else float("nan")
        vals = flips + [gap, r[last][1], r[last][2]]
        for i, x in enumerate(vals):
            cols[i].append(x)
        print(f"| {v} | {floors[v]:.3f} | " + " | ".join(f"{x:.3f}" for x in flips)
              + f" | {gap:+.3f} | {r[last][1]:.3f} | {r[last][2]:.3f} |")
    n = len(frames)
    mean = [sum(x) / len(x) for x in cols.values()]
    worst = [max(cols[i]) for i in range(n)] + [max(cols[n], key=abs), max(cols[n + 1]),
                                               max(cols[n + 2], key=lambda x: abs(x - 1))]
    print("| **mean** | | " + " | ".join(f"{x:.3f}" for x in mean[:n])
          + f" | {mean[n]:+.3f} | {mean[n + 1]:.3f} | {mean[n + 2]:.3f} |")
    print("| **worst** | | " + " | ".join(f"{x:.3f}" for x in worst[:n])
          + f" | {worst[n]:+.3f} | {worst[n + 1]:.3f} | {worst[n + 2]:.3f} |\n")
PY
cat "$table"
