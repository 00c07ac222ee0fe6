#!/usr/bin/env python3
"""What a reconstruction's depth error against the lidar is made of: AbsRel by lidar range and at depth edges.

usage: depth-error-parts.py RECONSTRUCTION EXPORT

RECONSTRUCTION is a `dggt reconstruct` output folder of an export's consecutive frames from frame 0 (its
`depth/{i:03}_{cam}.npy`: the network's z-depth per pixel at the network's size, up to scale); EXPORT is the scene
export it reconstructed, with `depth_flows_4/` (`dggt convert --depth-flows boxes`: the lidar's z-depth per 4x4
cell of the original image, 0 where no return). Each lidar cell's centre (4 col + 2, 4 row + 2) is scaled to the
network's size (width and height separately, as the preprocessing resizes) and the predicted depth read at the
nearest pixel; per view the prediction is fitted to the lidar by least-squares scale and shift (as `dggt eval`
scores depth), then |fit - lidar| / lidar is averaged: over all cells, per lidar range, and apart for the cells
whose predicted 3x3 neighbourhood spans more than a factor 1.3 in depth (a depth edge at the network's size).
"""
import sys
from pathlib import Path

import numpy as np

EDGE_RATIO = 1.3
RANGES_M = [(0, 10), (10, 20), (20, 40), (40, 80), (80, float("inf"))]


def view_cells(predicted, lidar, original_size):
    """(lidar depth, fitted prediction, at an edge) of one view's cells with a return."""
    height, width = predicted.shape
    rows, cols = np.nonzero(lidar > 0)
    x = (4 * cols + 2.0) * width / original_size[0] - 0.5
    y = (4 * rows + 2.0) * height / original_size[1] - 0.5
    xi = np.clip(np.round(x).astype(int), 0, width - 1)
    yi = np.clip(np.round(y).astype(int), 0, height - 1)
    guess, truth = predicted[yi, xi].astype(np.float64), lidar[rows, cols].astype(np.float64)
    padded = np.pad(predicted, 1, mode="edge")
    around = np.stack([padded[1 + dy:1 + dy + height, 1 + dx:1 + dx + width] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    edge = (around.max(0) / np.maximum(around.min(0), 1e-6))[yi, xi] > EDGE_RATIO
    (scale, shift), *_ = np.linalg.lstsq(np.stack([guess, np.ones_like(guess)], 1), truth, rcond=None)
    return truth, scale * guess + shift, edge


def main():
    reconstruction, export = Path(sys.argv[1]), Path(sys.argv[2])
    original_size = (960, 540)
    parts = []
    for path in sorted((reconstruction / "depth").glob("*.npy")):
        lidar_file = export / "depth_flows_4" / path.name
        if not lidar_file.is_file():
            sys.exit(f"{lidar_file}: missing (convert the export with --depth-flows boxes)")
        lidar = np.load(lidar_file)[..., 0]
        original_size = (lidar.shape[1] * 4, lidar.shape[0] * 4)
        parts.append(view_cells(np.load(path), lidar, original_size))
    if not parts:
        sys.exit(f"{reconstruction / 'depth'}: no depth maps")
    truth, fit, edge = (np.concatenate(p) for p in zip(*parts))
    error = np.abs(fit - truth) / truth
    print(f"{len(parts)} views, {len(truth)} lidar cells, AbsRel {error.mean():.3f}")
    print("| cells | share of cells | AbsRel | share of the error |\n|---|---:|---:|---:|")
    groups = [(f"lidar {lo:g}-{hi:g} m", (truth >= lo) & (truth < hi)) for lo, hi in RANGES_M]
    groups += [(f"at a depth edge (3x3 span > {EDGE_RATIO})", edge), ("elsewhere", ~edge)]
    for name, mask in groups:
        print(f"| {name} | {mask.mean() * 100:.1f} % | {error[mask].mean():.3f} | {error[mask].sum() / error.sum() * 100:.1f} % |")


if __name__ == "__main__":
    main()
