#!/usr/bin/python3
"""surgsim-solve against CalculiX (ccx, Debian calculix-ccx), an independent FEM code with its own assembly and
solver, on one small tetrahedral bar: first with one material, then with two (the half away from the clamp in a
softer material, given to surgsim-solve as a --region and to CalculiX as a second *MATERIAL and *SOLID SECTION).
The bar is clamped at x = 0 and its end face at x = L is moved by an imposed displacement; both programs use linear
tetrahedra (P1, CalculiX's C3D4) on the same nodes and elements, so their displacements must agree to CalculiX's
printed digits, with two materials as with one.

Usage: solve_calculix_test.py SURGSIM_SOLVE_BINARY
A missing ccx fails the test with the package to install (scripts/setup.sh installs it): it is not optional."""
import os
import re
import shutil
import subprocess
import sys
import tempfile

L, W, H = 0.10, 0.02, 0.02  # bar, m
NX, NY, NZ = 10, 2, 2  # hexahedra along each axis, 6 tets each
STIFF = (6000.0, 0.45)  # Pa, Poisson: the base material (the liver's order of magnitude)
SOFT = (1500.0, 0.30)  # the region x > L/2: a quarter of the modulus, another Poisson ratio
END_U = (0.002, 0.0, -0.004)  # m, imposed on every node of the end face x = L
TOLERANCE = 1e-5  # largest node error / largest displacement; CalculiX prints 7 digits (1e-7 relative)


def fail(message):
    print('FAIL: ' + message)
    sys.exit(1)


def bar_mesh():
    """Nodes (x, y, z) and positively oriented tets (0-based) of a structured bar, each hexahedron cut into 6 tets
    around its main diagonal (a conforming split)."""
    def index(i, j, k):
        return (k * (NY + 1) + j) * (NX + 1) + i

    nodes = [(L * i / NX, W * j / NY, H * k / NZ) for k in range(NZ + 1) for j in range(NY + 1) for i in range(NX + 1)]
    tets = []
    for k in range(NZ):
        for j in range(NY):
            for i in range(NX):
                c = [index(i + (a & 1), j + ((a >> 1) & 1), k + ((a >> 2) & 1)) for a in range(8)]
                # Corners 0 and 7 are the diagonal; each tet walks one path of unit steps from corner 0 to corner 7.
                for p in ((1, 3), (1, 5), (2, 3), (2, 6), (4, 5), (4, 6)):
                    t = [c[0], c[p[0]], c[p[1]], c[7]]
                    if signed_volume(nodes, t) < 0:
                        t[2], t[3] = t[3], t[2]
                    tets.append(t)
    return nodes, tets


def signed_volume(nodes, t):
    a, b, c, d = (nodes[n] for n in t)
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    w = [d[i] - a[i] for i in range(3)]
    return (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
            u[2] * (v[0] * w[1] - v[1] * w[0])) / 6


def centroid_x(nodes, t):
    return sum(nodes[n][0] for n in t) / 4


def write_vtk(path, nodes, tets):
    with open(path, 'w') as f:
        f.write('# vtk DataFile Version 3.0\nbar\nASCII\nDATASET UNSTRUCTURED_GRID\n')
        f.write(f'POINTS {len(nodes)} double\n')
        for x in nodes:
            f.write('%.17g %.17g %.17g\n' % x)
        f.write(f'CELLS {len(tets)} {5 * len(tets)}\n')
        for t in tets:
            f.write('4 %d %d %d %d\n' % tuple(t))
        f.write(f'CELL_TYPES {len(tets)}\n' + '10\n' * len(tets))


