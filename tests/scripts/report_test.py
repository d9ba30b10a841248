#!/usr/bin/python3
"""Tests scripts/report.py on a synthetic report folder (no benches run): the haptic-rate error it computes against
an analytic value, the tables and plots it writes, the stamp on every CSV, and that a missing input is reported as
missing rather than invented.

    /usr/bin/python3 tests/scripts/report_test.py SOURCE_DIR
"""
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

SOURCE = sys.argv.pop(1) if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "..")
REPORT_PY = os.path.join(SOURCE, "scripts", "report.py")


def write(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def haptic_log(path, rate, duration):
    """A ramp force fz = t (N) sampled at `rate`: the held 100 Hz signal lags the 10 kHz one by up to 10 ms."""
    lines = ["tick,t,fx,fy,fz,contacts"]
    for k in range(int(round(duration * rate))):
        t = k / rate
        lines.append("%d,%.9f,0,0,%.9f,1" % (k, t, t))
    write(path, "\n".join(lines) + "\n")


def stats(path, rate, ticks):
    write(path, json.dumps({"ticks": ticks, "rate_hz": rate,
                            "tick_us": {"p50": 10.0, "p99": 20.0, "mean": 12.0, "max": 30.0, "count": ticks}}))


class ReportTest(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="surgsim-report-test-")
        write(os.path.join(self.dir, "meta.json"), json.dumps({
            "commit": "0123456789abcdef", "dirty": False, "command": "scripts/report.sh --quick", "cpu": "Test CPU",
            "cores": 2, "memory_gib": 1.0, "kernel": "k", "os": "Debian", "load_at_start": "0 0 0",
            "date": "2026-01-01T00:00:00Z", "quick": 1, "build_s": 0}))
        write(os.path.join(self.dir, "csv", "liver_error_time.csv"),
              "family,variant,time_per_frame_us_p50,time_per_frame_us_p99,disp_rel_error,force_rel_error,memory_mib\n"
              "full_solve,factor+solve,50000,60000,0,0,10\n"
              "tensors_double,double,5,7,1e-15,2e-15,50\n"
              "tensors_float,float,4,6,3e-7,2e-7,25\n")
        # The other sections' inputs, a few rows each in the bench programs' formats.
        for name in ("intestine_timestep", "intestine_pairs", "intestine_lod", "stability", "liver_nonlinear",
                     "liver_mesh_convergence", "node_tick", "liver_precompute", "rt_floor", "haptic_signal",
                     "haptic_signal_slide"):
            shutil.copy(os.path.join(os.path.dirname(os.path.abspath(__file__)), "fixtures", name + ".csv"),
                        os.path.join(self.dir, "csv", name + ".csv"))
        rates = os.path.join(self.dir, "raw", "rates")
        for rate in (100, 10000):
            haptic_log(os.path.join(rates, "ramp_%d.csv" % rate), rate, 1.0)
            stats(os.path.join(rates, "ramp_%d.json" % rate), rate, int(rate))
        os.makedirs(os.path.join(self.dir, "plots"))

    def tearDown(self):
        shutil.rmtree(self.dir)

    def run_report(self):
        return subprocess.run(["/usr/bin/python3", REPORT_PY, self.dir], capture_output=True, text=True)

    def test_writes_tables_plots_and_stamps(self):
        r = self.run_report()
        self.assertEqual(r.returncode, 0, r.stderr)
        with open(os.path.join(self.dir, "README.md")) as f:
            text = f.read()
        self.assertIn("## Headline", text)
        self.assertIn("| tensors_float | float |", text)
        self.assertIn("Test CPU", text)
        self.assertNotIn("failed**", text)
        self.assertIn("| intestine step (400 masses + collisions), dt 1 ms | p99 699 us", text)
        self.assertIn("| stability: cases with only finite outputs | 2 of 3 | all | **over** |", text)
        # Issue 14's section: the patch contact against the paper's triangle, each against its budget.
        self.assertIn("| slab slide 31.7 deg 3 mm | ripple | 96.77 % | 2.975 % | - | <= 5 % | within |", text)
        self.assertIn("| slab onset 0.1 m/s to 3 mm | step_max | 3.333 % of held | 6.5 % of held | 7 % of held | <= 5 % | **over** |", text)
        self.assertIn("plots/haptic_signal_slide.png", text)
        self.assertIn("| precompute, 1382-node liver (direct, double) | 1.20 s | <= 2 s | within |", text)
        self.assertIn("(rt_bench, 10000 ticks) | 30 missed (0.300 %), wake-up late p99 25 / max 3533 us | < 0.1 % missed | **over** |",
                      text)
        for plot in ("liver_error_vs_time", "liver_haptic_rate", "intestine_timestep", "intestine_pairs",
                     "intestine_lod", "liver_nonlinear", "liver_mesh_convergence"):
            self.assertGreater(os.path.getsize(os.path.join(self.dir, "plots", plot + ".png")), 1000)
        with open(os.path.join(self.dir, "csv", "liver_error_time.csv")) as f:
            first = f.readline()
        self.assertTrue(first.startswith("# Test CPU") and "0123456789ab" in first, first)
        # Running twice does not stamp twice.
        self.assertEqual(self.run_report().returncode, 0)
        with open(os.path.join(self.dir, "csv", "liver_error_time.csv")) as f:
            self.assertEqual(sum(1 for line in f if line.startswith("#")), 1)

    def test_held_signal_error_matches_the_analytic_value(self):
        self.assertEqual(self.run_report().returncode, 0)
        rows = {}
        with open(os.path.join(self.dir, "csv", "liver_haptic_rate.csv")) as f:
            lines = [line for line in f if not line.startswith("#")]
        header = lines[0].strip().split(",")
        for line in lines[1:]:
            row = dict(zip(header, line.strip().split(",")))
            rows[int(row["rate_hz"])] = row
        # f = t held at 100 Hz: error e(t) = t - floor(100 t) / 100, a sawtooth of amplitude h = 10 ms over [0, 1):
        # RMS h / sqrt(3) (to the 10 kHz grid's resolution), max h - 0.1 ms; reference RMS 1 / sqrt(3).
        h = 0.01
        self.assertAlmostEqual(float(rows[100]["force_rms_rel_error"]), h, delta=2e-4)
        self.assertAlmostEqual(float(rows[100]["force_max_error_n"]), h - 1e-4, delta=1e-6)
        self.assertEqual(float(rows[10000]["force_rms_rel_error"]), 0.0)
        # CPU per simulated second = rate x mean tick time.
        self.assertTrue(math.isclose(float(rows[100]["cpu_ms_per_sim_s"]), 100 * 12.0 / 1000.0))

    def test_missing_inputs_are_named_not_invented(self):
        self.assertEqual(self.run_report().returncode, 0)
        with open(os.path.join(self.dir, "README.md")) as f:
            text = f.read()
        self.assertIn("**Missing**: `csv/intestine_frame_rate.csv` was not written", text)
        self.assertIn("Missing inputs:", text)
        self.assertIn("`raw/live_liver/haptic_stats.json`", text)

    def test_refuses_a_folder_without_meta(self):
        os.remove(os.path.join(self.dir, "meta.json"))
        r = self.run_report()
        self.assertEqual(r.returncode, 1)
        self.assertIn("meta.json not found", r.stderr)


if __name__ == "__main__":
    unittest.main(verbosity=2)
