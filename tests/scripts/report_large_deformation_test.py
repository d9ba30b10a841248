#!/usr/bin/python3
"""Tests scripts/report_large_deformation.py (issue 16) on a synthetic liver_large_deformation.csv: the plot is
written from every case and method, a cell the bench left as nan is skipped, and a missing CSV gives None (no plot
invented).

    /usr/bin/python3 tests/scripts/report_large_deformation_test.py SOURCE_DIR
"""
import importlib.util
import math
import os
import sys
import tempfile
import unittest

SOURCE = sys.argv.pop(1) if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "..")
spec = importlib.util.spec_from_file_location(
    "report_large_deformation", os.path.join(SOURCE, "scripts", "report_large_deformation.py"))
rld = importlib.util.module_from_spec(spec)
spec.loader.exec_module(rld)

CASES = ["indent_%d" % d for d in (5, 10, 15, 20, 25, 30)] + ["lift_45", "lift_90", "rigid_90"]


class ReportLargeDeformation(unittest.TestCase):
    def test_plot_from_every_case_and_method(self):
        with tempfile.TemporaryDirectory() as d:
            with open(os.path.join(d, "liver_large_deformation.csv"), "w") as f:
                f.write("case,method,force_rel_error,disp_rel_error,tick_us_p99\n")
                for i, c in enumerate(CASES):
                    for j, m in enumerate(rld.METHODS):
                        force = "nan" if (c, m) == ("lift_90", "linear") else "%g" % (0.01 * (i + 1) * (j + 1))
                        f.write("%s,%s,%s,%g,%g\n" % (c, m, force, 0.02 * (i + 1), 10 + j))
            rows = rld.read(d)
            self.assertEqual(len(rows), len(CASES) * len(rld.METHODS))
            self.assertTrue(math.isnan(rows[("lift_90", "linear")]["force"]))
            self.assertAlmostEqual(rows[("indent_10", "quasi_organ")]["force"], 0.06)
            out = rld.plot(d, os.path.join(d, "plots"))
            self.assertTrue(os.path.getsize(out) > 10000, out)

    def test_reads_a_csv_stamped_by_report_py(self):
        # scripts/report.py puts a '# machine, commit, command' line on top of every CSV before its sections read them.
        with tempfile.TemporaryDirectory() as d:
            with open(os.path.join(d, "liver_large_deformation.csv"), "w") as f:
                f.write("# cpu, 2 cores; commit abc; scripts/report.sh; date\n")
                f.write("case,method,force_rel_error,disp_rel_error,tick_us_p99\n")
                f.write("indent_5,linear,0.0237,0.0236,14.7\n")
            rows = rld.read(d)
            self.assertEqual(list(rows), [("indent_5", "linear")])
            self.assertAlmostEqual(rows[("indent_5", "linear")]["force"], 0.0237)

    def test_motion_table_and_plot(self):
        # The multirate motion CSV: read, a markdown row per case and duration with a verdict, drawn in the plot.
        with tempfile.TemporaryDirectory() as d:
            with open(os.path.join(d, "liver_large_deformation.csv"), "w") as f:
                f.write("case,method,force_rel_error,disp_rel_error,tick_us_p99\n")
                for c in CASES:
                    f.write("%s,multirate,1e-10,1e-9,1.5\n" % c)
            with open(os.path.join(d, rld.MOTION), "w") as f:
                f.write("# stamped\n")
                f.write("case,method,duration_s,force_rel_error_p99,force_rel_error_max,slow_cycle_ms_p50,"
                        "slow_cycle_ms_p99\n")
                f.write("indent_20,multirate,1,0.012,0.02,31.5,40.1\n")
                f.write("lift_90,multirate,0.5,0.15,0.3,33,45\n")
            motion = rld.read_motion(d)
            self.assertEqual(set(motion), {("indent_20", 1.0), ("lift_90", 0.5)})
            self.assertAlmostEqual(motion[("lift_90", 0.5)]["cycle_p99"], 45)
            md = rld.motion_markdown(d)
            self.assertEqual(len(md), 4)
            self.assertIn("| indent_20 | multirate | 1 | 1.20 % |", md[2])
            self.assertTrue(md[2].endswith("| <= 5 % | within |"), md[2])
            self.assertTrue(md[3].endswith("| <= 10 % | over |"), md[3])
            out = rld.plot(d, os.path.join(d, "plots"))
            self.assertTrue(os.path.getsize(out) > 10000, out)
            os.remove(os.path.join(d, rld.MOTION))
            self.assertEqual(rld.motion_markdown(d), [])

    def test_missing_csv_gives_none(self):
        with tempfile.TemporaryDirectory() as d:
            self.assertIsNone(rld.plot(d, d))
            self.assertFalse(os.path.exists(os.path.join(d, "liver_large_deformation.png")))


if __name__ == "__main__":
    unittest.main()
