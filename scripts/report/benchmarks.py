"""Benchmarks against the budgets of docs/DESIGN.md, section 'Budgets': precompute, haptic tick, the machine's floor,
the live liver and intestine, deformation and render (liver_bench, node_bench, rt_bench, intestine_error_bench, the
live runs' stats), then the round trips (network_figures.sh) and intestine_bench's printed tables."""
import os

from report.budgets import BUDGETS
from report.document import budget_table, embed_log_table, first_key, number, verdict

TITLE = "Benchmarks against the budgets of docs/DESIGN.md, section 'Budgets'"


def write(rep):
    rows = []
    pre = rep.csv_rows("liver_precompute") or []
    near = sorted(pre, key=lambda r: abs(r["nodes"] - 1400))[:1]
    for r in near:
        rows.append(("precompute, %d-node liver (direct, double)" % r["nodes"], "%.2f s" % r["direct_s"],
                     "<= 2 s", verdict(r["direct_s"] <= BUDGETS["precompute_1k4_s"])))
    for r in pre:
        if r not in near:
            rows.append(("precompute, %d-node liver" % r["nodes"], "%.2f s, peak %.0f MiB" % (r["direct_s"], r["direct_peak_mib"]),
                         "", ""))
    ticks = rep.csv_rows("node_tick") or []
    small = min((r["nodes"] for r in ticks), default=None)
    for r in ticks:
        if r["contacts"] == 10:
            budget = "p99 <= 100 us" if r["nodes"] == small else ""
            rows.append(("haptic tick, %d nodes, 10 contacts (bench)" % r["nodes"],
                         "p50 %.1f / p99 %.1f us" % (r["tick_us_p50"], r["tick_us_p99"]), budget,
                         verdict(r["tick_us_p99"] <= BUDGETS["tick_p99_us"]) if budget else ""))
    # rt_bench appends a row per run to rt_floor.csv: this is the run alone, before the live liver.
    floors = rep.csv_rows("rt_floor") or []
    floor = next((r for r in floors if r.get("condition") == "alone"), floors[0] if floors else None)
    if floor:
        rows.append(("machine floor: the same timer, a fixed %g us busy tick, nothing else (rt_bench, %d ticks)" % (
            floor["work_us"], floor["ticks"]),
            "%d missed (%.3f %%), wake-up late p99 %.0f / max %.0f us" % (
                floor["missed"], floor["missed_pct"], floor["late_us_p99"], floor["late_us_max"]),
            "< 0.1 % missed", verdict(floor["missed_pct"] < 100 * BUDGETS["missed_fraction"])))
    h = rep.load_json("raw/live_liver/haptic_stats.json")
    v = rep.load_json("raw/live_liver/visual_stats.json")
    if h:
        missed = h.get("deadline_misses", 0) / max(h.get("ticks", 1), 1)
        rows.append(("live liver: haptic loop at %g Hz, %d ticks (%s)" % (h.get("rate_hz", 0), h.get("ticks", 0),
                                                                        h.get("realtime", "")),
                     "%.1f Hz, %d missed (%.3f %%), tick p50 %.1f / p99 %.1f us" % (
                         h.get("achieved_hz", 0), h.get("deadline_misses", 0), 100 * missed, h["tick_us"]["p50"],
                         h["tick_us"]["p99"]),
                     "< 0.1 % missed", verdict(missed < BUDGETS["missed_fraction"])))
        rt = h.get("round_trip_us", {})
        if rt.get("count"):
            rows.append(("live liver: haptic -> visual -> haptic round trip", "p50 %.0f / p99 %.0f us" % (rt["p50"], rt["p99"]),
                         "", ""))
    else:
        rep.missing.append("raw/live_liver/haptic_stats.json")
    if v:
        lat = v.get("latency_us", {})
        rows.append(("live liver: haptic -> visual latency, one host", "p50 %.0f / p99 %.0f us" % (lat.get("p50", -1), lat.get("p99", -1)),
                     "p50 <= 150 us, p99 <= 1 ms",
                     verdict(lat.get("p50", 1e9) <= BUDGETS["latency_p50_us"] and lat.get("p99", 1e9) <= BUDGETS["latency_p99_us"])))
        rows.append(("live liver: visual frames at %sx%s" % ("640", "480"), "%.1f fps, render p50 %.1f ms" % (
            v.get("fps", 0), v.get("render_ms", {}).get("p50", -1)), ">= 50 Hz (scene rate 50 Hz)",
            verdict(v.get("fps", 0) >= 0.97 * BUDGETS["fps"])))
        d = v.get("deform_us", {})
        rows.append(("live liver: deformation of %d visible nodes" % v.get("visible_nodes", 0),
                     "p50 %.0f / p99 %.0f us" % (d.get("p50", -1), d.get("p99", -1)), "<= 1 ms",
                     verdict(d.get("p99", 1e9) <= 1000 * BUDGETS["deform_ms"])))
    for r in rep.csv_rows("node_deform") or []:
        rows.append(("deformation, %d visible nodes, 10 contacts (bench)" % r["visible_nodes"],
                     "p50 %.0f / p99 %.0f us" % (r["deform_us_p50"], r["deform_us_p99"]), "<= 1 ms",
                     verdict(r["deform_us_p99"] <= 1000 * BUDGETS["deform_ms"])))
    for r in rep.csv_rows("node_render") or []:
        rows.append(("render %dx%d, %d visible nodes + tool (bench)" % (r["width"], r["height"], r["visible_nodes"]),
                     "p50 %.2f / p99 %.2f ms (%.0f fps capable)" % (r["frame_ms_p50"], r["frame_ms_p99"], 1000 / r["frame_ms_p50"]),
                     ">= 50 Hz" if r["width"] == 640 else "", verdict(1000 / r["frame_ms_p50"] >= BUDGETS["fps"]) if r["width"] == 640 else ""))
    ts = rep.csv_rows("intestine_timestep") or []
    for r in ts:
        dk = first_key(r, "dt_ms")
        pk = first_key(r, "step_us_p99")
        if dk and pk and r[dk] == 1 and r.get("self_collisions", 1) == 1 and number(r[pk]):
            rows.append(("intestine step (400 masses + collisions), dt 1 ms", "p99 %.0f us of thread CPU (%.0f Hz capable)" % (r[pk], 1e6 / r[pk]),
                         ">= 1 kHz capable", verdict(1e6 / r[pk] >= BUDGETS["intestine_step_hz"])))
    hi = rep.load_json("raw/live_intestine/haptic_stats.json")
    vi = rep.load_json("raw/live_intestine/visual_stats.json")
    if hi:
        rows.append(("live intestine: haptic loop at %g Hz" % hi.get("rate_hz", 0),
                     "%.1f Hz, %d missed, tick p50 %.0f / p99 %.0f us" % (hi.get("achieved_hz", 0), hi.get("deadline_misses", 0),
                                                                       hi["tick_us"]["p50"], hi["tick_us"]["p99"]), "", ""))
    if vi:
        rows.append(("live intestine: visual", "%.1f fps, latency p50 %.0f us" % (vi.get("fps", 0), vi.get("latency_us", {}).get("p50", -1)),
                     "", ""))
    budget_table(rep, rows)
    rep.csv_section("liver_precompute", "Precompute: time and memory (direct CHOLMOD against CG per column)", "")
    rep.csv_section("liver_table1", "The paper's Table 1: tensor evaluation against the reference solve", "")
    rep.csv_section("node_tick", "Haptic tick against contacts and mesh size", "")
    embed_log_table(rep, "network", "Round trips: one host and two hosts (scripts/network_figures.sh)")
    for name in ("intestine_bench",):
        path = os.path.join(rep.root, "logs", name + ".log")
        if os.path.exists(path):
            rep.md("### intestine_bench (its printed tables)")
            rep.md()
            rep.md("```")
            with open(path) as f:
                rep.md(f.read().rstrip())
            rep.md("```")
            rep.md()
