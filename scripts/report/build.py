#!/usr/bin/python3
"""Turns the measurements of scripts/report.sh into report/README.md (Markdown tables) and report/plots/*.png.

    /usr/bin/python3 scripts/report/build.py REPORT_DIR

Reads REPORT_DIR/meta.json (machine, commit, command), REPORT_DIR/csv/*.csv (written by the bench programs with
--out), REPORT_DIR/raw/ (haptic logs at several rates, live-run stats JSON, step times) and REPORT_DIR/logs/. Every
number in the report comes from those files; a part whose input is missing is reported as missing, not invented.
The sections, their order and so their numbers come from report/sections.py. Uses Debian's python3-numpy and
python3-matplotlib only.
"""
import os
import sys

if __name__ == "__main__" and not __package__:
    # Run as a file: import the package from scripts/ (this folder's modules are not top-level modules).
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
from report.document import Report  # noqa: E402
from report.sections import SECTIONS, heading, number  # noqa: E402


def write_sections(rep):
    """Every section under its numbered heading; a section that raises is named in the report (the others still
    run). Returns the labels of those that failed."""
    failed = []
    for section in SECTIONS:
        rep.md(heading(section))
        rep.md()
        try:
            section.write(rep)
        except Exception as e:  # a broken input must not lose the rest of the report
            label = "section %d, %s.py" % (number(section), section.__name__.rsplit(".", 1)[-1])
            rep.md("**%s failed**: %s: %s" % (label, type(e).__name__, e))
            rep.md()
            rep.missing.append(label)
            failed.append(label)
    return failed


def main():
    if len(sys.argv) != 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        return 0 if len(sys.argv) == 2 else 2
    root = sys.argv[1]
    if not os.path.exists(os.path.join(root, "meta.json")):
        print("build.py: %s/meta.json not found (run scripts/report.sh, which writes it)" % root, file=sys.stderr)
        return 1
    rep = Report(root)
    rep.stamp_csv_files()
    failed = write_sections(rep)
    rep.write()
    print("build.py: wrote %s/README.md" % root)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
