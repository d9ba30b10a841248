"""The report's sections in their order. A section's number is its position in SECTIONS (from 1): add, remove or
move a section here, and the numbers of the headings follow; no title carries a number of its own.

A section is a module with TITLE (the heading's text) and write(rep), which writes the section's body into the
report (report.document.Report) under the heading build.py puts above it."""
from report import (benchmarks, haptic_signal, intestine_error, intestine_live, large_deformation, liver_error, scale,
                    stability, steps, tool_size, two_hands, web, abdomen)

SECTIONS = [
    liver_error,
    intestine_error,
    stability,
    benchmarks,
    haptic_signal,
    tool_size,
    two_hands,
    abdomen,
    intestine_live,
    large_deformation,
    scale,
    web,
    steps,
]


def number(section):
    """The number of a section (one of the SECTIONS modules) in the report."""
    return SECTIONS.index(section) + 1


def heading(section):
    """The section's heading in README.md, e.g. '## 1. Error against run time: liver'."""
    return "## %d. %s" % (number(section), section.TITLE)
