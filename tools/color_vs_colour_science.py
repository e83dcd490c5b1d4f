"""lumen's colour fits against colour-science's on the same camera RGB and XYZ.

Usage (the peers' virtual environment, ../shared/tools/peers-venv.sh):
    target/release/lumen color spectral --camera nikon-d5100 --illuminant d65 --out out/spectral-d65
    for m in linear-3x3 root-poly-2 root-poly-3; do
        target/release/lumen color fit --patches out/spectral-d65/rgb.csv \
            --reference out/spectral-d65/xyz.csv --white "$(tail -1 out/spectral-d65/white.csv)" \
            --model $m --out out/spectral-d65/$m.json
    done
    $PEERS_PY tools/color_vs_colour_science.py out/spectral-d65

Prints, per method, colour-science's mean ΔE2000 and leave-one-out mean on lumen's patch
values, lumen's, and the largest per-patch difference of the two fits' ΔE2000.

On photographs, with the patch values `lumen color fit` sampled (the chart found by itself):
    for f in ../shared/data/color/photos/*.jpg; do
        for m in linear-3x3 root-poly-2 root-poly-3; do
            target/release/lumen color fit --image $f --model $m --out out/photos/$(basename $f .jpg)/$m.json
        done
    done
    $PEERS_PY tools/color_vs_colour_science.py --photos out/photos [--csv tests/data/chart-photos/colour-science.csv]
Prints, per photograph and method, colour-science's leave-one-out mean ΔE2000 on the same
sampled values and reference, and lumen's, then the median and largest of each; --csv also
writes colour-science's figures (image,model,loo_mean_de2000), which the pipeline's `chart`
cases on the photographs show beside lumen's.
"""
import json
import sys
import warnings

import numpy as np

warnings.filterwarnings("ignore")
import colour  # noqa: E402


def table(path):
    rows = [l for l in open(path) if l.strip() and not l.startswith("#")][1:]
    return np.array([[float(v) for v in r.split(",")[1:]] for r in rows])


METHODS = {
    "linear-3x3": dict(method="Cheung 2004", terms=3),
    "root-poly-2": dict(method="Finlayson 2015", degree=2),
    "root-poly-3": dict(method="Finlayson 2015", degree=3),
}


def loo_mean(rgb, xyz, lab, kw):
    loo = []
    for i in range(len(rgb)):
        keep = np.arange(len(rgb)) != i
        p = colour.colour_correction(rgb[i], rgb[keep], xyz[keep], **kw)
        loo.append(colour.delta_E(lab(p), lab(xyz[i]), method="CIE 2000"))
    return float(np.mean(loo))


def photos(root, csv_path=None):
    import os
    rows = {m: [] for m in METHODS}
    csv_rows = []
    print(f"{'photograph':<12} " + " ".join(f"{m + ' cs':>16} {m + ' lumen':>18}" for m in METHODS))
    for name in sorted(os.listdir(root)):
        line = f"{name:<12} "
        for m, kw in METHODS.items():
            j = json.load(open(f"{root}/{name}/{m}.json"))
            used = [p for p in j["report"]["patches"] if p["used"]]
            rgb = np.array([p["rgb"] for p in used])
            xyz = np.array([p["reference_xyz"] for p in used])
            xy = colour.XYZ_to_xy(np.array(j["white"]))
            lab = lambda v: colour.XYZ_to_Lab(v, illuminant=xy)  # noqa: E731
            cs = loo_mean(rgb, xyz, lab, kw)
            ours = j["report"]["loo_mean_de2000"]
            rows[m].append((cs, ours))
            csv_rows.append(f"{name}.jpg,{m},{cs:.4f}")
            line += f"{cs:16.3f} {ours:18.3f} "
        print(line)
    for m, r in rows.items():
        r = np.array(r)
        print(f"{m}: leave-one-out mean ΔE2000 over the photographs, median / largest: "
              f"colour-science {np.median(r[:, 0]):.3f} / {r[:, 0].max():.3f}, lumen {np.median(r[:, 1]):.3f} / {r[:, 1].max():.3f}")
    if csv_path:
        with open(csv_path, "w") as f:
            f.write("# colour-science 0.4.7 colour_correction on the patch values lumen color fit sampled\n")
            f.write("image,model,loo_mean_de2000\n" + "\n".join(csv_rows) + "\n")


def main(folder):
    rgb, xyz = table(f"{folder}/rgb.csv"), table(f"{folder}/xyz.csv")
    white = [l for l in open(f"{folder}/white.csv") if l.strip() and not l.startswith("#")][1]
    white = np.array([float(v) for v in white.split(",")])
    xy = colour.XYZ_to_xy(white)
    lab = lambda v: colour.XYZ_to_Lab(v, illuminant=xy)  # noqa: E731
    methods = {
        "linear-3x3": dict(method="Cheung 2004", terms=3),
        "root-poly-2": dict(method="Finlayson 2015", degree=2),
        "root-poly-3": dict(method="Finlayson 2015", degree=3),
    }
    print(f"{'model':<12} {'cs mean':>9} {'lumen mean':>11} {'max |Δ|':>9} {'cs loo':>8} {'lumen loo':>10}")
    for name, kw in methods.items():
        pred = colour.colour_correction(rgb, rgb, xyz, **kw)
        de = colour.delta_E(lab(pred), lab(xyz), method="CIE 2000")
        loo = []
        for i in range(len(rgb)):
            keep = np.arange(len(rgb)) != i
            p = colour.colour_correction(rgb[i], rgb[keep], xyz[keep], **kw)
            loo.append(colour.delta_E(lab(p), lab(xyz[i]), method="CIE 2000"))
        try:
            ours = json.load(open(f"{folder}/{name}.json"))["report"]
        except FileNotFoundError:
            print(f"{name:<12} {de.mean():9.4f} {'(no ' + name + '.json)':>11}")
            continue
        ours_de = np.array([p["de2000"] for p in ours["patches"]])
        print(
            f"{name:<12} {de.mean():9.4f} {ours['mean_de2000']:11.4f} {np.abs(ours_de - de).max():9.2e} "
            f"{np.mean(loo):8.4f} {ours['loo_mean_de2000']:10.4f}"
        )
    # colour-science's own integration of the same spectra: lumen's XYZ to within the tables.
    shape = colour.SpectralShape(380, 780, 5)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    d65 = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    refl = [l for l in open("data/color/colorchecker24_babelcolor_average.csv") if not l.startswith("#")][1:]
    worst = 0.0
    for i, line in enumerate(refl):
        values = [float(v) for v in line.split(",")[2:]]
        sd = colour.SpectralDistribution(dict(zip(range(380, 785, 5), values)))
        cs = colour.sd_to_XYZ(sd, cmfs, d65, method="Integration") / 100
        worst = max(worst, float(np.abs(cs - xyz[i]).max()))
    print(f"largest |XYZ(colour-science sd_to_XYZ) - XYZ(lumen)| over the 24 patches: {worst:.2e}")

if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--photos":
        photos(sys.argv[2], sys.argv[4] if len(sys.argv) > 4 and sys.argv[3] == "--csv" else None)
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else "out/spectral-d65")