def write_inp(path, nodes, tets, soft_tets, fixed, loaded, soft):
    """CalculiX input: C3D4 elements, one *SOLID SECTION per material, clamp and imposed end displacement as
    *BOUNDARY, a linear *STATIC step printing U of every node and RF of the loaded ones in the .dat file."""
    with open(path, 'w') as f:
        f.write('*HEADING\nsurgsim-solve reference bar\n*NODE, NSET=NALL\n')
        for n, x in enumerate(nodes):
            f.write('%d, %.17g, %.17g, %.17g\n' % ((n + 1,) + x))
        f.write('*ELEMENT, TYPE=C3D4, ELSET=EALL\n')
        for e, t in enumerate(tets):
            f.write('%d, %d, %d, %d, %d\n' % ((e + 1,) + tuple(n + 1 for n in t)))
        stiff_set = [e for e in range(len(tets)) if e not in soft_tets]
        for name, members in (('ESTIFF', stiff_set), ('ESOFT', sorted(soft_tets))):
            if not members:
                continue
            f.write(f'*ELSET, ELSET={name}\n')
            for k in range(0, len(members), 8):
                f.write(', '.join(str(e + 1) for e in members[k:k + 8]) + '\n')
        f.write('*NSET, NSET=NLOAD\n')
        for k in range(0, len(loaded), 8):
            f.write(', '.join(str(n + 1) for n in loaded[k:k + 8]) + '\n')
        materials = [('STIFF', 'ESTIFF', STIFF)] + ([('SOFT', 'ESOFT', soft)] if soft_tets else [])
        for name, elset, (e, nu) in materials:
            f.write(f'*MATERIAL, NAME={name}\n*ELASTIC\n{e!r}, {nu!r}\n')
            f.write(f'*SOLID SECTION, ELSET={elset}, MATERIAL={name}\n')
        f.write('*BOUNDARY\n')
        for n in fixed:
            f.write(f'{n + 1}, 1, 3\n')
        f.write('*STEP\n*STATIC\n*BOUNDARY\n')
        for n in loaded:
            for dof in range(3):
                f.write(f'{n + 1}, {dof + 1}, {dof + 1}, {END_U[dof]!r}\n')
        f.write('*NODE PRINT, NSET=NALL\nU\n*NODE PRINT, NSET=NLOAD, TOTALS=ONLY\nRF\n*END STEP\n')


def read_dat(path, count):
    """Displacements of nodes 1..count and the loaded set's total reaction from CalculiX's .dat file."""
    u = [None] * count
    total = None
    section = None
    number = r'([-+]?\d\.\d+E[-+]\d+)'
    for line in open(path):
        if line.strip().startswith('displacements'):
            section = 'u'
        elif line.strip().startswith('total force'):
            section = 'rf'
        elif section == 'u':
            m = re.match(r'\s*(\d+)\s+' + r'\s+'.join([number] * 3) + r'\s*$', line)
            if m:
                u[int(m.group(1)) - 1] = tuple(float(m.group(i)) for i in (2, 3, 4))
        elif section == 'rf':
            m = re.match(r'\s*' + r'\s+'.join([number] * 3) + r'\s*$', line)
            if m:
                total = tuple(float(m.group(i)) for i in (1, 2, 3))
                section = None
    if any(v is None for v in u):
        fail(f'{path}: CalculiX printed no displacement for {sum(v is None for v in u)} of {count} nodes')
    if total is None:
        fail(f'{path}: CalculiX printed no total reaction of the loaded nodes')
    return u, total


def read_csv(path):
    rows = [line.strip().split(',') for line in open(path)][1:]
    return {int(r[0]): tuple(float(v) for v in r[1:]) for r in rows}


