"""The instrument's contact (tip size): the same 5 mm tip on the shipped liver meshed at three sizes, the footprint
contact against the earlier node patch (tool_size_bench: csv/tool_size.csv, tool_size_slide.csv, tool_size_press.csv),
the flat punch on a bonded slab against Hayes 1972, and the contact tick with 10 patch contacts (tool_size_bench)."""
import os

from report.budgets import BUDGETS
from report.document import fmt, missing_line, number, plt, step_note, verdict

TITLE = "The instrument's contact (tip size)"

FOOTPRINT = "footprint 5 mm"
NODES = "nodes 5 mm"
# The order of the models in the tables and panels: the footprint (the new contact) first.
MODELS = (FOOTPRINT, NODES, "nodes 2.5 edges")


def liver_meshes(rows):
    """The liver meshes in the rows ('liver 1500', ...), coarsest first (by target node count)."""
    names = {r["mesh"] for r in rows if str(r.get("mesh", "")).startswith("liver ")}

    def target(name):
        try:
            return int(name.split()[1])
        except (IndexError, ValueError):
            return 0
    return sorted(names, key=target)


def in_order(rows, key, first):
    """The distinct values of rows[key], those of `first` first (in that order), then the others as they come."""
    seen = [v for v in first if any(r.get(key) == v for r in rows)]
    for r in rows:
        if r.get(key) not in seen:
            seen.append(r.get(key))
    return seen


def pct(v):
    return "%+.2f %%" % v if number(v) else str(v)


def worst(values, signed=True):
    """The (value, where) of largest magnitude among [(value, where)] with a finite value; None when there is none."""
    finite = [(v, w) for v, w in values if number(v)]
    if not finite:
        return None
    return max(finite, key=lambda vw: abs(vw[0]) if signed else vw[0])


def write(rep):
    rep.md("`tool_size_bench` drives the instrument's contact directly at 1 kHz (the tool vertical, one contact point, "
           "the shipped scene's law and material). The tip is a flat punch of radius a (`tool.tip_radius`, in metres; "
           "a 5 mm tip here, a 10 mm instrument). The footprint contact integrates each node's shape functions against "
           "the punch's pressure over the tip's disc, and adds in series the near field the mesh cannot resolve, "
           "so that the patch's total compliance is the punch's Boussinesq compliance (1 - nu^2) / (2 a E) plus the "
           "mesh's smooth remainder: the tensors' compliance less its own field within one ring of each node, and "
           "less the Boussinesq kernel beyond (`common/contact/near_field.h`). The earlier model "
           "put Wendland weights on the nodes within the radius, with no near field; its old default radius was 2.5 "
           "mean surface edges, so the tip grew with the mesh. Both run side by side in one run: `footprint 5 mm`, "
           "`nodes 5 mm` (the earlier model at the same 5 mm) and `nodes 2.5 edges` (the earlier model at its old "
           "default). The livers are the shipped liver meshed at the target node counts in their names (1500, 5000 "
           "and 20000 give about 1.4k, 4.9k and 21.2k nodes; the step log prints the counts); the finest is the "
           "reference. Slide: the tip 5 mm below the rest surface, moved 7 cm across the liver's curved top at 2 cm/s; "
           "ripple is the peak-to-peak of the force less its 2 cm centred moving average, over its mean. Press: the "
           "force at each mm of depth, 1 to 10 mm, at one point. Punch: a 5 mm tip pressed 1 mm into a 20 x 20 x 4 cm "
           "slab with a fixed bottom, at 11 positions across a cell, against the bonded-layer solution of Hayes et al. "
           "1972 (`tests/support/layer_indentation.h`).")
    rep.md()
    rows = rep.csv_rows("tool_size")
    if rows is None:
        missing_line(rep, "`csv/tool_size.csv`", "tool_size")
        rows = []
    else:
        rep.md("Data: [`csv/tool_size.csv`](csv/tool_size.csv)" + "".join(
            ", [`csv/%s.csv`](csv/%s.csv)" % (n, n) for n in ("tool_size_slide", "tool_size_press")
            if os.path.exists(os.path.join(rep.root, "csv", n + ".csv"))))
        rep.md()
    fig = {}
    for r in rows:
        fig[(r.get("mesh"), r.get("model"), r.get("case"), r.get("metric"))] = r.get("value")
    livers = liver_meshes(rows)
    ref = livers[-1] if livers else None
    coarse = livers[:-1]
    slabs = [m for m in in_order(rows, "mesh", ()) if str(m).startswith("slab")]
    write_budgets(rep, rows, fig, livers, ref, coarse, slabs)
    if rows:
        write_meshes(rep, rows, fig, livers, ref)
        write_punch(rep, rows, fig, slabs)
    plot_slide(rep)
    plot_press(rep)


