"""Two hands: two instruments on the shipped liver (two_hands_bench: the tick with both touching, the
grasper's force against a direct solve), the machine's floor just before, and both nodes live at 1 kHz."""
import csv
import glob
import os
import shutil

import numpy as np

from report.budgets import BUDGETS
from report.document import (budget_table, convert, fmt, load_json_safe, missing_line, number, plt, step_note,
                             verdict)

TITLE = "Two hands"


def write(rep):
    """Two instruments on the shipped liver (grasper holding the free lobe, probe pressing beside it): the
    tick with both touching, the coupling against the direct solve, and both nodes live at 1 kHz."""
    rep.md("`two_hands_bench` replays the shipped two-instrument scene `config/liver_two_tools.yaml` tick by tick at "
           "1 kHz along `config/trajectories/liver_two_hands.csv`: the grasper (left port) closes on the free lobe, "
           "pulls back and holds while the probe (right port, 3 cm away) presses 8 mm and comes out. The tick is both "
           "instruments' contacts in one solve, the scene's law and each instrument's force stage, with each "
           "instrument's contact capacity set to 10 (the issue's 2 instruments x 10 contacts), over the ticks where "
           "both touch. The coupling run is linear (no law) at the shipped capacities: the grasper's force from the "
           "two-instrument solve, from the same grasper with no probe, and from a direct solve of the elasticity "
           "with both instruments' constraints (K_ff by sparse LDLT, independent of the tensors), wherever the "
           "grasper holds and the probe presses. Then `rt_bench` gives the machine's floor for as long as the live "
           "run, just before it, and both nodes run live at 1 kHz on the same scene and trajectory.")
    rep.md()
    rows = rep.csv_rows("two_hands")
    figs = {}
    if rows is None:
        missing_line(rep, "`csv/two_hands.csv`", "two_hands")
    else:
        figs = {r.get("metric"): r.get("value") for r in rows}
        trace = os.path.exists(os.path.join(rep.root, "csv", "two_hands_trace.csv"))
        rep.md("Data: [`csv/two_hands.csv`](csv/two_hands.csv)" +
               (", [`csv/two_hands_trace.csv`](csv/two_hands_trace.csv)" if trace else ""))
        rep.md()

    def fig(name):
        v = figs.get(name)
        return v if number(v) else None

    table = []  # (what, measured, budget, verdict)
    p99 = fig("tick_both_touching_p99_us")
    if p99 is not None:
        budget = "p99 <= %g us" % BUDGETS["tick_p99_us"]
        table.append(("tick with both instruments touching, 2 x 10 contacts (bench, %s ticks)" % (
            fmt(fig("ticks_both_touching")) if fig("ticks_both_touching") is not None else "?"),
            "p50 %s / p99 %s / max %s us" % tuple(fmt(fig(k)) if fig(k) is not None else "-" for k in (
                "tick_both_touching_p50_us", "tick_both_touching_p99_us", "tick_both_touching_max_us")),
            budget, verdict(p99 <= BUDGETS["tick_p99_us"])))
        if fig("tick_all_p99_us") is not None:
            table.append(("tick over the whole trajectory (bench)", "p99 %s us" % fmt(fig("tick_all_p99_us")), "", ""))
        if fig("contact_nodes_max_grasper") is not None:
            table.append(("contact nodes, most at once: grasper / probe (bench, capacity 10 each)",
                          "%s / %s, %s ticks over capacity" % (
                              fmt(fig("contact_nodes_max_grasper")), fmt(fig("contact_nodes_max_probe")),
                              fmt(fig("ticks_over_capacity")) if fig("ticks_over_capacity") is not None else "?"),
                          "", ""))
        if fig("tick_both_touching_p99_us_shipped_capacity") is not None:
            # The same tick at the scene's own capacities (what the live node runs): a reference for the live row.
            table.append(("tick with both touching at the scene's own capacities, %s + %s contact nodes (bench)" % (
                fmt(fig("contact_nodes_max_grasper_shipped_capacity")), fmt(fig("contact_nodes_max_probe_shipped_capacity"))),
                "p50 %s / p99 %s / max %s us" % tuple(fmt(fig(k + "_shipped_capacity")) if fig(
                    k + "_shipped_capacity") is not None else "-" for k in (
                        "tick_both_touching_p50_us", "tick_both_touching_p99_us", "tick_both_touching_max_us")),
                "", ""))
    elif rows is not None:
        table.append(("tick with both instruments touching (bench)", "missing: not in `csv/two_hands.csv`", "", ""))

    # The machine's floor just before the live run, then the live run.
    floor = next((r for r in rep.csv_rows("rt_floor") or [] if r.get("condition") == "before_live_two_hands"), None)
    if floor:
        table.append(("machine floor just before: the same timer, a fixed %g us busy tick, nothing else "
                      "(rt_bench, %d ticks)" % (floor["work_us"], floor["ticks"]),
                      "%d missed (%.3f %%), wake-up late p99 %.0f / max %.0f us" % (
                          floor["missed"], floor["missed_pct"], floor["late_us_p99"], floor["late_us_max"]),
                      "< 0.1 % missed", verdict(floor["missed_pct"] < 100 * BUDGETS["missed_fraction"])))
    else:
        table.append(("machine floor just before (rt_bench)", "missing: no `before_live_two_hands` row in "
                      "`csv/rt_floor.csv` (%s)" % step_note(rep, "rt_floor_two_hands"), "", ""))
    h = load_json_safe(rep, "raw/live_two_hands/haptic_stats.json")
    v = load_json_safe(rep, "raw/live_two_hands/visual_stats.json")
    if h and isinstance(h.get("tick_us"), dict):
        t = h["tick_us"]
        ticks = h.get("ticks", 0) or 0
        misses = h.get("deadline_misses", 0) or 0
        missed = misses / max(ticks, 1)
        floor_text = "; floor just before: %d of %d (%.3f %%)" % (
            floor["missed"], floor["ticks"], floor["missed_pct"]) if floor else "; floor just before: missing"
        table.append(("live: both nodes, %s instruments at the shipped capacities (contacts up to %s), haptic loop "
                      "at %g Hz, %d ticks (%s)" % (h.get("instrument_count", "?"), h.get("contacts_max", "?"),
                                                    h.get("rate_hz", 0), ticks, h.get("realtime", "")),
            "tick p50 %.1f / p99 %.1f / max %.0f us" % (t.get("p50", float("nan")), t.get("p99", float("nan")),
                                                     t.get("max", float("nan"))),
            "p99 <= %g us" % BUDGETS["tick_p99_us"], verdict(t.get("p99", 1e9) <= BUDGETS["tick_p99_us"])))
        table.append(("live: missed deadlines, beside rt_bench's just before", "%d of %d (%.3f %%), %.1f Hz "
                      "achieved%s" % (misses, ticks, 100 * missed, h.get("achieved_hz", 0), floor_text),
                      "< 0.1 % missed",
            verdict(missed < BUDGETS["missed_fraction"])))
    else:
        table.append(("live: both nodes at 1 kHz on liver_two_tools", "missing or unreadable: "
                      "`raw/live_two_hands/haptic_stats.json` (%s)" % step_note(rep, "live_two_hands"), "", ""))
        rep.missing.append("raw/live_two_hands/haptic_stats.json")
    if v and isinstance(v.get("latency_us"), dict):
        lat = v["latency_us"]
        table.append(("live: visual node", "%.1f fps, haptic -> visual latency p50 %.0f / p99 %.0f us" % (
            v.get("fps", 0), lat.get("p50", -1), lat.get("p99", -1)), "", ""))

    err = fig("max_rel_error_vs_direct_solve")
    compared = fig("ticks_compared_with_direct_solve")
    if err is not None:
        ok = err <= 1e-9 and (compared or 0) > 0
        table.append(("largest relative error of either instrument's force against the direct solve (%s ticks "
                      "compared)" % (fmt(compared) if compared is not None else "?"),
                      "%.2g" % err, "<= 1e-9", verdict(ok) if (compared or 0) > 0 else "**nothing compared**"))
    elif rows is not None:
        table.append(("largest relative error against the direct solve", "missing: not in `csv/two_hands.csv`", "",
                      ""))
    coupling = fig("grasper_force_change_by_probe_max")
    if coupling is not None:
        at, alone, both = fig("time_of_max_coupling"), fig("grasper_fz_alone_at_max"), fig("grasper_fz_with_probe_at_max")
        detail = ""
        if at is not None and alone is not None and both is not None:
            detail = " (t = %.3f s: F_z %.4g N alone, %.4g N with the probe)" % (at, alone, both)
        # Present means far above the solve's own error: the probe really changes what the grasper feels.
        dz = two_hands_largest_dz(rep)
        if dz is not None:
            detail += "; largest F_z change in the trace %.4g N" % dz
        table.append(("largest change of the grasper's force caused by the probe (relative to the grasper alone)",
                      "%.3g %%%s" % (coupling, detail), "> 0 (the coupling is there)",
                      "present" if coupling > 1e-4 else "**absent**"))
    elif rows is not None:
        table.append(("largest change of the grasper's force caused by the probe",
                      "missing: not in `csv/two_hands.csv`", "", ""))

    if table:
        budget_table(rep, table, "budget / reference", "two hands: ")

    two_hands_plot(rep)
    two_hands_live_tools(rep, h)


