"""The benchmark report's writer: turns the measurements of scripts/report.sh into REPORT_DIR/README.md (Markdown
tables), REPORT_DIR/plots/*.png and stamped CSV files.

    /usr/bin/python3 scripts/report/build.py REPORT_DIR

document.py holds the report being written (inputs, Markdown, plots) and the helpers the sections share; each
section is a module with a TITLE and write(rep); sections.py lists them in the report's order, which gives their
numbers. large_deformation.py, scale.py and web.py also run on their own (see each one's usage)."""
