"""Error against run time, liver: every shortcut's error against its time per frame (liver_error_bench's CSV files),
and the haptic rate against a 10 kHz reference on replayed trajectories (the haptic node's logs in raw/rates/)."""
import csv
import glob
import os

import numpy as np

from report.document import first_key, fmt, number, plt

TITLE = "Error against run time: liver"


def write(rep):
    rows = rep.csv_section(
        "liver_error_time", "Every shortcut: error against time per frame",
        "Reference: the exact direct solve in double of the same contact frames. Errors are relative (displacement "
        "of the visible nodes, total contact force); time per frame is what the method pays each frame.")
    if rows:
        fig, ax = plt.subplots(figsize=(8, 5.5))
        fams = sorted({r["family"] for r in rows})
        markers = "osD^v<>ph*"
        for i, fam in enumerate(fams):
            pts = [r for r in rows if r["family"] == fam and number(r.get("time_per_frame_us_p50"))
                   and number(r.get("disp_rel_error"))]
            if not pts:
                continue
            x = [r["time_per_frame_us_p50"] for r in pts]
            y = [max(r["disp_rel_error"], 1e-17) for r in pts]
            ax.scatter(x, y, marker=markers[i % len(markers)], label=fam, s=36)
            for r, xi, yi in zip(pts, x, y):
                ax.annotate(str(r.get("variant", "")), (xi, yi), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time per frame, us (p50)")
        ax.set_ylabel("relative displacement error (visible nodes)")
        ax.set_title("Liver: error against time per frame")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        rep.save(fig, "liver_error_vs_time", "Liver: each method's error against its time per frame (log-log).")
        tensors = [r for r in rows if r["family"] == "tensors_double"]
        full = [r for r in rows if r["family"] == "full_solve"]
        if tensors and full and number(tensors[0]["time_per_frame_us_p50"]) and number(full[0]["time_per_frame_us_p50"]):
            rep.headline.append((
                "liver: precomputed tensors vs per-frame full solve (time per frame p50)",
                "%s us vs %s us (x%.0f faster), error %s" % (
                    fmt(tensors[0]["time_per_frame_us_p50"]), fmt(full[0]["time_per_frame_us_p50"]),
                    full[0]["time_per_frame_us_p50"] / max(tensors[0]["time_per_frame_us_p50"], 1e-9),
                    fmt(tensors[0]["disp_rel_error"])),
                "the reference is exact linear elasticity", ""))
    # Detailed tables the liver error bench may write.
    for name, title, text in [
        ("liver_mesh_convergence", "Discretization: meshes against the finest",
         "The same indenter load on livers meshed at several sizes, compared with the finest mesh."),
        ("liver_nonlinear", "Linear and quasi non-linear against a neo-Hookean Newton reference",
         "A flat indenter pushed into the top at indentations given as a fraction of the organ size."),
    ]:
        rows = rep.csv_section(name, title, text)
        if rows and name == "liver_nonlinear":
            plot_nonlinear(rep, rows)
        if rows and name == "liver_mesh_convergence":
            plot_mesh(rep, rows)
    for path in sorted(glob.glob(os.path.join(rep.root, "csv", "liver_error_*.csv"))):
        name = os.path.basename(path)[:-4]
        if name != "liver_error_time":
            rep.csv_section(name, name.replace("_", " "), "")
    haptic_rates(rep)


def plot_nonlinear(rep, rows):
    xk = first_key(rows[0], "indentation_percent", "indentation")
    if not xk:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, what in zip(axes, ("force", "disp")):
        for col in [c for c in rows[0] if what in c and "error" in c]:
            pts = [(r[xk], r[col]) for r in rows if number(r[xk]) and number(r[col])]
            if pts:
                ax.plot(*zip(*pts), marker="o", label=col)
        ax.set_xlabel(xk)
        ax.set_ylabel("relative error against neo-Hookean")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    rep.save(fig, "liver_nonlinear", "Liver: linear and quasi non-linear errors against the neo-Hookean reference.")


def plot_mesh(rep, rows):
    xk = first_key(rows[0], "nodes")
    if not xk:
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    for col in [c for c in rows[0] if "error" in c]:
        pts = [(r[xk], r[col]) for r in rows if number(r[xk]) and number(r[col]) and r[col] > 0]
        if pts:
            ax.loglog(*zip(*pts), marker="o", label=col)
    ax.set_xlabel("nodes")
    ax.set_ylabel("relative error against the finest mesh")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    rep.save(fig, "liver_mesh_convergence", "Liver: discretization error against mesh size.")


def read_log(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    return data["t"], np.stack([data["fx"], data["fy"], data["fz"]], axis=1)


def haptic_rates(rep):
    rep.md("### Haptic rate against a 10 kHz reference (force signal)")
    rep.md()
    rep.md("The real haptic node replays each trajectory tick-exact (`--speed max`) at each rate; a device holds each "
           "force until the next tick, so the lower rate's signal is compared, held, with the 10 kHz one at every "
           "10 kHz tick. Errors are relative to the reference signal's RMS; time per tick from the node's stats.")
    rep.md()
    folder = os.path.join(rep.root, "raw", "rates")
    refs = sorted(glob.glob(os.path.join(folder, "*_10000.csv")))
    if not refs:
        rep.missing.append("raw/rates")
        rep.md("**Missing**: no 10 kHz reference log (step haptic_rates failed?).")
        rep.md()
        return
    out_rows = []
    fig, axes = plt.subplots(len(refs), 1, figsize=(9, 3.2 * len(refs)), squeeze=False)
    for ax, ref in zip(axes[:, 0], refs):
        traj = os.path.basename(ref)[: -len("_10000.csv")]
        t_ref, f_ref = read_log(ref)
        ref_rms = float(np.sqrt(np.mean(np.sum(f_ref ** 2, axis=1))))
        ax.plot(t_ref, np.linalg.norm(f_ref, axis=1), lw=0.8, color="k", label="10000 Hz")
        for log in sorted(glob.glob(os.path.join(folder, traj + "_*.csv")), key=lambda p: int(p.rsplit("_", 1)[1][:-4])):
            rate = int(log.rsplit("_", 1)[1][:-4])
            stats = rep.load_json(os.path.relpath(log[:-4] + ".json", rep.root)) or {}
            tick = stats.get("tick_us", {})
            row = {"trajectory": traj, "rate_hz": rate, "ticks": stats.get("ticks", ""),
                   "tick_us_p50": tick.get("p50", ""), "tick_us_p99": tick.get("p99", ""),
                   "cpu_ms_per_sim_s": rate * tick.get("mean", float("nan")) / 1000.0 if tick else ""}
            if rate != 10000:
                t, f = read_log(log)
                idx = np.clip(np.floor(t_ref * rate + 1e-9).astype(int), 0, len(f) - 1)
                diff = np.linalg.norm(f[idx] - f_ref, axis=1)
                row.update({"force_rms_rel_error": float(np.sqrt(np.mean(diff ** 2))) / max(ref_rms, 1e-12),
                            "force_max_error_n": float(diff.max()), "peak_force_n": float(np.linalg.norm(f, axis=1).max())})
                ax.step(t, np.linalg.norm(f, axis=1), where="post", lw=0.8, label="%d Hz" % rate)
            else:
                row.update({"force_rms_rel_error": 0.0, "force_max_error_n": 0.0,
                            "peak_force_n": float(np.linalg.norm(f_ref, axis=1).max())})
            out_rows.append(row)
        ax.set_title(traj)
        ax.set_xlabel("t, s")
        ax.set_ylabel("|force|, N")
        ax.legend(fontsize=7)
        ax.grid(True, alpha=0.3)
    cols = ["trajectory", "rate_hz", "ticks", "tick_us_p50", "tick_us_p99", "cpu_ms_per_sim_s",
            "force_rms_rel_error", "force_max_error_n", "peak_force_n"]
    with open(os.path.join(rep.root, "csv", "liver_haptic_rate.csv"), "w", newline="") as f:
        f.write("# " + rep.stamp() + "\n")
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in out_rows:
            w.writerow(r)
    rep.md("Data: [`csv/liver_haptic_rate.csv`](csv/liver_haptic_rate.csv)")
    rep.md()
    rep.table(out_rows, cols)
    rep.save(fig, "liver_haptic_rate", "Liver: tool force magnitude at each haptic rate against the 10 kHz reference.")
    for r in out_rows:
        if r["rate_hz"] == 1000 and number(r.get("force_rms_rel_error")):
            rep.headline.append(("liver: force error of 1 kHz against 10 kHz (%s)" % r["trajectory"],
                                 "RMS %.2g %%, max %.3g N" % (100 * r["force_rms_rel_error"], r["force_max_error_n"]),
                                 "", ""))
