#!/usr/bin/env python3
"""What each foveation level costs the eye, from frames the example read back (scripts/perceptual.sh).

For one eye's frame at each level and the same frame at level NONE (full rate, the reference), per
band of eccentricity (degrees from where the eye looks: the projection centre for fixed foveation;
for eye-tracked foveation, the left eye's own line of sight to where the scripted gaze meets the
fixation plane, as fovea's model places the fovea, docs/eye-tracking.md "Into each eye": the
simulated tracker's gaze is the head's, and at 1 m the left eye, 31.5 mm to the left, looks 1.7°
further right than the head's 15°):

- FLIP (NVIDIA's perceptual difference metric, `flip-evaluator`, BSD-3-Clause; Andersson et al.,
  "FLIP: A Difference Evaluator for Alternating Images", HPG 2020): the mean of its per-pixel error
  (0 identical, 1 the largest difference), at the pixels per degree of the eye buffer's centre;
- identical: the share of pixels equal to the reference's (the fovea must be 1.000), and the
  nearest pixel that differs, in degrees from the gaze, beside the nearest pixel whose texel in
  the density map read back with the frame is below full rate (what the map asked for);
- blocky: the share of 2×2 pixel blocks (aligned to the image's origin, as fragments are) whose four
  pixels are all identical: what coarse fragments leave (a 2×2 or larger fragment makes every such
  block inside it uniform), against the reference's own share (the scene is textured down to the
  pixel, so at full rate few are). The same measure as `fovea_vkdouble::blocks::uniform_share`.

A control, from the fixed reference frame alone (no layer, no double): the frame shaded at one
fragment size everywhere (2×2, 4×4), each fragment's value the mean of its middle pixels in linear
light (the double's stand-in for the value at the fragment's centre, crates/vkdouble/src/layer/centre.rs),
shown as blocks and as the bilinear blend between fragment centres (reconstruction's rule,
docs/reconstruction.md), FLIP per band: what the metric makes of blocks against the blend on this
scene, apart from fovea's maps and shaders.

Each figure is given for the frame as shaded (coarse blocks: FOVEA_SUBSAMPLED=off) and, where a run
with reconstruction exists (folder HEADSET-GAZE-LEVEL-smooth, FOVEA_SUBSAMPLED=on), for the
reconstructed frame in the "reconstructed" rows; where that frame is identical to the blocky one
(fovea without reconstruction ignores the setting) the rows say so instead of repeating figures.

Usage: perceptual.py FRAMES_DIR MODEL_JSON_DIR OUT_DIR, where FRAMES_DIR holds one folder per run
named HEADSET-GAZE-LEVEL (or HEADSET-GAZE-LEVEL-smooth) with the example's PNGs and a `run.txt` of
its stdout (the located FOVs),
and MODEL_JSON_DIR holds `fovea report --headset H --json` as H.json. Writes OUT_DIR/table.md,
OUT_DIR/table.json (the runs) and OUT_DIR/control.json (the control).

It is a measuring tool, run from a script: nothing of fovea links it.
"""

import json
import math
import re
import sys
from pathlib import Path

import numpy as np
from PIL import Image
import flip_evaluator as flip

# The levels' floors change at 15° (HIGH), 20° (MEDIUM) and 30° (HIGH): docs/density-model.md#floors.
BANDS = [(0, 10), (10, 15), (15, 20), (20, 30), (30, 45), (45, 180)]
LEVELS = ["low", "medium", "high"]
# Where the scripted gaze looks (perceptual.sh's FOVEA_SIM_GAZE): yaw right, pitch up, degrees.
GAZE = {"fixed": (0.0, 0.0), "gaze": (15.0, 8.0)}
# Where fovea's model puts the eyes' fixation (gaze_fixation_m's default) and the simulated
# runtime's left eye (IPD 63 mm, crates/sim/src/space.rs), metres.
FIXATION_M = 1.0
LEFT_EYE_X_M = -0.0315


def left_eye_gaze(gaze_deg):
    """The left eye's line of sight, as tangents (right, up), to where the head's gaze (yaw, pitch:
    the tracker's, as crates/model/src/gaze.rs turns it into a direction) meets the fixation
    plane; straight ahead (fixed foveation) stays straight ahead."""
    if gaze_deg == (0.0, 0.0):
        return 0.0, 0.0
    yaw, pitch = (math.radians(a) for a in gaze_deg)
    x = math.cos(pitch) * math.sin(yaw) * FIXATION_M - LEFT_EYE_X_M
    y = math.sin(pitch) * FIXATION_M
    z = math.cos(pitch) * math.cos(yaw) * FIXATION_M
    return x / z, y / z