def two_hands_largest_dz(rep):
    """The largest |F_z with the probe - F_z alone| of the grasper in two_hands_trace.csv (every 10 ms), or None."""
    path = os.path.join(rep.root, "csv", "two_hands_trace.csv")
    if not os.path.exists(path):
        return None
    dz = [abs(r["grasper_fz_N"] - r["grasper_alone_fz_N"]) for r in rep.csv_rows("two_hands_trace") or []
          if number(r.get("grasper_fz_N")) and number(r.get("grasper_alone_fz_N"))]
    return max(dz) if dz else None


def two_hands_plot(rep):
    trace = rep.csv_rows("two_hands_trace")
    if not trace:
        missing_line(rep, "`csv/two_hands_trace.csv`", "two_hands")
        return

    def col(name):
        return np.array([r.get(name) if number(r.get(name)) else np.nan for r in trace], dtype=float)

    t = col("t_s")
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    ax = axes[0]
    ax.plot(t, col("grasper_fz_N"), lw=1.4, color="C0", label="grasper, two-instrument solve")
    ax.plot(t, col("grasper_alone_fz_N"), lw=1.0, ls="--", color="C1", label="grasper alone (no probe)")
    direct = col("grasper_direct_fz_N")
    ok = np.isfinite(direct)
    if ok.any():
        ax.plot(t[ok], direct[ok], ls="none", marker="o", ms=3, mfc="none", color="k",
                label="direct solve, both constraints")
    ax.set_ylabel("grasper force F_z (N)")
    ax.set_title("The holding instrument while the other presses")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[1]
    ax.plot(t, col("probe_fz_N"), lw=1.4, color="C2", label="probe, two-instrument solve")
    ax.plot(t, col("probe_alone_fz_N"), lw=1.0, ls="--", color="C3", label="probe alone (no grasper)")
    ax.set_ylabel("probe force F_z (N)")
    ax.set_xlabel("t (s)")
    ax.grid(True, alpha=0.3)
    ax2 = ax.twinx()
    for name, color in (("grasper_contacts", "C0"), ("probe_contacts", "C2")):
        c = col(name)
        if np.isfinite(c).any():
            ax2.step(t, c, where="post", lw=0.6, alpha=0.5, color=color, label=name.replace("_", " "))
    ax2.set_ylabel("contact nodes", fontsize=8)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7)
    rep.save(fig, "two_hands_forces", "Two hands on the shipped liver: the grasper's force (z) from the two-instrument "
             "solve, from the grasper alone, and from the direct solve with both instruments' constraints (where the "
             "grasper holds and the probe presses), and the probe's force, against time (linear, 1 kHz, every 10 ms).")


