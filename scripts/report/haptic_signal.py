"""What the hand feels: the contact signal, triangle against patch (haptic_signal_bench), the live loop
with and without the publisher thread, and the loop closed through a simulated device (device_grid.sh)."""
import os

from report.budgets import BUDGETS
from report.document import plt, verdict

TITLE = "What the hand feels (haptic signal)"


def write(rep):
    """The contact signal (triangle against patch), the live loop with and without the publisher thread,
    and the loop closed through a simulated device."""
    rep.md("`haptic_signal_bench` drives the liver's contact model directly at 1 kHz, with the paper's triangle "
           "distribution and with the patch contact in one run. The slab is 20 x 20 x 4 cm (1 cm cells) with a "
           "fixed bottom; the liver is the shipped scene. Ripple is the peak-to-peak of the normal force at constant "
           "depth, with the linear trend removed, as a % of its mean. Energy returned is the sum of F . dx on the tool "
           "over a straight press to 60 mm and back; a positive value means the tissue gave energy to the hand, "
           "before the force stage.")
    rep.md()
    rows = rep.csv_rows("haptic_signal")
    if rows is None:
        rep.md("**Missing**: `csv/haptic_signal.csv` (see the haptic_signal step log).")
        rep.md()
    else:
        by = {}
        for r in rows:
            by.setdefault((r["case"], r["metric"]), {})[r["model"]] = r
        rep.md("Data: [`csv/haptic_signal.csv`](csv/haptic_signal.csv)")
        rep.md()
        rep.md("| case | metric | triangle (paper) | patch | patch + force stage (sent to the device) | budget | "
               "verdict (patch) |")
        rep.md("|---|---|---|---|---|---|---|")
        budgets = {"ripple": ("ripple_pct", "<= %g %%"), "tangential_max": ("tangential_pct", "<= %g %%"),
                   "step_max": ("step_pct", "<= %g %%")}
        for (case, metric), models in by.items():
            tri, pat, staged = models.get("triangle"), models.get("patch"), models.get("patch+stage")
            unit = (pat or tri or staged)["unit"]
            cell = lambda r: "%.4g %s" % (r["value"], unit) if r else "-"
            budget, ok = "", ""
            if metric in budgets and pat and "stab" not in case:
                key, text = budgets[metric]
                budget = text % BUDGETS[key]
                ok = verdict(pat["value"] <= BUDGETS[key])
                rep.headline.append(("hand: %s, %s (patch; paper's triangle %s)" % (case, metric, cell(tri)),
                                     cell(pat), budget, ok))
            rep.md("| %s | %s | %s | %s | %s | %s | %s |" % (case, metric, cell(tri), cell(pat), cell(staged), budget, ok))
        rep.md()
    slide = rep.csv_rows("haptic_signal_slide")
    if slide:
        cases = []
        for r in slide:
            if r["case"] not in cases:
                cases.append(r["case"])
        shown = [c for c in cases if "31.7" in c and "3 mm" in c] + [c for c in cases if c == "liver_press_slide"]
        if shown:
            fig, axes = plt.subplots(len(shown), 1, figsize=(9, 3.2 * len(shown)), squeeze=False)
            for ax, case in zip(axes[:, 0], shown):
                for model, style in (("triangle", "-"), ("patch", "-")):
                    pts = [r for r in slide if r["case"] == case and r["model"] == model]
                    ax.plot([r["s_mm"] for r in pts], [r["fn_N"] for r in pts], style, lw=1, label=model + " normal")
                    ax.plot([r["s_mm"] for r in pts], [r["ft_N"] for r in pts], ":", lw=1, label=model + " tangential")
                ax.set_title(case)
                ax.set_xlabel("position along the slide (mm)" if case != "liver_press_slide" else "time (ms)")
                ax.set_ylabel("force on the tool (N)")
                ax.legend(fontsize=7)
            rep.save(fig, "haptic_signal_slide", "Force while sliding: the paper's triangle contact (before) against "
                     "the patch contact (after), on the slab at 3 mm and along liver_press_slide.")
    # Live: the publisher thread against the DDS writes on the loop thread, and the benchmark's tick for the same work.
    h = rep.load_json("raw/live_liver/haptic_stats.json")
    hi = rep.load_json("raw/live_liver_inline/haptic_stats.json")
    bench = [r for r in (rep.csv_rows("node_tick") or []) if r.get("contacts") == 10]
    bench_p99 = min((r["tick_us_p99"] for r in bench), default=None)
    rep.md("### The live loop: publisher thread against writes on the loop thread")
    rep.md()
    rep.md("The same 1 kHz liver run, one after the other: first with the publisher thread (the default), then with "
           "`SURGSIM_HAPTIC_PUBLISHER=inline` (the DDS writes on the loop thread, as before the publisher thread).")
    rep.md()
    rep.md("| run | ticks | missed | tick p50 / p99 / max us | budget | verdict |")
    rep.md("|---|---|---|---|---|---|")
    for label, st in (("publisher thread", h), ("writes on the loop thread", hi)):
        if not st:
            rep.md("| %s | missing | | | | |" % label)
            continue
        t = st["tick_us"]
        budget = "p99 <= %g us" % BUDGETS["tick_p99_us"]
        if bench_p99 is not None:
            budget += ", <= bench p99 %.0f + %g us" % (bench_p99, BUDGETS["tick_vs_bench_us"])
        ok = t["p99"] <= BUDGETS["tick_p99_us"] and (bench_p99 is None or t["p99"] <= bench_p99 + BUDGETS["tick_vs_bench_us"])
        row = ("live liver 1 kHz tick, %s" % label, "p50 %.1f / p99 %.1f / max %.0f us (%d missed of %d)" % (
            t["p50"], t["p99"], t["max"], st.get("deadline_misses", 0), st.get("ticks", 0)), budget, verdict(ok))
        rep.md("| %s | %d | %d | %.1f / %.1f / %.0f | %s | %s |" % (label, st.get("ticks", 0), st.get("deadline_misses", 0),
                                                                     t["p50"], t["p99"], t["max"], budget, verdict(ok)))
        rep.headline.append(row)
    rep.md()
    # The loop closed through the simulated device.
    ddir = os.path.join(rep.root, "raw", "device")
    runs = sorted(f for f in os.listdir(ddir) if f.endswith("_device.json")) if os.path.isdir(ddir) else []
    rep.md("### The loop closed through a simulated device (surgsim-device-sim --physical)")
    rep.md()
    if not runs:
        rep.md("**Missing**: no `raw/device/*_device.json` (see the device_loop step log).")
        rep.md()
        rep.missing.append("raw/device")
        return
    rep.md("| mass kg | damping N s/m | hand N | settled | settling s | overshoot mm | p2p last window mm | "
           "velocity reversals | resting force N | budget | verdict |")
    rep.md("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in runs:
        d = rep.load_json(os.path.join("raw", "device", name))
        hand = d.get("hand_force_n", 0)
        f = d.get("force_final_n", 0)
        ok = d.get("settled", False) and hand > 0 and abs(f - hand) <= BUDGETS["device_force_pct"] / 100 * hand
        budget = "settles, force within %g %%" % BUDGETS["device_force_pct"]
        rep.md("| %g | %g | %g | %s | %.3f | %.2f | %.3f | %d | %.3f | %s | %s |" % (
            d.get("mass_kg", 0), d.get("damping_ns_per_m", 0), hand, d.get("settled"), d.get("settling_time_s", -1),
            1e3 * d.get("overshoot_m", 0), 1e3 * d.get("position_p2p_window_m", 0),
            d.get("velocity_sign_changes_window", -1), f, budget, verdict(ok)))
        rep.headline.append(("closed loop: %g kg, %g N s/m, hand %g N" % (d.get("mass_kg", 0), d.get("damping_ns_per_m", 0), hand),
                             "resting %.3f N, settled %s in %.2f s" % (f, d.get("settled"), d.get("settling_time_s", -1)),
                             budget, verdict(ok)))
    rep.md()
