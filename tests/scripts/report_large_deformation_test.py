#!/usr/bin/python3
"""Tests scripts/report/large_deformation.py on a synthetic liver_large_deformation.csv: the plot is
written from every case and method, a cell the bench left as nan is skipped, and a missing CSV gives None (no plot
invented).

    /usr/bin/python3 tests/scripts/report_large_deformation_test.py SOURCE_DIR
"""
import math
import os
import sys
import tempfile
import unittest

SOURCE = sys.argv.pop(1) if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "..")
sys.path.insert(0, os.path.join(SOURCE, "scripts"))
from report import large_deformation as rld  # noqa: E402

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
        # scripts/report/build.py puts a '# machine, commit, command' line on top of every CSV before its sections read them.
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

    def test_node_table_per_phase_with_verdicts(self):
        # multirate_node_bench's CSV: per phase p50 / p99 / max of both models, the 10 % budget on the p99.
        with tempfile.TemporaryDirectory() as d:
            self.assertEqual(rld.node_markdown(d), [])
            with open(os.path.join(d, rld.NODE), "w") as f:
                f.write("# stamped\n")
                f.write("t_s,phase,nodes,f_ref_n,f_multirate_n,f_linear_n,multirate_rel_error,linear_rel_error,model\n")
                f.write("1.0,grasp,23,0.1,0.1,0.1,0.001,0.005,nonlinear\n")
                f.write("2.0,lift,23,1.0,1.1,0.8,0.02,0.2,nonlinear\n")
                f.write("2.1,lift,23,2.0,2.4,1.5,0.2,0.25,partial\n")
                f.write("3.0,hold,23,4.0,4.6,2.5,0.15,0.48,nonlinear\n")
            md = rld.node_markdown(d)
            self.assertEqual(len(md), 6)  # header, rule, grasp, lift, hold, all
            self.assertEqual(md[2], "| grasp | 1 | 0.10 / 0.10 / 0.10 % | 0.50 / 0.50 / 0.50 % | <= 10 % | within |")
            self.assertEqual(md[3], "| lift | 2 | 2.00 / 2.00 / 20.00 % | 20.00 / 20.00 / 25.00 % | <= 10 % | within |")
            self.assertTrue(md[5].startswith("| all | 4 | "), md[5])
            self.assertTrue(md[5].endswith("| over |"), md[5])

    def test_missing_csv_gives_none(self):
        with tempfile.TemporaryDirectory() as d:
            self.assertIsNone(rld.plot(d, d))
            self.assertFalse(os.path.exists(os.path.join(d, "liver_large_deformation.png")))


if __name__ == "__main__":
    unittest.main()
