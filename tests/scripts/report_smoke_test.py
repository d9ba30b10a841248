#!/usr/bin/python3
"""Runs scripts/report.sh --smoke --no-build against a build, end to end, into a fresh folder, and checks that every
step succeeded (raw/steps.csv and the exit status), that README.md carries every section of
scripts/report/sections.py under its number and in that order, that no section failed and that no input a section
reads is missing. The figures are not checked (a smoke run's numbers mean nothing; timings are never asserted).
4-5 minutes on 2 cores; needs the benchmark programs (SURGSIM_BUILD_BENCHMARKS) and the visual node.

    /usr/bin/python3 tests/scripts/report_smoke_test.py SOURCE_DIR BUILD_DIR

Exit 0 when every check holds (the report folder is then removed), 1 with one line per failed check and the end of
each failed step's log (the folder is kept, its path printed).
"""
import csv
import os
import shutil
import subprocess
import sys
import tempfile


def check(out, run, sections):
    """The failed checks, as lines."""
    problems = []
    steps_path = os.path.join(out, "raw", "steps.csv")
    if not os.path.exists(steps_path):
        return ["no %s: report.sh stopped before its first step; its output ends with:\n%s" % (
            steps_path, (run.stdout + run.stderr)[-3000:])]
    with open(steps_path) as f:
        steps = list(csv.DictReader(f))
    for s in steps:
        if s["status"] != "ok":
            log = os.path.join(out, s["log"])
            tail = open(log, errors="replace").read()[-2000:] if os.path.exists(log) else "(no log)"
            problems.append("step %s: %s; the end of %s:\n%s" % (s["step"], s["status"], log, tail))
    if "render" not in [s["step"] for s in steps]:
        problems.append("no render step in %s: report.sh stopped early" % steps_path)
    if run.returncode != 0:
        problems.append("report.sh exited with %d; its output ends with:\n%s" % (run.returncode, run.stderr[-1500:]))
    readme = os.path.join(out, "README.md")
    if not os.path.exists(readme):
        return problems + ["no %s" % readme]
    with open(readme) as f:
        text = f.read()
    headings = [line for line in text.split("\n") if line.startswith("## ") and line != "## Headline"]
    expected = [sections.heading(s) for s in sections.SECTIONS]
    if headings != expected:
        problems.append("README.md's sections are\n  %s\nnot, as scripts/report/sections.py gives them,\n  %s" % (
            "\n  ".join(headings), "\n  ".join(expected)))
    for line in text.split("\n"):
        # A section that raised ('**section N, NAME.py failed**'), an input missing (the headline's list, a
        # section's own line, the patient-size section's form).
        if ("failed**" in line or line.startswith("Missing inputs:") or "**Missing**" in line
                or ": missing (run `" in line):
            problems.append("README.md: " + line)
    return problems


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    source, build = (os.path.abspath(a) for a in sys.argv[1:3])
    sys.path.insert(0, os.path.join(source, "scripts"))
    from report import sections
    folder = tempfile.mkdtemp(prefix="surgsim-report-smoke-")
    out = os.path.join(folder, "report")
    run = subprocess.run([os.path.join(source, "scripts", "report.sh"), "--smoke", "--no-build", "--out", out],
                         env=dict(os.environ, SURGSIM_BUILD_DIR=build), capture_output=True, text=True)
    problems = check(out, run, sections)
    if problems:
        for p in problems:
            print("report_smoke_test: " + p, file=sys.stderr)
        print("report_smoke_test: %d check(s) failed; the report is kept in %s" % (len(problems), out),
              file=sys.stderr)
        return 1
    shutil.rmtree(folder)
    print("report_smoke_test: every step ok, the %d sections in order, none failed, nothing missing" %
          len(sections.SECTIONS))
    return 0


if __name__ == "__main__":
    sys.exit(main())
