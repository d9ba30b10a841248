#!/usr/bin/python3
"""The liver at large deformation (issue 16): plots of liver_large_deformation.csv (large_deformation_bench).

plot(csv_dir, out_dir) reads CSV_DIR/liver_large_deformation.csv and writes OUT_DIR/liver_large_deformation.png:
force and displacement error against indentation depth (indent_5..indent_30) and against the angle (lift_45,
lift_90; rigid_90 drawn apart: its force error is relative to the Newton force of a 10 % indentation), one line per
method, the issue's targets drawn dashed. Returns the PNG path, or None when the CSV is missing.

Command line: /usr/bin/python3 scripts/report_large_deformation.py CSV_DIR OUT_DIR
"""
import csv
import math
import os
import sys

METHODS = ["linear", "quasi_cylinder", "quasi_organ", "corotational", "corotational_organ"]


def _num(text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        return math.nan
    return v


def read(csv_dir):
    path = os.path.join(csv_dir, "liver_large_deformation.csv")
    if not os.path.exists(path):
        return None
    rows = {}
    with open(path, newline="") as f:
        # scripts/report.py stamps its CSV files with a '#' line (machine, commit, command): skip comments.
        for r in csv.DictReader(line for line in f if not line.startswith("#")):
            rows[(r["case"], r["method"])] = {
                "force": _num(r["force_rel_error"]),
                "disp": _num(r["disp_rel_error"]),
                "tick": _num(r["tick_us_p99"]),
            }
    return rows


def plot(csv_dir, out_dir):
    rows = read(csv_dir)
    if rows is None:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    depths = [5, 10, 15, 20, 25, 30]
    angles = [45, 90]
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    for method in METHODS:
        for row, key in enumerate(["force", "disp"]):
            ys = [rows.get(("indent_%d" % d, method), {}).get(key, math.nan) for d in depths]
            axes[row][0].plot(depths, [100 * y for y in ys], marker="o", label=method)
            ya = [rows.get(("lift_%d" % a, method), {}).get(key, math.nan) for a in angles]
            line = axes[row][1].plot(angles, [100 * y for y in ya], marker="o", label=method)
            r = rows.get(("rigid_90", method), {}).get(key, math.nan)
            if not math.isnan(r):
                axes[row][1].scatter([92], [100 * max(r, 1e-6)], marker="x", color=line[0].get_color())
    axes[0][0].axhline(5, linestyle="--", color="grey", label="target 5 %")
    axes[0][1].plot([45, 90], [5, 10], linestyle="--", color="grey", label="target 5 / 10 %")
    axes[0][1].axhline(1, linestyle=":", color="grey", label="rigid target 1 % (x at 92)")
    for ax in axes.flat:
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_title("indentation (punch at (0.03, 0))")
    axes[0][1].set_title("grasp-and-lift of the free lobe; x: rigid 90 deg")
    axes[0][0].set_ylabel("force error against Newton, %")
    axes[1][0].set_ylabel("visible-surface displacement error, %")
    axes[1][0].set_xlabel("indentation, % of the organ's height")
    axes[1][1].set_xlabel("angle turned by the grasped region, degrees")
    axes[0][0].legend(fontsize=8)
    axes[0][1].legend(fontsize=8)
    fig.suptitle("Liver at large deformation: error against the neo-Hookean Newton reference")
    fig.tight_layout()
    out = os.path.join(out_dir, "liver_large_deformation.png")
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0 if len(sys.argv) == 2 else 2)
    p = plot(sys.argv[1], sys.argv[2])
    if p is None:
        print("report_large_deformation: no liver_large_deformation.csv in " + sys.argv[1], file=sys.stderr)
        sys.exit(1)
    print(p)