def two_hands_live_tools(rep, h):
    rep.md("### The live run, per instrument")
    rep.md()
    if not h:
        missing_line(rep, "`raw/live_two_hands/haptic_stats.json`", "live_two_hands")
        return
    tools = h.get("tools")
    if not isinstance(tools, list) or not tools:
        rep.md("**Missing**: `raw/live_two_hands/haptic_stats.json` has no `tools` list (a haptic node from before "
               "several instruments?).")
        rep.md()
        return
    rep.md("From [`raw/live_two_hands/haptic_stats.json`](raw/live_two_hands/haptic_stats.json) (%s instruments; "
           "totals: contacts max %s, force max %s N, %s input-lost ticks, %s saturated ticks)." % (
               h.get("instrument_count", len(tools)), fmt(h.get("contacts_max", "-")), fmt(h.get("force_max_n", "-")),
               fmt(h.get("input_lost_ticks", "-")), fmt(h.get("saturated_ticks", "-"))))
    rep.md()
    preferred = ["name", "contacts_max", "force_max_n", "contact_ticks", "saturated_ticks", "input_lost_ticks",
                 "over_capacity_events", "nonfinite_rejected", "commands_received"]
    scalar = [k for k in tools[0] if not isinstance(tools[0][k], (dict, list))]
    columns = [k for k in preferred if k in scalar] + [k for k in scalar if k not in preferred]
    rep.table([{k: (e.get(k, "") if not isinstance(e.get(k), (dict, list)) else "") for k in columns} for e in tools],
              columns)
    frame = two_hands_frame(rep)
    if frame:
        shutil.copyfile(frame, os.path.join(rep.root, "plots", "two_hands_live_frame.png"))
        rep.md("![two instruments, live](plots/two_hands_live_frame.png)")
        rep.md()
        rep.md("*The live run as the visual node drew it: `%s`, the saved frame with the most contacts shown (grey: "
               "the grasper, blue: the probe; yellow: contact nodes).*" % os.path.relpath(frame, rep.root))
        rep.md()


def two_hands_frame(rep):
    """The live run's PNG with the most contacts (frames.csv), else its middle one; None when there is none."""
    folder = os.path.join(rep.root, "raw", "live_two_hands", "frames")
    pngs = sorted(glob.glob(os.path.join(folder, "*.png")))
    if not pngs:
        return None
    best = pngs[len(pngs) // 2]
    index = os.path.join(folder, "frames.csv")
    if os.path.exists(index):
        try:
            with open(index) as f:
                rows = [r for r in csv.DictReader(f) if r.get("png")]
            rows = [r for r in rows if os.path.exists(os.path.join(folder, r["png"]))]
            if rows:
                best = os.path.join(folder, max(rows, key=lambda r: convert(r.get("contacts")) if number(
                    convert(r.get("contacts"))) else -1)["png"])
        except (ValueError, KeyError, OSError):
            pass
    return best
