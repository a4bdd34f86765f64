"""Visual review material (``make review``, after ``make repro``).

1. ``data/review/review.rrd``: a few representative items of every stage's recording in one
   recording, one tab per stage (:mod:`viz.review_recording`); seconds, no browser.
2. ``reports/<stage>/rerun.png``: each stage's recording as Rerun's web viewer opens it,
   screenshotted in headless Chromium (:mod:`viz.screenshot`); the stage reports show them.
   Needs Debian's ``chromium``; about half a minute per recording on 2 cores.

Not a DVC stage: the combined recording is a view over the stages' recordings (rebuilt from
them in seconds, git-ignored), and the screenshots depend on the browser, not only on the
data. Exit code 2 when the recordings or the browser are missing.
"""

import argparse
import sys
from pathlib import Path

from PIL import Image

from viz.review_recording import REVIEW, build_review
from viz.screenshot import missing_tools, screenshot

MIN_FILL = 0.01  # a screenshot whose 3D view is emptier than this is refused


def small_png(path: Path) -> int:
    """Re-save ``path`` with a 256-colour palette (a few hundred KB → ~100 KB); its size."""
    Image.open(path).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)
    return path.stat().st_size


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/review.py", description=__doc__.splitlines()[0])
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--reports", default="reports", type=Path)
    ap.add_argument("--stages", nargs="*", default=list(REVIEW), choices=list(REVIEW))
    ap.add_argument("--no-screenshots", action="store_true")
    args = ap.parse_args(argv)
    try:
        kept = build_review(args.data_root, args.data_root / "review" / "review.rrd")
    except FileNotFoundError as err:
        print(f"ERROR: {err}", file=sys.stderr)
        return 2
    print(f"{args.data_root / 'review' / 'review.rrd'}: " +
          ", ".join(f"{s} {n} items" for s, n in kept.items()))
    if args.no_screenshots:
        return 0
    if missing := missing_tools():
        print(f"ERROR: screenshots need {', '.join(missing)}", file=sys.stderr)
        return 2
    for stage in args.stages:
        rrd = args.data_root / stage / f"{stage}.rrd"
        png = args.reports / stage / "rerun.png"
        shot = screenshot(rrd, png)
        if shot.view_fill < MIN_FILL:
            print(f"ERROR: {rrd}: the 3D view is nearly empty ({shot.view_fill:.4f}); see {png}",
                  file=sys.stderr)
            return 1
        print(f"{png}: 3D view fill {shot.view_fill:.3f}, settled in {shot.seconds:.0f} s, "
              f"{small_png(png) // 1024} KB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
