"""Codebook lookup with and without a viewpoint prior: the AAE's box search of one detection on the CPU.

Builds a codebook of the full LM-O benchmark's size (1,000 view-sphere directions x 72 in-plane angles = 72,000
entries, random unit codes of 128 values) and times ``CodebookLookup`` (top-10 matches + neighbour average, as
``ImplicitPose6D`` runs it) for the 75 crops of ``--box-search`` against the same codebook restricted to the
benchmark's viewpoint prior (``Codebook.within(ViewpointRange((0, 90), 45))``), in the same run. Encoding is the
same either way and is not timed. Run: ``.venv/bin/python benchmarks/aae_viewpoints.py [--repeats 20]``.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from timing import median_seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=1000)
    parser.add_argument("--in-plane", type=int, default=72)
    parser.add_argument("--crops", type=int, default=75, help="codes per call (75: one box of --box-search)")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    print(f"CPU cores: {os.cpu_count()}, load average (1 min) at start: {os.getloadavg()[0]:.1f}")
    from paz6d.aae.codebook import Codebook, codebook_rotations, fibonacci_sphere, look_at_rotations
    from paz6d.aae.pipeline import CodebookLookup
    from paz6d.backend.viewpoints import ViewpointRange

    rng = np.random.default_rng(0)
    rotations = codebook_rotations(look_at_rotations(fibonacci_sphere(args.views)), args.in_plane)
    entries = len(rotations)
    everything = Codebook(rng.normal(size=(entries, 128)), rotations, np.tile([0.0, 0.0, 10.0, 10.0], (entries, 1)),
                          np.eye(3), 1.0)
    prior = ViewpointRange((0, 90), 45)
    restricted = everything.within(prior)
    codes = rng.normal(size=(args.crops, 128)).astype(np.float32)
    whole = median_seconds(lambda: CodebookLookup(everything)(codes), args.repeats)
    within = median_seconds(lambda: CodebookLookup(restricted)(codes), args.repeats)
    print(f"{args.crops} codes: whole sphere ({entries} entries) {1000 * whole:.1f} ms, {prior.describe()} "
          f"({len(restricted)} entries) {1000 * within:.1f} ms: {whole / within:.1f}x faster")


if __name__ == "__main__":
    main()
