"""Single-photo rho on real photo pairs (a shadow photo and a shadow-free one of the same scene); print JSON.

Usage: nice -n 5 python examples/real_pairs.py PAIRS_DIR [--pair SHADOW.jpg:FREE.jpg ...]
                                               [--row-bands 40:150,150:200,200:250,250:425]

Default pairs: DSC_0569.jpg:DSC_0570.jpg (asphalt) and p21_1.jpg:p21_n.jpg
(concrete steps). The photos carry no licence and are not part of the
project: point PAIRS_DIR at your own copy.

Each shadow photo is read with ``fitting.read_photo`` and measured with
``measure_shadow_edges`` as `softshadow fit` does. The reference is the
ratio image shadow / shadow-free (both Gaussian-smoothed by 1 px), divided
by the same ratio on the lit ground (the exposures differ), two ways:

- at the profiles: per kept profile, the median ratio on its umbra plateau
  over that on its lit plateau; the median over profiles;
- umbra-wide: the median ratio over the umbra (an Otsu threshold of the log
  ratio image, eroded by 4 px) over the median on the lit ground (the
  other side of the threshold, eroded by 4 px).

With --row-bands, the umbra-wide reference is also given per band of image
rows (for ground that is not flat: each surface of a step has its own rho).

The shadow-free photos are measured too: they should show no shadow edge,
or be flagged unreliable.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage.filters import threshold_otsu

DEFAULT_PAIRS = ("DSC_0569.jpg:DSC_0570.jpg", "p21_1.jpg:p21_n.jpg")


def references(m, gray: np.ndarray, free_gray: np.ndarray, bands=()) -> tuple[float | None, float, dict]:
    """(reference at the kept profiles or None, umbra-wide reference, {band: umbra-wide reference in those rows})."""
    from benchmarks.pair_reference import attenuation_image, reference_at_profiles
    ratio = attenuation_image(gray, free_gray)
    at_profiles = reference_at_profiles(m, ratio)
    log_ratio = np.log(np.maximum(ratio, 1e-6))
    cut = threshold_otsu(log_ratio)
    umbra = ndimage.binary_erosion(log_ratio < cut, iterations=4)
    lit = ndimage.binary_erosion(log_ratio >= cut, iterations=4)
    lit_level = np.median(ratio[lit])
    wide = float(np.median(ratio[umbra]) / lit_level)
    per_band = {}
    for lo, hi in bands:
        rows = np.zeros_like(umbra)
        rows[lo:hi] = True
        if (umbra & rows).any():
            per_band[f"{lo}:{hi}"] = float(np.median(ratio[umbra & rows]) / lit_level)
    return at_profiles, wide, per_band


def main(argv=None) -> None:
    from fitting import read_photo
    from fitting.edges.measure import measure_shadow_edges

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs_dir")
    ap.add_argument("--pair", action="append", help="SHADOW:FREE file names (default: the two known pairs)")
    ap.add_argument("--row-bands", default="", help="LO:HI,... image row bands for per-surface references")
    args = ap.parse_args(argv)
    bands = [tuple(int(v) for v in b.split(":")) for b in args.row_bands.split(",") if b]
    root = Path(args.pairs_dir)
    rows = []
    for pair in args.pair or DEFAULT_PAIRS:
        shadow_name, free_name = pair.split(":")
        shadow, free = read_photo(root / shadow_name), read_photo(root / free_name)
        for photo in (shadow, free):
            start = time.process_time()
            m = measure_shadow_edges(photo.gray, mask=photo.saturated, linear_rgb=photo.linear)
            row = {"photo": photo.name, "rho": None if not m.edges_found else m.rho,
                   "rho_stderr": None if not m.edges_found else m.rho_stderr, "profiles": m.n_profiles,
                   "reliable": m.reliable if m.edges_found else None, "warnings": list(m.warnings),
                   "reason": m.reason, "cpu_s": round(time.process_time() - start, 2)}
            if photo is shadow and m.edges_found:
                at, wide, per_band = references(m, shadow.gray.astype(float), free.gray.astype(float), bands)
                rows_kept = [int(round(p.position_uv[1])) for p in m.profiles if p.kept]
                row.update(reference_at_profiles=at, reference_umbra_wide=wide, reference_by_row_band=per_band,
                           kept_profile_rows=rows_kept,
                           error_at_profiles=None if at is None else m.rho - at, error_umbra_wide=m.rho - wide)
            rows.append(row)
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
