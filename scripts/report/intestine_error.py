"""Error against run time, intestine: time step, random pairs and level of detail (intestine_error_bench's CSV files),
and the tube skinned in the vertex shader against the CPU (tube_skinning_bench's printed table)."""
import glob
import os

from report.document import embed_log_table, first_key, number, plt, twin_plot

TITLE = "Error against run time: intestine"


def write(rep):
    ts = rep.csv_section("intestine_timestep", "Time step against a fine-step reference",
                         "The scripted probe run integrated at several steps, compared with the finest step.")
    if ts and "dt_ms" in ts[0]:
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        modes = sorted({r.get("self_collisions", 0) for r in ts})
        for mode in modes:
            rows = [r for r in ts if r.get("self_collisions", 0) == mode]
            label = "self-collisions " + ("on" if mode else "off")
            for col, style in (("pos_rms_error_mm", "-o"), ("settle_rms_error_mm", "--s")):
                pts = [r for r in rows if col in r and number(r[col]) and r[col] > 0]
                if pts:
                    ax[0].loglog([r["dt_ms"] for r in pts], [r[col] for r in pts], style, label="%s, %s" % (label, col))
                    if "cpu_s_per_sim_s" in pts[0]:
                        ax[1].loglog([r["cpu_s_per_sim_s"] for r in pts], [r[col] for r in pts], style,
                                     label="%s, %s" % (label, col))
        ax[0].set_xlabel("time step, ms")
        ax[1].set_xlabel("CPU seconds per simulated second")
        for a in ax:
            a.set_ylabel("RMS position error against the finest step, mm")
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=6)
        rep.save(fig, "intestine_timestep", "Intestine: error against time step and against cost (whole run, and "
                 "the settling phase before the probe acts).")
    pairs = rep.csv_section("intestine_pairs", "Random pairs n: recall and time per step",
                            "Recall against the brute-force detector over the scripted run (the paper's fig. 14).")
    if pairs:
        twin_plot(rep, pairs, first_key(pairs[0], "random_pairs", "n"), first_key(pairs[0], "pair_recall", "recall"),
                  first_key(pairs[0], "step_us_p50", "us_p50"), "intestine_pairs",
                  "Intestine: detection recall and time per step against n.", xlabel="random pairs per step n",
                  xscale="symlog")
    lod = rep.csv_section("intestine_lod", "Level of detail: geometric error and frame time", "")
    if lod:
        twin_plot(rep, lod, first_key(lod[0], "lod"), first_key(lod[0], "max_error_mm", "error"),
                  first_key(lod[0], "frame_ms_p50", "frame_ms"), "intestine_lod",
                  "Intestine: tube geometric error and frame time per level of detail.", xlabel="LOD", yscale="log")
    rep.csv_section("intestine_frame_rate", "Guaranteed frame rate (paper eq. 15) on the real renderer", "")
    embed_log_table(rep, "tube_skinning", "Tube skinning in the vertex shader against the CPU, per level of detail "
                    "(tube_skinning_bench)")
    for path in sorted(glob.glob(os.path.join(rep.root, "csv", "intestine_*.csv"))):
        name = os.path.basename(path)[:-4]
        if name not in ("intestine_timestep", "intestine_pairs", "intestine_lod", "intestine_frame_rate"):
            rep.csv_section(name, name.replace("_", " "), "")
