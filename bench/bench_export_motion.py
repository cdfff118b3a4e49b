"""Motion export (``lessmimic export-motion``) per format on a corpus's valid physicalized episodes:

* **size**: the export folder's bytes (motions, sidecars, meshes, manifest), in all and per second of motion;
* **write speed**: exported frames per second of writing (forward kinematics of every body, the format's file, the
  sidecar; the dataset's reading is timed apart, once per export). The Unitree CSV is written at 30 Hz, so its
  frames are fewer: the 50 Hz source frames per second are shown beside.

Run: ``make bench-export-motion [CORPUS=corpus]`` (a physicalized corpus: ``make corpus``).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from motion_export import FORMAT_NAMES
from motion_export.stage import export_motion


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--name", default="corpus", help="corpus: datasets/<NAME>/physicalized/ (default corpus)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        export_motion(a.name, FORMAT_NAMES[0], Path(tmp) / "warm-up", episode=0)  # imports, scene compile, caches
        rows = []
        for fmt in FORMAT_NAMES:
            s = export_motion(a.name, fmt, Path(tmp) / fmt)
            source_frames = s.frames if fmt != "unitree-csv" else round(s.seconds * 50)
            rows.append((fmt, s, source_frames))
        n = len(rows[0][1].episodes)
        print(f"datasets/{a.name}/physicalized/: {n} valid episodes, {rows[0][1].seconds:.0f} s of motion")
        print("| format | size [MB] | kB per s of motion | frames written | write [s] | frames/s | source frames/s "
              "| read [s] |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|")
        for fmt, s, src in rows:
            print(
                f"| {fmt} | {s.bytes / 1e6:.1f} | {s.bytes / 1e3 / s.seconds:.1f} | {s.frames} | {s.write_s:.2f} | "
                f"{s.frames / s.write_s:,.0f} | {src / s.write_s:,.0f} | {s.read_s:.2f} |"
            )


if __name__ == "__main__":
    main()