def fovs(run_txt):
    """The left view's located FOV (left, right, up, down radians) from the example's stdout."""
    m = re.search(r"located FOVs in radians \(left,right,up,down per view\) (\S+)", run_txt)
    return [float(v) for v in m.group(1).split(",")]


def last_left_frame(folder, level):
    frames = sorted(folder.glob(f"f*_{level}_left.png"))
    if not frames:
        raise SystemExit(f"{folder}: no frame of the left eye at {level}")
    return frames[-1]


def load(path):
    return np.asarray(Image.open(path).convert("RGB"))


def eccentricity(shape, fov, gaze_tan):
    """Degrees between each pixel's ray and the gaze's (tangents right and up)."""
    h, w = shape
    l, r, u, d = (math.tan(a) for a in fov)
    tx = l + (np.arange(w) + 0.5) / w * (r - l)
    ty = u - (np.arange(h) + 0.5) / h * (u - d)
    x, y = np.meshgrid(tx, ty)
    gx, gy = gaze_tan
    dot = x * gx + y * gy + 1.0
    norm = np.sqrt(x * x + y * y + 1.0) * math.sqrt(gx * gx + gy * gy + 1.0)
    return np.degrees(np.arccos(np.clip(dot / norm, -1.0, 1.0)))


def uniform_2x2(img):
    """Per 2×2 block: all four pixels identical."""
    h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
    a = img[:h:2, :w:2]
    same = (img[:h:2, 1:w:2] == a).all(-1) & (img[1:h:2, :w:2] == a).all(-1)
    return same & (img[1:h:2, 1:w:2] == a).all(-1)


def centre_ppd(shape, fov):
    """Pixels per degree at the projection centre: pixels per unit tangent, per radian there."""
    l, r = math.tan(fov[0]), math.tan(fov[1])
    return shape[1] / (r - l) * math.pi / 180.0


