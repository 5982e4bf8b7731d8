#!/usr/bin/env python3
"""Convergence curves from `scripts/view-set.sh` runs: HDR-FLIP and the mean
ratio (test / reference) against frames, one line per run and configuration,
averaged over the views each has (issue "Converged in 100 frames…", goal 2).

    python3 scripts/convergence-plot.py OUT.png RUN_DIR [RUN_DIR...]

Each RUN_DIR is `OUT_DIR/TAG` of a view-set run; its `VIEW-CONFIG/series.tsv`
files (frame, FLIP, dark fraction, mean ratio) are read. Needs matplotlib.
Not part of CI.
"""

import sys
from collections import defaultdict
from pathlib import Path


# The view names: the first field of view-set.sh's view_table lines.
_SCRIPT = (Path(__file__).parent / "view-set.sh").read_text()
_TABLE = _SCRIPT.split("view_table() {", 1)[1].split("EOF\n}", 1)[0]
VIEWS = [line.split("|", 1)[0] for line in _TABLE.splitlines() if "|" in line]


def main() -> int:
    if len(sys.argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(sys.argv[1])
    fig, (ax_flip, ax_ratio) = plt.subplots(1, 2, figsize=(11, 4.2))
    # Per run and configuration, per view, its series; then only the views
    # every curve has, so the means compare like with like.
    series_by = {}
    for run in map(Path, sys.argv[2:]):
        for series in sorted(run.glob("*/series.tsv")):
            name = series.parent.name
            view = max((v for v in VIEWS if name.startswith(v + "-")), key=len, default=None)
            if view is not None:
                series_by.setdefault((run, name[len(view) + 1 :]), {})[view] = series
    common = set.intersection(*(set(v) for v in series_by.values())) if series_by else set()
    for run in map(Path, sys.argv[2:]):
        curves = defaultdict(lambda: defaultdict(list))  # config -> frame -> [(flip, ratio)]
        for (r, config), views in sorted(series_by.items()):
            if r != run:
                continue
            for view, series in sorted(views.items()):
                if view not in common:
                    continue
                for line in series.read_text().splitlines():
                    f, rest = line.split("\t")
                    flip, _dark, ratio = (float(x) for x in rest.split())
                    curves[config][int(f)].append((flip, ratio))
        for config, by_frame in sorted(curves.items()):
            frames = sorted(by_frame)
            views = len(by_frame[frames[0]])
            label = f"{run.name}: {config} ({views} view{'s' if views != 1 else ''})"
            mean = lambda i: [sum(x[i] for x in by_frame[f]) / len(by_frame[f]) for f in frames]  # noqa: E731
            ax_flip.plot(frames, mean(0), label=label)
            ax_ratio.plot(frames, mean(1), label=label)
    for ax, title in ((ax_flip, "HDR-FLIP against Mitsuba (mean over views)"), (ax_ratio, "mean ratio, test / reference")):
        ax.set_xlabel("frame")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.axvline(100, color="grey", lw=0.8, ls=":")
    ax_ratio.axhline(1.0, color="black", lw=0.8)
    ax_flip.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