def run_case(tmp, ccx, solve, name, soft):
    nodes, tets = bar_mesh()
    soft_tets = {e for e, t in enumerate(tets) if centroid_x(nodes, t) > L / 2} if soft else set()
    fixed = [n for n, x in enumerate(nodes) if x[0] == 0.0]
    loaded = [n for n, x in enumerate(nodes) if abs(x[0] - L) < 1e-12]
    folder = os.path.join(tmp, name)
    os.makedirs(folder)
    mesh = os.path.join(folder, 'bar.vtk')
    write_vtk(mesh, nodes, tets)
    write_inp(os.path.join(folder, 'bar.inp'), nodes, tets, soft_tets, fixed, loaded, soft)
    p = subprocess.run([ccx, '-i', 'bar'], cwd=folder, capture_output=True, text=True)
    if p.returncode != 0 or 'Job finished' not in p.stdout:
        fail(f'ccx failed on {folder}/bar.inp (exit {p.returncode}):\n{p.stdout[-3000:]}\n{p.stderr[-2000:]}')
    ref, ref_total = read_dat(os.path.join(folder, 'bar.dat'), len(nodes))

    results = {}
    for method in ('direct', 'tensor'):  # the reference solve, and the precomputed tensors the nodes use
        out = os.path.join(folder, method)
        args = [solve, '--mesh', mesh, '--young', repr(STIFF[0]), '--poisson', repr(STIFF[1]),
                '--fixed', ','.join(map(str, fixed)), '--method', method, '--out', out]
        if soft:
            # By tet centroid, as the test picked CalculiX's ESOFT: every tet of the hexahedra beyond x = L/2.
            args += ['--region', f'soft:{soft[0]!r},{soft[1]!r}:box:{L / 2},-1,-1,1,1,1']
        for n in loaded:
            args += ['--impose', f'{n}:' + ','.join(map(repr, END_U))]
        p = subprocess.run(args, capture_output=True, text=True)
        if p.returncode != 0:
            fail(f'surgsim-solve failed (exit {p.returncode}): {" ".join(args)}\n{p.stdout}\n{p.stderr}')
        if soft and f'{len(soft_tets)} tets soft' not in p.stdout:
            fail(f'surgsim-solve did not put the {len(soft_tets)} tets of x > L/2 in the region:\n{p.stdout}')
        u = read_csv(os.path.join(out, 'displacement.csv'))
        reaction = read_csv(os.path.join(out, 'reaction.csv'))

        scale = max(max(abs(c) for c in v) for v in ref)
        error = max(max(abs(a - b) for a, b in zip(u[n], ref[n])) for n in range(len(nodes))) / scale
        total = tuple(sum(reaction[n][c] for n in loaded) for c in range(3))
        force_scale = max(abs(c) for c in ref_total)
        force_error = max(abs(a - b) for a, b in zip(total, ref_total)) / force_scale
        print(f'{name}, --method {method}: {len(nodes)} nodes, {len(tets)} tets ({len(soft_tets)} soft), max |u| '
              f'{scale:.6g} m: largest node difference / max |u| = {error:.3e}; end-face reaction surgsim-solve '
              f'({total[0]:.7g}, {total[1]:.7g}, {total[2]:.7g}) N, CalculiX ({ref_total[0]:.7g}, '
              f'{ref_total[1]:.7g}, {ref_total[2]:.7g}) N, difference / |max| = {force_error:.3e}')
        results[method] = (u, error, force_error)
    return results


def main():
    if len(sys.argv) != 2:
        fail('usage: solve_calculix_test.py SURGSIM_SOLVE_BINARY')
    solve = sys.argv[1]
    ccx = shutil.which('ccx')
    if ccx is None:
        fail('ccx (CalculiX) is not installed: it is the independent reference of this test; install the Debian '
             'package calculix-ccx (scripts/setup.sh does: apt-get install calculix-ccx)')
    if not os.access(solve, os.X_OK):
        fail(f'{solve} is not an executable: build surgsim-solve first')
    with tempfile.TemporaryDirectory() as tmp:
        one = run_case(tmp, ccx, solve, 'one material', None)
        two = run_case(tmp, ccx, solve, 'two materials', SOFT)
    failures = []
    for name, results in (('one material', one), ('two materials', two)):
        for method, (_, e, fe) in results.items():
            if not e < TOLERANCE:
                failures.append(f'{name}, --method {method}: displacements differ from CalculiX by {e:.3e} of the '
                                f'largest (> {TOLERANCE})')
            if not fe < TOLERANCE:
                failures.append(f'{name}, --method {method}: the end-face reaction differs from CalculiX by {fe:.3e} '
                                f'(> {TOLERANCE})')
    one, two = one['direct'][0], two['direct'][0]
    # The comparison must tell the materials apart: the soft half changes the field by far more than the tolerance.
    scale = max(max(abs(c) for c in v) for v in one.values())
    change = max(max(abs(a - b) for a, b in zip(one[n], two[n])) for n in one) / scale
    print(f'the soft half changes the displacements by {change:.3e} of the largest')
    if not change > 1000 * TOLERANCE:
        failures.append(f'the soft region changed the displacements by only {change:.3e}: the test cannot tell')
    if failures:
        fail('\n'.join(failures))
    print('ok')


main()