def analyse(frames_dir, models_dir):
    rows = []
    for ref_dir in sorted(frames_dir.glob("*-*-none")):
        headset, gaze, _ = ref_dir.name.split("-")
        fov = fovs((ref_dir / "run.txt").read_text())
        ref_path = last_left_frame(ref_dir, "none")
        ref = load(ref_path)
        ecc = eccentricity(ref.shape[:2], fov, left_eye_gaze(GAZE[gaze]))
        ecc_blocks = ecc[: ecc.shape[0] // 2 * 2 : 2, : ecc.shape[1] // 2 * 2 : 2]
        ppd = centre_ppd(ref.shape[:2], fov)
        model = json.loads((models_dir / f"{headset}.json").read_text())
        fractions = {lv["level"]: lv["shaded_fraction"] for lv in model["levels"]}
        ref_blocks = uniform_2x2(ref)
        blocky_frames = {}
        for level, smooth in [("none", False)] + [(lv, sm) for lv in LEVELS for sm in (False, True)]:
            run = frames_dir / f"{headset}-{gaze}-{level}{'-smooth' if smooth else ''}"
            if not run.is_dir():
                continue
            path = last_left_frame(run, level)
            if path.name.split("_")[0] != ref_path.name.split("_")[0]:
                raise SystemExit(f"{path} and {ref_path} are not the same frame")
            img = load(path)
            if not smooth:
                blocky_frames[level] = img
            elif level in blocky_frames and np.array_equal(img, blocky_frames[level]):
                # FOVEA_SUBSAMPLED=on changed nothing: this fovea has no reconstruction.
                rows.append(
                    {"headset": headset, "gaze": gaze, "level": level, "reconstructed": None}
                )
                continue
            if level == "none":
                error = np.zeros(ecc.shape, np.float32)
            else:
                error, _, _ = flip.evaluate(
                    ref.astype(np.float32) / 255.0,
                    img.astype(np.float32) / 255.0,
                    "LDR",
                    inputsRGB=True,
                    applyMagma=False,
                    computeMeanError=True,
                    parameters={"ppd": ppd},
                )
            error = np.asarray(error).reshape(ecc.shape)
            same = (img == ref).all(-1)
            blocks = uniform_2x2(img)
            bands = []
            for lo, hi in BANDS:
                m = (ecc >= lo) & (ecc < hi)
                mb = (ecc_blocks >= lo) & (ecc_blocks < hi)
                if not m.any():
                    bands.append(None)
                    continue
                bands.append(
                    {
                        "flip": float(error[m].mean()),
                        "identical": float(same[m].mean()),
                        "blocky": float(blocks[mb].mean()) if mb.any() else None,
                        "blocky_full_rate": float(ref_blocks[mb].mean()) if mb.any() else None,
                        "pixels": int(m.sum()),
                    }
                )
            # The same from the density map read back with the frame: the nearest pixel whose
            # texel is below full rate, which tells the map's fovea from what the renderer did.
            map_path = path.with_name(path.name.replace(f"_{level}_left", f"_{level}_density_left"))
            map_nearest = None
            if map_path.is_file() and level != "none":
                m = np.asarray(Image.open(map_path).convert("RGB"))
                texel = ref.shape[1] // m.shape[1]
                full = (m[..., 0] == 255) & (m[..., 1] == 255)
                full = np.repeat(np.repeat(full, texel, 0), texel, 1)
                pad = np.ones(ecc.shape, bool)
                h, w = min(full.shape[0], ecc.shape[0]), min(full.shape[1], ecc.shape[1])
                pad[:h, :w] = full[:h, :w]
                if (~pad).any():
                    map_nearest = float(ecc[~pad].min())
            rows.append(
                {
                    "headset": headset,
                    "gaze": gaze,
                    "level": level,
                    "reconstructed": smooth,
                    "map_nearest_change_deg": map_nearest,
                    "shaded_fraction": fractions.get(level),
                    "ppd": ppd,
                    "frame": path.name,
                    "size": [int(ref.shape[1]), int(ref.shape[0])],
                    "flip_mean": float(error.mean()),
                    # Degrees from the gaze of the nearest pixel that differs from full rate.
                    "nearest_change_deg": float(ecc[~same].min()) if (~same).any() else None,
                    "bands": bands,
                }
            )
    return rows


def to_linear(s):
    return np.where(s <= 0.04045, s / 12.92, ((s + 0.055) / 1.055) ** 2.4)


def to_srgb8(lin):
    lin = np.clip(lin, 0.0, 1.0)
    s = np.where(lin <= 0.0031308, lin * 12.92, 1.055 * lin ** (1 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


def shaded_at(lin, size):
    """Per size×size fragment (aligned to the origin): the mean of its middle 2×2 (1 for size 1)."""
    a, b = (size - 1) // 2, size // 2
    return (lin[a::size, a::size] + lin[a::size, b::size] + lin[b::size, a::size]
            + lin[b::size, b::size]) / 4.0


def blocks_of(values, size):
    return np.repeat(np.repeat(values, size, 0), size, 1)


def blend_of(values, size, shape):
    """Bilinear between fragment centres (pixel coordinate i·size + size/2), clamped at the edges."""
    h, w = shape

    def axis(n, count):
        g = (np.arange(n) + 0.5 - size / 2.0) / size
        g0 = np.floor(g)
        f = g - g0
        i0 = np.clip(g0.astype(int), 0, count - 1)
        return i0, np.clip(i0 + 1, 0, count - 1), f

    y0, y1, fy = axis(h, values.shape[0])
    x0, x1, fx = axis(w, values.shape[1])
    fy, fx = fy[:, None, None], fx[None, :, None]
    top = values[y0][:, x0] * (1 - fx) + values[y0][:, x1] * fx
    bottom = values[y1][:, x0] * (1 - fx) + values[y1][:, x1] * fx
    return top * (1 - fy) + bottom * fy


def control(frames_dir):
    """FLIP per band of the fixed reference shaded at one size everywhere: blocks and blend."""
    rows = []
    for ref_dir in sorted(frames_dir.glob("*-fixed-none")):
        headset = ref_dir.name.split("-")[0]
        fov = fovs((ref_dir / "run.txt").read_text())
        ref = load(last_left_frame(ref_dir, "none"))
        ppd = centre_ppd(ref.shape[:2], fov)
        for size in (2, 4):
            h, w = ref.shape[0] // size * size, ref.shape[1] // size * size
            crop = ref[:h, :w]
            ecc = eccentricity(ref.shape[:2], fov, left_eye_gaze(GAZE["fixed"]))[:h, :w]
            values = shaded_at(to_linear(crop.astype(np.float64) / 255.0), size)
            for form, lin in (("blocks", blocks_of(values, size)),
                              ("blend", blend_of(values, size, (h, w)))):
                error, _, _ = flip.evaluate(
                    crop.astype(np.float32) / 255.0,
                    to_srgb8(lin).astype(np.float32) / 255.0,
                    "LDR",
                    inputsRGB=True,
                    applyMagma=False,
                    computeMeanError=True,
                    parameters={"ppd": ppd},
                )
                error = np.asarray(error).reshape(h, w)
                bands = [
                    float(error[(ecc >= lo) & (ecc < hi)].mean())
                    if ((ecc >= lo) & (ecc < hi)).any() else None
                    for lo, hi in BANDS
                ]
                rows.append({"headset": headset, "size": size, "form": form, "flip": bands})
    return rows


def control_table(rows):
    heads = " | ".join(f"{lo}–{hi}°" if hi < 180 else f"≥{lo}°" for lo, hi in BANDS)
    out = [
        "**Control: FLIP per band of the fixed reference shaded at one size everywhere, "
        "as blocks and as the blend between fragment centres**\n",
        f"| headset | fragment | form | {heads} |",
        "|---|---|---|" + "---|" * len(BANDS),
    ]
    for r in rows:
        cells = " | ".join("–" if v is None else f"{v:.3f}" for v in r["flip"])
        out.append(f"| {r['headset']} | {r['size']}×{r['size']} | {r['form']} | {cells} |")
    out.append("")
    return "\n".join(out)


def cell(band, key):
    if band is None or band.get(key) is None:
        return "–"
    return f"{band[key]:.3f}"


def table(rows):
    heads = " | ".join(f"{lo}–{hi}°" if hi < 180 else f"≥{lo}°" for lo, hi in BANDS)
    out = []
    for key, title in [
        ("flip", "FLIP mean error per eccentricity band (0 = identical to full rate)"),
        ("blocky", "Uniform 2×2 blocks per band (full rate's own share in brackets)"),
        ("identical", "Pixels identical to full rate per band"),
    ]:
        out.append(f"**{title}**\n")
        near = key == "identical"
        extra = " nearest change (map's) |" if near else ""
        out.append(f"| headset | gaze | level | shaded | {heads} |{extra} reconstructed |")
        out.append("|---|---|---|---|" + "---|" * (len(BANDS) + near) + "---|")
        for r in rows:
            if key != "blocky" and r["level"] == "none":
                continue
            if r["reconstructed"] is None:
                blank = " | ".join("–" for _ in range(len(BANDS) + near))
                out.append(
                    f"| {r['headset']} | {r['gaze']} | {r['level']} | – | {blank} | "
                    "no effect: FOVEA_SUBSAMPLED=on left the frame as shaded |"
                )
                continue
            if key == "blocky":
                cells = [
                    "–"
                    if b is None or b["blocky"] is None
                    else f"{b['blocky']:.3f} ({b['blocky_full_rate']:.3f})"
                    for b in r["bands"]
                ]
            else:
                cells = [cell(b, key) for b in r["bands"]]
            frac = "–" if r["shaded_fraction"] is None else f"{r['shaded_fraction']:.3f}"
            if near:
                n, m = r["nearest_change_deg"], r.get("map_nearest_change_deg")
                cells.append(
                    ("–" if n is None else f"{n:.1f}°") + ("" if m is None else f" ({m:.1f}°)")
                )
            out.append(
                f"| {r['headset']} | {r['gaze']} | {r['level']} | {frac} | "
                + " | ".join(cells)
                + (" | yes |" if r["reconstructed"] else " | no |")
            )
        out.append("")
    return "\n".join(out)


def main():
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    frames_dir, models_dir, out = (Path(a) for a in sys.argv[1:])
    rows = analyse(frames_dir, models_dir)
    # Each level's blocky row, then its reconstructed one.
    order = {"none": 0, "low": 1, "medium": 2, "high": 3}
    rows.sort(key=lambda r: (r["headset"], r["gaze"], order[r["level"]], bool(r["reconstructed"])))
    if not rows:
        raise SystemExit(f"{frames_dir}: no runs")
    controls = control(frames_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.json").write_text(json.dumps(rows, indent=1))
    (out / "control.json").write_text(json.dumps(controls, indent=1))
    text = table(rows) + "\n" + control_table(controls)
    (out / "table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
