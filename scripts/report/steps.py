"""How this report was made: every step of scripts/report.sh with its time, status and log (raw/steps.csv), and the
command."""
import csv
import os

from report.document import convert

TITLE = "How this report was made"


def write(rep):
    path = os.path.join(rep.root, "raw", "steps.csv")
    if os.path.exists(path):
        with open(path) as f:
            rows = [{k: convert(v) for k, v in r.items()} for r in csv.DictReader(f)]
        rep.table(rows)
    rep.md("Command: `%s`. Programs: `build/bench/*` and `build/bin/*` of this commit; logs in `logs/`." %
           rep.meta.get("command"))
    rep.md()