def write_budgets(rep, rows, fig, livers, ref, coarse, slabs):
    """One row per budgeted figure: the worst over the meshes, the budget, the verdict (each to the headline)."""
    rep.md("### Against the budgets (docs/DESIGN.md, \"The instrument's contact\")")
    rep.md()
    rep.md("| figure | value (worst over meshes) | budget | verdict |")
    rep.md("|---|---|---|---|")
    table = []
    nothing = "**Missing**: %s (%s)" % ("no such rows in `csv/tool_size.csv`" if rows else "`csv/tool_size.csv`",
                                        step_note(rep, "tool_size"))
    against = "%s against %s" % (" and ".join(coarse) or "the coarser livers", ref or "the finest liver")
    # The coarser livers against the finest, the footprint model.
    for metric, what, key in (
            ("mean_force_error", "mean slide force, %s, %s" % (against, FOOTPRINT), "tool_mean_force_pct"),
            ("depth_force_worst_error", "force against depth 1-10 mm, %s, %s, at every depth" % (against, FOOTPRINT),
             "tool_depth_force_pct")):
        w = worst([(fig.get((m, FOOTPRINT, "against_reference", metric)), m) for m in coarse])
        budget = "within %g %%" % BUDGETS[key]
        if w is None:
            table.append((what, nothing, budget, None))
        else:
            table.append((what, "%s (%s)" % (pct(w[0]), w[1]), budget, verdict(abs(w[0]) <= BUDGETS[key])))
    w = worst([(fig.get((m, FOOTPRINT, "slide", "ripple")), m) for m in livers], signed=False)
    what = "ripple along the slide, every liver%s, %s" % (" (%s)" % ", ".join(livers) if livers else "", FOOTPRINT)
    budget = "<= %g %%" % BUDGETS["tool_ripple_pct"]
    if w is None:
        table.append((what, nothing, budget, None))
    else:
        table.append((what, "%.2f %% (%s)" % w, budget, verdict(w[0] <= BUDGETS["tool_ripple_pct"])))
    # Every slab on its own row: the finer one passing does not hide the coarser one failing.
    budget = "within %g %%" % BUDGETS["tool_punch_pct"]
    for slab in slabs or ["the slab"]:
        err = fig.get((slab, FOOTPRINT, "punch", "error"))
        what = "flat punch against Hayes 1972 (a 5 mm, 1 mm deep, 4 cm thick slab), %s, %s" % (slab, FOOTPRINT)
        if not number(err):
            table.append((what, nothing, budget, None))
        else:
            force, ref_n = (fig.get((slab, FOOTPRINT, "punch", k)) for k in ("force", "reference"))
            table.append((what, "%s (%s N against %s N)" % (pct(err), fmt(force), fmt(ref_n)), budget,
                          verdict(abs(err) <= BUDGETS["tool_punch_pct"])))
    # The tick with 10 contacts of the footprint model: tool_size_bench's own timing of ToolContacts::step (10 patch
    # contacts sliding), on every liver; the worst carries the verdict.
    budget = "<= %g us" % BUDGETS["tick_p99_us"]
    what = "contact tick p99 with 10 patch contacts (%s, `ToolContacts::step`, every liver)" % FOOTPRINT
    own = [(fig.get((m, FOOTPRINT, "tick", "tick_us_p99")), m) for m in livers]
    w = worst(own, signed=False)
    if w is None:
        table.append((what, "**Missing**: no tick rows in `csv/tool_size.csv` (%s)" % step_note(rep, "tool_size"),
                      budget, None))
    else:
        each = ", ".join("%s %s us" % (m, fmt(float(v))) for v, m in own if number(v))
        table.append((what, "p99 %s us at worst (%s)" % (fmt(float(w[0])), each), budget,
                      verdict(float(w[0]) <= BUDGETS["tick_p99_us"])))
    for what, value, budget, ok in table:
        rep.md("| %s | %s | %s | %s |" % (what, value, budget, ok or "-"))
        if ok:
            rep.headline.append(("tip size: " + what, value, budget, ok))
    rep.md()
    rep.md("The contact tick is timed by `tool_size_bench` on one instrument with 10 contact points 6 mm apart "
           "sliding at 4 mm depth (their footprints overlap: up to 64 union nodes), the earlier model beside it in "
           "`csv/tool_size.csv`. It is the contact stage alone, on this shared 2-core machine: a timing, not a test.")
    # node_bench's tick with 10 point contacts (the triangle model's solve), for comparison.
    ticks = rep.csv_rows("node_tick")
    bench = [r for r in (ticks or []) if r.get("contacts") == 10 and number(r.get("tick_us_p99"))]
    if bench:
        rep.md("For comparison, `node_bench`'s tick with 10 point contacts (the superposition solve): %s." % ", ".join(
            "p99 %.1f us (%s nodes)" % (r["tick_us_p99"], r.get("nodes", "?")) for r in bench))
    rep.md()


