#!/usr/bin/python3
"""Tests the report's writer (the package scripts/report/, run as scripts/report/build.py) on a synthetic report
folder (no benches run): the haptic-rate error it computes against an analytic value, the tables and plots it writes,
the stamp on every CSV, that a missing input is reported as missing rather than invented, and that the sections are
numbered by their place in report/sections.py.

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
REPORT_PY = os.path.join(SOURCE, "scripts", "report", "build.py")
# The headings' numbers come from the list of sections (scripts/report/sections.py).
sys.path.insert(0, os.path.join(SOURCE, "scripts"))
from report import haptic_signal, intestine_live, sections, tool_size  # noqa: E402


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
                     "haptic_signal_slide", "tool_size", "tool_size_slide", "tool_size_press"):
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

    def report_text(self):
        """Runs build.py (it must succeed) and returns README.md."""
        r = self.run_report()
        self.assertEqual(r.returncode, 0, r.stderr)
        with open(os.path.join(self.dir, "README.md")) as f:
            return f.read()

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
        # What the hand feels: the patch contact against the paper's triangle, each against its budget.
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

    def test_intestine_live_section(self):
        """The push run complete (floor, haptic and visual stats, a frame trace with a load step), the lift
        run with its floor and haptic stats but no visual node output: figures and verdicts for the first, a named
        missing line (no traceback) for the second."""
        with open(os.path.join(self.dir, "csv", "rt_floor.csv"), "a") as f:
            f.write("before_live_intestine_push,6500,1000,50,SCHED_FIFO,10,0.1538,0.01,35.2,4523.4,109.0\n")
            f.write("before_live_intestine_lift,7500,1000,50,SCHED_FIFO,3,0.0400,0.01,30.0,900.0,90.0\n")
        push = os.path.join(self.dir, "raw", "live_intestine_push")
        write(os.path.join(push, "haptic_stats.json"), json.dumps({
            "ticks": 6500, "rate_hz": 1000, "deadline_misses": 12, "achieved_hz": 999.9,
            "tick_us": {"p50": 560.0, "p99": 740.0}, "intestine": {"step_us": {"p50": 515.0, "p99": 669.0}}}))
        write(os.path.join(push, "visual_stats.json"), json.dumps({
            "fps": 29.85, "fps_configured": 30, "frames_late": 4,
            "frame_interval_ms": {"p50": 33.4, "p99": 60.0},
            "load_step": {"at_s": 2, "for_s": 2, "factor": 1.5},
            "intestine": {"work_ms": {"p50": 15.0}, "work_fps_mean": 62.0, "lod_mean": 4.2, "target_fps": 60}}))
        # 30 Hz frames over 6 s: LOD 5 until the load comes on at t = 2.0 s, then 4, 3 and 2 one frame apart, where it
        # stays (alternating 2-3) until the load goes off at t = 4.0 s; then 3 and 4, and 4-5 from t = 4.1 s.
        lines = ["t_s,lod,work_ms,interval_ms,fps,load_on", "-1.000000,6,1.0,33.3,30.0,0"]
        for k in range(180):
            t = k / 30.0
            on = 2.0 - 1e-9 <= t < 4.0 - 1e-9
            if t < 2.0 - 1e-9:
                lod = 5
            elif on:
                lod = [4, 3][k - 60] if k - 60 < 2 else 2 + (k % 2)
            else:
                lod = [3, 4, 4][k - 120] if k - 120 < 3 else 4 + (k % 2)
            lines.append("%.6f,%d,%.4f,33.3,30.0,%d" % (t, lod, 16.0 if on else 15.0, 1 if on else 0))
        write(os.path.join(push, "frames", "frame_trace.csv"), "\n".join(lines) + "\n")
        lift = os.path.join(self.dir, "raw", "live_intestine_lift")
        write(os.path.join(lift, "haptic_stats.json"), json.dumps({
            "ticks": 7500, "rate_hz": 1000, "deadline_misses": 40, "tick_us": {"p50": 600.0, "p99": 900.0}}))
        write(os.path.join(self.dir, "raw", "steps.csv"), "step,seconds,status,log\n"
              "live_intestine_lift,9.0,failed,logs/live_intestine_lift.log\n")
        text = self.report_text()
        self.assertIn("## %d. The intestine live at 1 kHz" % sections.number(intestine_live), text)
        self.assertNotIn("intestine_live.py failed", text)
        self.assertIn("| push: machine floor just before (rt_bench, 6500 ticks) | 10 missed (0.154 %) |", text)
        # 12 / 6500 = 0.185 %, 0.031 points over the floor's 0.154 %: within 0.1.
        self.assertIn("| push: missed deadlines, 6500 ticks at 1000 Hz | 12 (0.185 %), +0.031 points from the floor | "
                      "<= floor + 0.1 points | within |", text)
        self.assertIn("| push: intestine step (wall, live) | p50 515 / p99 669 us |", text)
        self.assertIn("| push: visual frames (whole run) | 29.85 fps, interval p50 33.4 / p99 60.0 ms, 4 late | "
                      ">= 97 % of 30 Hz | within |", text)
        self.assertIn("| push: visual frames from 1 s after the first frame shown (trace) | 30.00 fps |", text)
        # The load on at frame 60 (t = 2.0 s): band 2-3 (LOD 4 is within a level of it) reached at frame 61 (2.033 s);
        # off at frame 120 (4.0 s): band 4-5 reached at frame 121 (4.033 s).
        self.assertIn("| push: LOD controller: load on at 2.00 s | settled in 0.03 s to LOD 2-3, then 62 Hz of work | "
                      "<= 1 s | within |", text)
        self.assertIn("| push: LOD controller: load off at 4.00 s | settled in 0.03 s to LOD 4-5, then 67 Hz of work |",
                      text)
        self.assertIn("every frame's work x1.5 from 2 s", text)
        self.assertGreater(os.path.getsize(os.path.join(self.dir, "plots", "intestine_live_controller.png")), 1000)
        # 40 / 7500 = 0.533 % against the floor's 0.040 %: over.
        self.assertIn("| lift: missed deadlines, 7500 ticks at 1000 Hz | 40 (0.533 %), +0.493 points from the floor | "
                      "<= floor + 0.1 points | **over** |", text)
        self.assertIn("| lift: intestine step (wall, live) | not in the haptic stats |", text)
        self.assertIn("| lift: visual node | missing: `raw/live_intestine_lift/visual_stats.json` (the "
                      "live_intestine_lift step failed: see [`logs/live_intestine_lift.log`]", text)

    def test_intestine_live_section_with_nothing(self):
        text = self.report_text()
        self.assertNotIn("intestine_live.py failed", text)
        self.assertIn("| push: machine floor just before (rt_bench) | missing: no `before_live_intestine_push` row in "
                      "`csv/rt_floor.csv` (the rt_floor_intestine_push step did not run) |", text)
        self.assertIn("| lift: haptic node at 1 kHz | missing: `raw/live_intestine_lift/haptic_stats.json` (the "
                      "live_intestine_lift step did not run) |", text)

    def test_tool_size_section(self):
        """The footprint contact's figures against their budgets, each slab on its own row (the failing one shown),
        the tick from node_bench, the side-by-side and punch tables and both plots (fixtures from a real run)."""
        text = self.report_text()
        self.assertIn("## %d. The instrument's contact (tip size)" % sections.number(tool_size), text)
        self.assertEqual(sections.number(tool_size), sections.number(haptic_signal) + 1)
        self.assertNotIn("tool_size.py failed", text)
        self.assertIn("| mean slide force, liver 1500 and liver 5000 against liver 20000, footprint 5 mm | "
                      "-5.47 % (liver 1500) | within 5 % | **over** |", text)
        self.assertIn("| force against depth 1-10 mm, liver 1500 and liver 5000 against liver 20000, footprint 5 mm, "
                      "at every depth | -5.96 % (liver 1500) | within 5 % | **over** |", text)
        self.assertIn("| ripple along the slide, every liver (liver 1500, liver 5000, liver 20000), footprint 5 mm | "
                      "4.30 % (liver 5000) | <= 5 % | within |", text)
        self.assertIn("slab 1 cm cells, footprint 5 mm | -5.65 % (0.0407 N against 0.04314 N) | within 5 % | "
                      "**over** |", text)
        self.assertIn("slab 5 mm cells, footprint 5 mm | -3.42 % (0.04166 N against 0.04314 N) | within 5 % | within |",
                      text)
        self.assertIn("| contact tick p99 with 10 patch contacts (footprint 5 mm, `ToolContacts::step`, every liver) | "
                      "p99 460.3 us at worst (liver 1500 112.5 us, liver 5000 162.2 us, liver 20000 460.3 us) | "
                      "<= 100 us | **over** |", text)
        self.assertIn("`node_bench`'s tick with 10 point contacts (the superposition solve): p99 61.8 us (1382 nodes)",
                      text)
        self.assertIn("| tip size: ripple along the slide", text)  # in the headline too
        self.assertIn("| liver 5000 | 5 | 0.2016 | 4.304 % | -2.26 % / -1.74 % | 5 | 0.1654 | 84.4 % |", text)
        self.assertIn("| liver 20000 | 5 | 0.2063 | 2.337 % | (reference) |", text)
        self.assertIn("| slab 5 mm cells | nodes 2.5 edges | 0.06138 | 0.04314 | +42.29 % | 2.042 % |", text)
        for plot in ("tool_size_slide", "tool_size_press"):
            self.assertGreater(os.path.getsize(os.path.join(self.dir, "plots", plot + ".png")), 1000)

    def test_tool_size_section_with_nothing(self):
        for name in ("tool_size", "tool_size_slide", "tool_size_press", "node_tick"):
            os.remove(os.path.join(self.dir, "csv", name + ".csv"))
        text = self.report_text()
        self.assertNotIn("tool_size.py failed", text)
        self.assertIn("**Missing**: `csv/tool_size.csv` (the tool_size step did not run).", text)
        self.assertIn("| ripple along the slide, every liver, footprint 5 mm | **Missing**: `csv/tool_size.csv` (the "
                      "tool_size step did not run) | <= 5 % | - |", text)
        self.assertIn("| contact tick p99 with 10 patch contacts (footprint 5 mm, `ToolContacts::step`, every liver) | "
                      "**Missing**: no tick rows in `csv/tool_size.csv` (the tool_size step did not run) | <= 100 us | "
                      "- |", text)
        self.assertIn("**Missing**: `csv/tool_size_slide.csv`, the force along the slide (the tool_size step did not "
                      "run).", text)
        self.assertIn("`csv/tool_size_press.csv`", text.split("## Headline")[1].split("##")[0])  # Missing inputs
        self.assertFalse(os.path.exists(os.path.join(self.dir, "plots", "tool_size_slide.png")))

    def test_sections_numbered_by_the_list(self):
        text = self.report_text()
        headings = [line for line in text.split("\n") if line.startswith("## ") and line != "## Headline"]
        self.assertEqual(headings, ["## %d. %s" % (i + 1, s.TITLE) for i, s in enumerate(sections.SECTIONS)])

    def test_a_failing_section_is_named_and_the_rest_written(self):
        # haptic_signal.csv without its columns: that section raises; the report names it, writes the others, fails.
        write(os.path.join(self.dir, "csv", "haptic_signal.csv"), "nothing\n1\n")
        r = self.run_report()
        self.assertEqual(r.returncode, 1, r.stdout + r.stderr)
        with open(os.path.join(self.dir, "README.md")) as f:
            text = f.read()
        self.assertIn("**section %d, haptic_signal.py failed**: KeyError" % sections.number(haptic_signal), text)
        self.assertIn(sections.heading(sections.SECTIONS[-1]), text)

    def test_refuses_a_folder_without_meta(self):
        os.remove(os.path.join(self.dir, "meta.json"))
        r = self.run_report()
        self.assertEqual(r.returncode, 1)
        self.assertIn("meta.json not found", r.stderr)


if __name__ == "__main__":
    unittest.main(verbosity=2)
