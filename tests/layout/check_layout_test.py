#!/usr/bin/python3
"""The layout check must fail on a planted wrong include or namespace: copies common/ (and the script) to a temporary tree, plants
one violation at a time, and expects check_layout.py to exit 1 naming the file and line; the untouched copy must pass.
Usage: check_layout_test.py SOURCE_ROOT"""
import os
import shutil
import subprocess
import sys
import tempfile

src = os.path.abspath(sys.argv[1])
script = os.path.join(src, 'scripts', 'check_layout.py')
failures = []


def run(root):
    p = subprocess.run([sys.executable, script, root], capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def case(name, path, line, expect):
    with tempfile.TemporaryDirectory() as tmp:
        shutil.copytree(os.path.join(src, 'common'), os.path.join(tmp, 'common'))
        if path is not None:
            full = os.path.join(tmp, 'common', path)
            os.makedirs(os.path.dirname(full), exist_ok=True)
            old = open(full).read() if os.path.exists(full) else ''
            with open(full, 'w') as f:
                f.write(line + '\n' + old)
        rc, out = run(tmp)
        want_rc = 0 if path is None or expect is None else 1
        if rc != want_rc or (expect and expect not in out):
            failures.append(f'{name}: exit {rc} (wanted {want_rc}), output:\n{out}')
        else:
            print(f'ok: {name}: {out.strip().splitlines()[0]}')


case('clean copy passes', None, '', 'keep to common/layers.txt')
case('liver includes scene', 'fem/fem.h', '#include "scene/scene.h"', 'common/fem/fem.h:1: includes "scene/scene.h"')
case('core includes mesh', 'core/stats.cpp', '#include "mesh/mesh.h"', 'core/ may use no other folder')
case('intestine includes liver', 'intestine/mass_spring.h', '#include "fem/fem.h"', 'intestine/mass_spring.h:1')
case('mesh includes DDS', 'mesh/mesh.cpp', '#include <fastdds/dds/core/Entity.hpp>', 'common/ has no DDS or GL')
case('bare include', 'tool/tool.cpp', '#include "scene.h"', 'without its folder')
case('unlisted folder', 'physics/x.h', '#pragma once', 'does not list')
# The namespace rules: one folder, one namespace; no name of a higher folder's namespace.
case('fem names contact', 'fem/fem.cpp', 'int f() { return contact::kNoSuchThing; }',
     'common/fem/fem.cpp:1: names namespace contact::')
case('mesh names surgsim::scene', 'mesh/mesh.cpp', 'void g(const surgsim::scene::Scene& s);',
     'mesh/ may use only core')
case('core uses namespace mesh', 'core/stats.cpp', 'using namespace surgsim::mesh;', 'common/core/stats.cpp:1:')
case('fem declares contact', 'fem/fem.h', 'namespace surgsim::contact { struct X; }',
     'declares namespace surgsim::contact, but fem/ may not use contact/')
case('tool code in surgsim', 'tool/tool.cpp', 'namespace surgsim { int h(); }', 'goes in namespace surgsim::tool')
case('a comment may name anything', 'fem/fem.h', '// see contact::ToolContacts and "scene::load"', None)
if failures:
    print('\n'.join(failures))
    sys.exit(1)