def write_meshes(rep, rows, fig, livers, ref):
    """Rows: the livers; for each model its tip radius, mean slide force, ripple, error against the finest liver."""
    if not livers:
        return
    models = in_order([r for r in rows if r.get("mesh") in livers], "model", MODELS)
    rep.md("### The three models on the three livers")
    rep.md()
    rep.md("Per model: the tip's radius, the mean force along the slide, its ripple, and the error against %s with "
           "the same model (mean slide force / worst force over 1-10 mm depth)." % ref)
    rep.md()
    head, rule = ["mesh"], ["---"]
    for m in models:
        head += ["%s: tip mm" % m, "mean force N", "ripple", "error (mean / depth)"]
        rule += ["---"] * 4
    rep.md("| " + " | ".join(head) + " |")
    rep.md("|" + "|".join(rule) + "|")
    for mesh in livers:
        cells = [mesh]
        for m in models:
            radius = fig.get((mesh, m, "slide", "tip_radius"))
            mean = fig.get((mesh, m, "slide", "mean_force"))
            ripple = fig.get((mesh, m, "slide", "ripple"))
            if mesh == ref:
                err = "(reference)"
            else:
                e1 = fig.get((mesh, m, "against_reference", "mean_force_error"))
                e2 = fig.get((mesh, m, "against_reference", "depth_force_worst_error"))
                err = "%s / %s" % (pct(e1) if e1 is not None else "-", pct(e2) if e2 is not None else "-")
            cells += [fmt(radius) if radius is not None else "-", fmt(mean) if mean is not None else "-",
                      "%s %%" % fmt(ripple) if number(ripple) else "-", err]
        rep.md("| " + " | ".join(cells) + " |")
    rep.md()


def write_punch(rep, rows, fig, slabs):
    """The flat punch on the slab, every model, against Hayes 1972."""
    if not slabs:
        return
    rep.md("### Flat punch on a bonded slab against Hayes 1972")
    rep.md()
    rep.md("The mean force over 11 positions across a cell against 2 a E delta / (1 - nu^2) kappa(a/h, nu); spread: "
           "(largest - smallest) / mean over the positions.")
    rep.md()
    rep.md("| slab | model | force N | Hayes reference N | error | spread across positions |")
    rep.md("|---|---|---|---|---|---|")
    for slab in slabs:
        for m in in_order([r for r in rows if r.get("mesh") == slab], "model", MODELS):
            g = lambda metric: fig.get((slab, m, "punch", metric))  # noqa: E731
            rep.md("| %s | %s | %s | %s | %s | %s |" % (
                slab, m, fmt(g("force")) if g("force") is not None else "-",
                fmt(g("reference")) if g("reference") is not None else "-", pct(g("error")),
                "%s %%" % fmt(g("spread")) if number(g("spread")) else "-"))
    rep.md()


def series(rows, xk, yk):
    """{(mesh, model): ([x], [y])} with finite values, in file order."""
    out = {}
    for r in rows:
        if number(r.get(xk)) and number(r.get(yk)):
            xs, ys = out.setdefault((r.get("mesh"), r.get("model")), ([], []))
            xs.append(r[xk])
            ys.append(r[yk])
    return out


def plot_slide(rep):
    rows = rep.csv_rows("tool_size_slide")
    if rows is None:
        missing_line(rep, "`csv/tool_size_slide.csv`, the force along the slide", "tool_size")
        return
    data = series(rows, "s_mm", "force_N")
    livers = liver_meshes(rows)
    models = [m for m in in_order(rows, "model", MODELS) if any((mesh, m) in data for mesh in livers)]
    if not models:
        rep.md("(no finite force in `csv/tool_size_slide.csv`)")
        rep.md()
        return
    f, axes = plt.subplots(len(models), 1, figsize=(9, 2.8 * len(models)), squeeze=False, sharex=True)
    for ax, model in zip(axes[:, 0], models):
        for i, mesh in enumerate(livers):
            if (mesh, model) in data:
                ax.plot(*data[(mesh, model)], lw=1, color="C%d" % i, label=mesh)
        ax.set_title(model, fontsize=9)
        ax.set_ylabel("force on the tool (N)")
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    axes[-1, 0].set_xlabel("position along the slide (mm), 5 mm below the rest surface")
    rep.save(f, "tool_size_slide", "Force along the 7 cm slide at 5 mm depth on the three livers, one panel per model: "
             "the footprint contact (top) against the earlier node patch at 5 mm and at its old default of 2.5 mean "
             "edges.")


def plot_press(rep):
    rows = rep.csv_rows("tool_size_press")
    if rows is None:
        missing_line(rep, "`csv/tool_size_press.csv`, the force against depth", "tool_size")
        return
    data = series(rows, "depth_mm", "force_N")
    livers = liver_meshes(rows)
    if not any((mesh, m) in data for mesh in livers for m in (FOOTPRINT, NODES)):
        rep.md("(no finite force in `csv/tool_size_press.csv`)")
        rep.md()
        return
    f, ax = plt.subplots(figsize=(7, 4.5))
    for i, mesh in enumerate(livers):
        for model, style, marker in ((FOOTPRINT, "-", "o"), (NODES, "--", "s")):
            if (mesh, model) in data:
                ax.plot(*data[(mesh, model)], style, marker=marker, ms=3, lw=1.2, color="C%d" % i,
                        label="%s, %s" % (mesh, model))
    ax.set_xlabel("depth below the rest surface (mm)")
    ax.set_ylabel("force on the tool (N)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    rep.save(f, "tool_size_press", "Force against depth on the three livers: the footprint contact (solid) and the "
             "earlier node patch at 5 mm (dashed).")
