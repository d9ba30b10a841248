"""Several organs: the shipped abdomen (liver, bowel, abdominal wall, floor, ribs; two instruments): the tick with
both instruments in contact, the wall during the trajectory, a device pushed into the floor (abdomen_bench), the
machine's floor just before, and both nodes live at 1 kHz."""
from report.budgets import BUDGETS
from report.document import budget_table, fmt, load_json_safe, missing_line, number, step_note, verdict

TITLE = "Several organs"


def write(rep):
    rep.md("`abdomen_bench` replays `config/abdomen.yaml` along `config/trajectories/abdomen.csv` at 1 kHz: the probe "
           "presses the liver 8 mm while the grasper pushes into the bowel's folds, then the probe slides 10 cm along "
           "the side wall 0.5 mm deep. The tick is every organ stepped with both instruments and each instrument's "
           "force stage (thread CPU time, over the ticks where both touch an organ). Then the probe is turned "
           "towards the floor (the posterior wall) and pushed along its shaft by a simulated device (the issue's "
           "mass, damping and hand ranges; the force held over each tick, without and with a tick of delay). Then "
           "`rt_bench` gives the machine's floor for as long as the live run, just before it, and both nodes run live "
           "at 1 kHz on the same scene and trajectory.")
    rep.md()
    rows = rep.csv_rows("abdomen")
    figs = {}
    if rows is None:
        missing_line(rep, "`csv/abdomen.csv`", "abdomen")
    else:
        figs = {r.get("metric"): r.get("value") for r in rows}
        rep.md("Data: [`csv/abdomen.csv`](csv/abdomen.csv), [`csv/abdomen_wall_push.csv`](csv/abdomen_wall_push.csv)")
        rep.md()

    def fig(name):
        v = figs.get(name)
        return v if number(v) else None

    table = []  # (what, measured, budget, verdict)
    p99 = fig("tick_both_in_contact_p99_us")
    if p99 is not None:
        table.append(("tick, both instruments in contact (bench, %s ticks)" % fmt(fig("ticks_both_in_contact")),
                      "p50 %s / p99 %s us" % (fmt(fig("tick_both_in_contact_p50_us")), fmt(p99)),
                      "p99 <= %g us" % BUDGETS["abdomen_tick_p99_us"],
                      verdict(p99 <= BUDGETS["abdomen_tick_p99_us"] and (fig("ticks_both_in_contact") or 0) > 0)))
    pen = fig("wall_penetration_max_mm")
    if pen is not None:
        table.append(("deepest penetration into the wall during the trajectory (bench)", "%.3f mm" % pen,
                      "<= %g mm" % BUDGETS["wall_penetration_mm"], verdict(pen <= BUDGETS["wall_penetration_mm"])))
    runs = fig("wall_push_runs")
    if runs is not None:
        passive, settled, worst = fig("wall_push_passive_runs"), fig("wall_push_settled_runs"), fig(
            "wall_push_energy_worst_j")
        table.append(("device pushed along the shaft into the floor (bench: m 0.05-0.2 kg, b 0.1-1 N s/m, "
                      "0.5-3 N, without and with a tick of delay)",
                      "%s of %s runs passive (environment's energy worst %s J), %s of %s at rest" % (
                          fmt(passive), fmt(runs), fmt(worst), fmt(settled), fmt(runs)),
                      "all settle, energy <= 0", verdict(passive == runs and settled == runs)))

    floor = next((r for r in rep.csv_rows("rt_floor") or [] if r.get("condition") == "before_live_abdomen"), None)
    if floor:
        table.append(("machine floor just before (rt_bench, %g us busy tick, %d ticks)" % (floor["work_us"],
                                                                                       floor["ticks"]),
                      "%d missed (%.3f %%)" % (floor["missed"], floor["missed_pct"]), "", ""))
    else:
        table.append(("machine floor just before (rt_bench)", "missing: no `before_live_abdomen` row in "
                      "`csv/rt_floor.csv` (%s)" % step_note(rep, "rt_floor_abdomen"), "", ""))
    h = load_json_safe(rep, "raw/live_abdomen/haptic_stats.json")
    v = load_json_safe(rep, "raw/live_abdomen/visual_stats.json")
    if h and isinstance(h.get("tick_us"), dict):
        ticks = h.get("ticks", 0) or 0
        missed_pct = 100.0 * (h.get("deadline_misses", 0) or 0) / max(ticks, 1)
        if floor:
            over = missed_pct - floor["missed_pct"]
            table.append(("live: missed deadlines at 1 kHz beside the visual node, %d ticks" % ticks,
                          "%.3f %% (floor %.3f %%: %+.3f points)" % (missed_pct, floor["missed_pct"], over),
                          "within %g points of the floor" % BUDGETS["abdomen_missed_points"],
                          verdict(over <= BUDGETS["abdomen_missed_points"])))
        else:
            table.append(("live: missed deadlines at 1 kHz", "%.3f %% (no floor to compare)" % missed_pct, "", ""))
        t = h["tick_us"]
        table.append(("live: haptic tick", "p50 %.1f / p99 %.1f us" % (t.get("p50", float("nan")),
                                                                       t.get("p99", float("nan"))), "", ""))
        deepest = max((i.get("max_penetration_mm", 0) for o in h.get("organs", []) if o.get("model") == "rigid"
                       for i in o.get("rigid", {}).get("instruments", [])), default=None)
        if deepest is not None:
            table.append(("live: deepest penetration into a rigid organ", "%.3f mm" % deepest,
                          "<= %g mm" % BUDGETS["wall_penetration_mm"],
                          verdict(deepest <= BUDGETS["wall_penetration_mm"])))
    else:
        table.append(("live: both nodes at 1 kHz on abdomen", "missing or unreadable: "
                      "`raw/live_abdomen/haptic_stats.json` (%s)" % step_note(rep, "live_abdomen"), "", ""))
        rep.missing.append("raw/live_abdomen/haptic_stats.json")
    if v and number(v.get("fps")) and number(v.get("fps_configured")) and v["fps_configured"] > 0:
        organs = ", ".join(o.get("name", "?") for o in v.get("organs", []))
        share = v["fps"] / v["fps_configured"]
        table.append(("live: visual node, every organ drawn (%s)" % organs,
                      "%.2f fps of %g (%.1f %%)" % (v["fps"], v["fps_configured"], 100 * share),
                      ">= %g %% of its rate" % (100 * BUDGETS["visual_rate_fraction"]),
                      verdict(share >= BUDGETS["visual_rate_fraction"])))
    elif v is None:
        table.append(("live: visual node", "missing: `raw/live_abdomen/visual_stats.json` (%s)" % step_note(
            rep, "live_abdomen"), "", ""))
    # The field with a browser showing the page for the whole run (scripts/field_live.py), in pairs after rt_bench.
    pairs = rep.csv_rows("field_live")
    if pairs:
        worst_miss = max(pairs, key=lambda r: r["miss_diff_points"])
        worst_vis = min(pairs, key=lambda r: r["visual_share"])
        within_m = sum(1 for r in pairs if r["miss_diff_points"] <= BUDGETS["abdomen_missed_points"])
        within_v = sum(1 for r in pairs if r["visual_share"] >= BUDGETS["visual_rate_fraction"])
        table.append(("live with a browser open (field_live, %d pairs of %d ticks): missed deadlines, worst pair"
                      % (len(pairs), worst_miss["ticks"]),
                      "%.3f %% against rt_bench's %.3f %% just before (%+.3f points); %d of %d pairs within" % (
                          worst_miss["miss_pct"], worst_miss["rt_bench_pct"], worst_miss["miss_diff_points"],
                          within_m, len(pairs)),
                      "within %g points of the floor" % BUDGETS["abdomen_missed_points"],
                      verdict(within_m == len(pairs))))
        table.append(("live with a browser open: visual node while the field ran, worst pair",
                      "%.2f fps (%.1f %%); %d of %d pairs within" % (worst_vis["visual_fps_run"],
                                                                   100 * worst_vis["visual_share"], within_v,
                                                                   len(pairs)),
                      ">= %g %% of its rate" % (100 * BUDGETS["visual_rate_fraction"]),
                      verdict(within_v == len(pairs))))
    else:
        table.append(("live with a browser open (field_live)", "missing: `csv/field_live.csv` (%s)" % step_note(
            rep, "field_live"), "", ""))
    budget_table(rep, table, "budget", "several organs: ")
