#!/usr/bin/env python3
"""What each foveation level costs the eye by FovVideoVDP, from the frames scripts/perceptual.sh wrote.

FovVideoVDP (Mantiuk et al., "FovVideoVDP: A visible difference predictor for wide field-of-view
video", SIGGRAPH 2021; `pyfvvdp` on PyPI, licence CC BY-NC 4.0: a measuring tool run from a script,
never shipped or linked) predicts how visible the difference between a frame and its reference is
to an eye that fixates one point, as a quality in JODs (just-objectionable differences: 10 is
indistinguishable from the reference, each unit less is one in which 75% of observers prefer the
reference). Where FLIP (scripts/perceptual.py) gives an error per eccentricity band, FovVideoVDP
weighs the whole frame by the eye's own falloff of sensitivity with eccentricity, so it says in one
figure whether a level's periphery is visible at all from where the eye looks.

For each run of perceptual.sh (HEADSET-GAZE-LEVEL[-smooth]) it compares the left eye's last frame
with the same frame at level NONE, as the eye that fixates:
- for fixed foveation, the projection centre;
- with the gaze, the left eye's own line of sight (perceptual.py's `left_eye_gaze`).
The display is the model's head-mounted display (`standard_hmd`: 100 cd/m²) with the frame's own
resolution and horizontal field of view from the located FOV, so its pixels per degree are the eye
buffer's at its centre. FovVideoVDP takes a flat display of uniform pixels per degree; an eye
buffer's pixels per degree fall off towards its edges, so its figures for the outer periphery are
conservative (it sees finer pixels there than the eye buffer has).

Usage: fovvideovdp.py FRAMES_DIR OUT_DIR. Writes OUT_DIR/fovvideovdp.md and fovvideovdp.json.
Runs on the CPU (about 20 s a frame on two cores) or on a GPU where torch finds one.
"""

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import torch
import pyfvvdp

from perceptual import GAZE, LEVELS, fovs, last_left_frame, left_eye_gaze, load


def fixation_pixel(shape, fov, gaze_tan):
    """The pixel (x right, y down) the gaze's ray (tangents right and up) passes through."""
    h, w = shape
    l, r, u, d = (math.tan(a) for a in fov)
    gx, gy = gaze_tan
    return [(gx - l) / (r - l) * w, (u - gy) / (u - d) * h]


def metric(shape, fov, device):
    h, w = shape
    horizontal = math.degrees(fov[1] - fov[0])
    geometry = pyfvvdp.fvvdp_display_geometry([w, h], distance_m=3, fov_horizontal=horizontal)
    return pyfvvdp.fvvdp(
        display_name="standard_hmd",
        display_geometry=geometry,
        foveated=True,
        quiet=True,
        device=device,
    )


def analyse(frames_dir):
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    rows = []
    for ref_dir in sorted(frames_dir.glob("*-*-none")):
        headset, gaze, _ = ref_dir.name.split("-")
        fov = fovs((ref_dir / "run.txt").read_text())
        ref = load(last_left_frame(ref_dir, "none"))
        fixation = fixation_pixel(ref.shape[:2], fov, left_eye_gaze(GAZE[gaze]))
        vdp = metric(ref.shape[:2], fov, device)
        ref_t = torch.tensor(ref)
        for level in LEVELS:
            jod = {}
            for smooth in (False, True):
                run = frames_dir / f"{headset}-{gaze}-{level}{'-smooth' if smooth else ''}"
                if not run.is_dir():
                    continue
                img = load(last_left_frame(run, level))
                q, _ = vdp.predict(
                    torch.tensor(img),
                    ref_t,
                    dim_order="HWC",
                    fixation_point=torch.tensor(fixation),
                )
                jod["reconstructed" if smooth else "blocky"] = float(q)
                print(f"{headset} {gaze} {level} {'smooth' if smooth else 'blocky'}: {float(q):.3f} JOD")
            rows.append(
                {
                    "headset": headset,
                    "gaze": gaze,
                    "level": level,
                    "fixation_px": [round(fixation[0], 1), round(fixation[1], 1)],
                    **jod,
                }
            )
    return rows


def table(rows):
    out = [
        "**FovVideoVDP quality of the left eye's frame against full rate, in JOD "
        "(10 = indistinguishable), fixating the gaze**\n",
        "| headset | gaze | level | blocky | reconstructed |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        cells = [f"{r[k]:.2f}" if k in r else "–" for k in ("blocky", "reconstructed")]
        out.append(f"| {r['headset']} | {r['gaze']} | {r['level']} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    frames_dir, out = (Path(a) for a in sys.argv[1:])
    torch.set_num_threads(max(1, len(os.sched_getaffinity(0))))
    rows = analyse(frames_dir)
    if not rows:
        raise SystemExit(f"{frames_dir}: no runs")
    out.mkdir(parents=True, exist_ok=True)
    (out / "fovvideovdp.json").write_text(json.dumps(rows, indent=1))
    text = table(rows)
    (out / "fovvideovdp.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
