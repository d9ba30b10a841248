"""Stability on stiff and extreme cases: what happens in every case of stability_report (converged, clamped,
refused, detected ...), and whether every output was finite."""
from report.document import verdict

TITLE = "Stability on stiff and extreme cases"


def write(rep):
    rows = rep.csv_section("stability", "Every case: what happens",
                           "Outcome per case (converged, clamped, refused, detected ...), with residuals and condition "
                           "estimates; `all_finite` says whether every output was checked finite.")
    if rows:
        finite = [r for r in rows if str(r.get("all_finite")).lower() in ("1", "true", "yes")]
        outcomes = {}
        for r in rows:
            outcomes[r.get("outcome")] = outcomes.get(r.get("outcome"), 0) + 1
        rep.headline.append(("stability: cases with only finite outputs", "%d of %d" % (len(finite), len(rows)),
                             "all", verdict(len(finite) == len(rows))))
        rep.headline.append(("stability: outcomes", ", ".join("%s %d" % kv for kv in sorted(outcomes.items())), "", ""))
