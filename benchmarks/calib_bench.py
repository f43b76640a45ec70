"""Benchmark: stereo calibration of 21 pairs of 512 x 512 images, corner detection included.

The images are rendered by ``wingphoto.synth`` (the thesis-like rig, the 3 x 7 pan-tilt
schedule of the thesis); rendering is not timed. The timed call is the whole user-facing
step, ``calibrate_stereo(left_images, right_images, (9, 6), square_size)``: corner
detection and sub-pixel refinement in 42 images, both single-camera calibrations, the
joint refinement and the uncertainties. Target (issue 3): under 10 s on the 2-core
development machine.

Run: ``python benchmarks/calib_bench.py [--repeat 3] [--seed 0]``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (the best is reported)")
    parser.add_argument("--seed", type=int, default=0, help="synthetic rig and noise seed")
    args = parser.parse_args(argv)

    from wingphoto import synth
    from wingphoto.calibrate import calibrate_stereo, find_corners

    rig = synth.thesis_rig(seed=args.seed, jitter=1.0)
    t0 = time.perf_counter()
    cs = synth.render_calibration_set(rig, seed=args.seed)
    t_render = time.perf_counter() - t0
    n = len(cs.left_images)
    h, w = cs.left_images[0].shape

    t0 = time.perf_counter()
    for img in cs.left_images + cs.right_images:
        find_corners(img, cs.pattern_size)
    t_detect = time.perf_counter() - t0

    times = []
    for _ in range(max(1, args.repeat)):
        t0 = time.perf_counter()
        st = calibrate_stereo(cs.left_images, cs.right_images, cs.pattern_size, cs.square_size)
        times.append(time.perf_counter() - t0)

    u = st.uncertainty
    print(f"{n} pairs of {w}x{h} images (rendered in {t_render:.1f} s, not timed)")
    print(f"corner detection alone, {2 * n} images: {t_detect:.2f} s")
    print(f"calibrate_stereo end to end: best {min(times):.2f} s, runs " + ", ".join(f"{t:.2f}" for t in times))
    print(f"pairs used: {int(st.used.sum())} of {n}")
    print(f"pixel error left {st.pixel_error_left}, right {st.pixel_error_right}")
    print(f"T error vs truth: {st.rig.T - cs.rig.T} mm (3-sigma {u['T']})")
    print(f"om error vs truth: {st.rig.om - cs.rig.om} rad (3-sigma {u['om']})")
    return min(times)


if __name__ == "__main__":
    np.set_printoptions(precision=4, suppress=True)
    main()
