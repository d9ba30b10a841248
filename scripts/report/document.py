"""The report's document: its inputs (meta.json, csv/*.csv, raw/, logs/ of a report folder), its Markdown (tables,
headline, missing inputs) and its plots, and the helpers every section shares. Sections get a Report and write into
it; build.py numbers them and writes README.md."""
import csv
import glob
import json
import math
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


class Report:
    def __init__(self, root):
        self.root = root
        self.meta = self.load_json("meta.json") or {}
        end = self.load_json("raw/end.json") or {}
        self.meta.update(end)
        self.lines = []
        self.headline = []  # (what, value, budget or reference, verdict)
        self.missing = []

    # ---- inputs -----------------------------------------------------------------------------------------------
    def load_json(self, rel):
        path = os.path.join(self.root, rel)
        if not os.path.exists(path):
            return None
        with open(path) as f:
            return json.load(f)

    def csv_rows(self, name):
        """Rows of csv/NAME.csv as dicts, numbers converted; None when the file is missing."""
        path = os.path.join(self.root, "csv", name + ".csv")
        if not os.path.exists(path):
            if "csv/%s.csv" % name not in self.missing:
                self.missing.append("csv/%s.csv" % name)
            return None
        with open(path) as f:
            lines = [ln for ln in f if not ln.startswith("#")]
        return [{k: convert(v) for k, v in row.items()} for row in csv.DictReader(lines)]

    def stamp(self):
        return "%s, %s cores, %s GiB; commit %s%s; %s; %s" % (
            self.meta.get("cpu", "?"), self.meta.get("cores", "?"), self.meta.get("memory_gib", "?"),
            str(self.meta.get("commit", "?"))[:12], " (modified)" if self.meta.get("dirty") else "",
            self.meta.get("command", "?"), self.meta.get("date", "?"))

    def stamp_csv_files(self):
        """Puts the machine/commit/command line at the top of every CSV (a '#' comment; readers skip it)."""
        line = "# " + self.stamp() + "\n"
        for path in sorted(glob.glob(os.path.join(self.root, "csv", "*.csv"))):
            with open(path) as f:
                text = f.read()
            if not text.startswith("#"):
                with open(path, "w") as f:
                    f.write(line + text)

    # ---- output -----------------------------------------------------------------------------------------------
    def md(self, text=""):
        self.lines.append(text)

    def table(self, rows, columns=None, headers=None):
        if not rows:
            self.md("(no rows)")
            self.md()
            return
        columns = columns or list(rows[0].keys())
        headers = headers or columns
        self.md("| " + " | ".join(headers) + " |")
        self.md("|" + "---|" * len(columns))
        for r in rows:
            self.md("| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |")
        self.md()

    def csv_section(self, name, title, text, columns=None):
        """csv/NAME.csv as a table under '### TITLE' (no heading when TITLE is None), TEXT above it; its rows, or
        None (and a Missing line) when the file is missing."""
        rows = self.csv_rows(name)
        if title is not None:
            self.md("### " + title)
            self.md()
        if text:
            self.md(text)
            self.md()
        if rows is None:
            self.md("**Missing**: `csv/%s.csv` was not written (see the step logs below)." % name)
            self.md()
            return None
        self.md("Data: [`csv/%s.csv`](csv/%s.csv)" % (name, name))
        self.md()
        self.table(rows, columns)
        return rows

    def save(self, fig, name, caption):
        fig.text(0.005, 0.005, self.stamp(), fontsize=5.5, color="0.35", ha="left", va="bottom")
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        path = os.path.join(self.root, "plots", name + ".png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        self.md("![%s](plots/%s.png)" % (caption, name))
        self.md()
        self.md("*%s*" % caption)
        self.md()

    def write(self):
        head = [
            "# surgsim benchmark report",
            "",
            "Made by `%s` on %s." % (self.meta.get("command", "scripts/report.sh"), self.meta.get("date", "?")),
            "",
            "| machine | commit | load (1/5/15 min) start / end | build s | total s |",
            "|---|---|---|---|---|",
            "| %s, %s cores, %s GiB, %s, kernel %s | `%s`%s | %s / %s | %s | %s |" % (
                self.meta.get("cpu"), self.meta.get("cores"), self.meta.get("memory_gib"), self.meta.get("os"),
                self.meta.get("kernel"), self.meta.get("commit"), " (modified tree)" if self.meta.get("dirty") else "",
                self.meta.get("load_at_start"), self.meta.get("load_at_end"), self.meta.get("build_s"),
                self.meta.get("total_s")),
            "",
            "Every number below comes from this run; the CSV files carry the same machine/commit/command line, and",
            "each plot states it in its footer. The machine is shared: timings are percentiles of what it gave us.",
            "",
            "## Headline",
            "",
            "| what | measured | budget / reference | verdict |",
            "|---|---|---|---|",
        ]
        for what, value, budget, verdict in self.headline:
            head.append("| %s | %s | %s | %s |" % (what, value, budget, verdict))
        head.append("")
        if self.missing:
            head.append("Missing inputs: " + ", ".join("`%s`" % m for m in self.missing))
            head.append("")
        with open(os.path.join(self.root, "README.md"), "w") as f:
            f.write("\n".join(head + self.lines) + "\n")


def convert(v):
    if v is None:
        return ""
    s = v.strip()
    try:
        if s.lstrip("-").isdigit():
            return int(s)
        return float(s)
    except ValueError:
        return s


def fmt(v):
    if isinstance(v, float):
        if math.isnan(v) or math.isinf(v):
            return str(v)
        if v == 0:
            return "0"
        a = abs(v)
        if a >= 1e5 or a < 1e-3:
            return "%.3g" % v
        if a >= 100:
            return "%.1f" % v
        return "%.4g" % v
    return str(v)


def budget_table(rep, rows, budget_header="budget", headline_prefix=""):
    """Rows (what, measured, budget, verdict) as a Markdown table; those with a budget go to the headline too."""
    rep.md("| what | measured | %s | verdict |" % budget_header)
    rep.md("|---|---|---|---|")
    for r in rows:
        rep.md("| %s | %s | %s | %s |" % r)
    rep.md()
    for r in rows:
        if r[2]:
            rep.headline.append((headline_prefix + r[0],) + tuple(r[1:]))


def verdict(ok):
    return "within" if ok else "**over**"


def number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def first_key(row, *candidates):
    for c in candidates:
        if c in row:
            return c
    for c in row:
        for cand in candidates:
            if cand in c:
                return c
    return None


def embed_log_table(rep, step, title):
    """The Markdown table a step printed (its lines starting with '|', and '(' notes), under a heading."""
    path = os.path.join(rep.root, "logs", step + ".log")
    if not os.path.exists(path):
        return
    rep.md("### " + title)
    rep.md()
    with open(path) as f:
        for line in f:
            if line.startswith("|") or line.startswith("("):
                rep.md(line.rstrip())
    rep.md()


def twin_plot(rep, rows, xk, yk, y2k, name, caption, xlabel, xscale="linear", yscale="linear"):
    """yk (left axis) and y2k (right axis, optional) against xk."""
    if not xk or not yk:
        return
    fig, ax = plt.subplots(figsize=(7, 4))
    pts = [r for r in rows if number(r[xk]) and number(r[yk])]
    ax.plot([r[xk] for r in pts], [max(r[yk], 1e-12) if yscale == "log" else r[yk] for r in pts], marker="o",
            color="C0")
    if xscale == "symlog":
        ax.set_xscale("symlog", linthresh=1)
    ax.set_yscale(yscale)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(yk, color="C0")
    if y2k:
        ax2 = ax.twinx()
        pts = [r for r in rows if number(r[xk]) and number(r[y2k])]
        ax2.plot([r[xk] for r in pts], [r[y2k] for r in pts], marker="s", color="C1")
        ax2.set_ylabel(y2k, color="C1")
    ax.grid(True, alpha=0.3)
    rep.save(fig, name, caption)


def step_status(rep, name):
    """'ok', 'failed' or None (the step did not run) from raw/steps.csv."""
    path = os.path.join(rep.root, "raw", "steps.csv")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        for r in csv.DictReader(f):
            if r.get("step") == name:
                return r.get("status")
    return None


def step_note(rep, step):
    """Why a step's output may be missing: its status and log, for a report line."""
    status = step_status(rep, step)
    if status == "failed":
        return "the %s step failed: see [`logs/%s.log`](logs/%s.log)" % (step, step, step)
    if status == "ok":
        return "the %s step ran but did not write it: see [`logs/%s.log`](logs/%s.log)" % (step, step, step)
    return "the %s step did not run" % step


def missing_line(rep, what, step):
    rep.md("**Missing**: %s (%s)." % (what, step_note(rep, step)))
    rep.md()


def load_json_safe(rep, rel):
    """load_json, but a truncated or broken file (a run killed mid-write) is None, not an exception."""
    try:
        return rep.load_json(rel)
    except (ValueError, OSError):
        return None
