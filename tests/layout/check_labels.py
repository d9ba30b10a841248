#!/usr/bin/python3
"""Every test named in a surgsim_label() list (tests/CMakeLists.txt: the `timing` tests the sanitizers leave out) is
a test ctest knows: ctest ignores a label set on a name it does not know, so a renamed test would silently lose its
label (and run, slow and failing, under the sanitizers). Also checks that the `timing` and `threaded` selections are
not empty. A test may carry both (a threaded program with one wall-clock test): scripts/sanitize.sh --threaded selects
`-L threaded -LE timing`, so the timing one still stays out.
Usage: check_labels.py BUILD_DIR"""
import glob
import os
import re
import subprocess
import sys

build = os.path.abspath(sys.argv[1])
listed = []
for path in sorted(glob.glob(os.path.join(build, 'tests', 'surgsim_label_*.cmake'))):
    for name in re.findall(r'set_tests_properties\(\[=\[(.*?)\]=\]', open(path).read()):
        listed.append((name, os.path.basename(path)))


def names(*args):
    out = subprocess.run(['ctest', '-N', *args], cwd=build, capture_output=True, text=True, check=True).stdout
    return set(re.findall(r'^\s*Test\s+#\d+: (\S+)', out, re.M))


known = names()
timing = names('-L', '^timing$')
threaded = names('-L', '^threaded$')
failures = [f'{name} (labelled in {f}) is not a test ctest knows: renamed or removed? Fix tests/CMakeLists.txt'
            for name, f in listed if name not in known]
if not timing:
    failures.append('no test carries the label timing')
if not threaded:
    failures.append('no test carries the label threaded')
for f in failures:
    print('check_labels:', f)
print(f'check_labels: {len(listed)} names listed, {len(timing)} timing, {len(threaded)} threaded '
      f'({len(timing & threaded)} of them also timing, left out by sanitize.sh), {len(failures)} problems')
sys.exit(1 if failures else 0)
