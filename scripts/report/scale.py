#!/usr/bin/python3
"""The report's section on patient-size livers, from the CSV files the benchmarks write with --out OUT:

    build/bench/liver_bench --sizes 1500,5000,20000 --no-cg --skip-table --out OUT   -> liver_precompute.csv
    build/bench/node_bench --sizes 1500,5000,20000 --out OUT                        -> node_memory.csv, node_tick.csv,
                                                                                       node_deform.csv, node_render.csv
    build/bench/liver_error_bench --out OUT (optional)                              -> the float column's error

markdown(OUT) returns its Markdown lines (write(rep) puts them in the report, under its number); run as a program
it prints them under the title. Budgets: precompute <= 0.5 s at ~1.4k nodes, <= 5 s at ~5k, <= 60 s at
~21k; peak resident memory <= 2 GB (2000 MB) at ~21k in the precompute and in each node; haptic tick p99 <= 100 us
with 10 contacts at ~21k; visual >= 50 fps at 640x480 at ~21k; float storage within 1e-6 relative. A missing file is
named, never invented.

Usage: /usr/bin/python3 scripts/report/scale.py OUT"""
import csv
import os
import sys

if __name__ == '__main__' and not __package__:
    # Run as a file: import the package from scripts/ (this folder's modules are not top-level modules).
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
from report.web import _table, _verdict  # noqa: E402  (the same Markdown helpers)

TITLE = 'Patient-size livers'

MIB_PER_GB = 1e9 / (1024.0 * 1024.0)   # the budget's 2 GB in MiB (1907.3)
PRECOMPUTE_BUDGET_S = [(2000, 0.5), (8000, 5.0), (10 ** 9, 60.0)]  # (up to this many nodes, seconds)


def _rows(out_dir, name):
    path = os.path.join(out_dir, name + '.csv')
    if not os.path.exists(path):
        return None
    with open(path, newline='') as f:
        return list(csv.DictReader(f))


def _precompute_budget(nodes):
    for limit, seconds in PRECOMPUTE_BUDGET_S:
        if nodes <= limit:
            return seconds
    return PRECOMPUTE_BUDGET_S[-1][1]


def _missing(what, command):
    return [f'*{what}: missing (run `{command}`).*', '']


def markdown(out_dir):
    """Markdown lines of the patient-size figures found in out_dir (no heading)."""
    md = ['The haptic block is stored as one packed half of the symmetric contacts x contacts matrix, the visual block '
          'keeps the boundary nodes that can move, both in float once double would pass 1 GiB; the precompute solves '
          'the unit right-hand sides in the factor\'s order on every core (CholmodSolver::solve_unit_columns).', '']
    pre = _rows(out_dir, 'liver_precompute')
    if pre:
        md += ['Precompute (`liver_bench`, forked child per size; peak = its ru_maxrss).', '']
        rows = []
        for r in pre:
            n = int(r['nodes'])
            budget = _precompute_budget(n)
            peak = float(r['direct_peak_mib'])
            ok = float(r['direct_s']) <= budget and (n < 15000 or peak <= 2 * MIB_PER_GB)
            rows.append([n, r['contactable'], r.get('precision', '?'), r.get('threads', '?'),
                         f"{float(r['direct_s']):.2f}", f'{budget:g}', f'{peak:.0f}',
                         f"{float(r['tensor_mib']):.0f}", _verdict(ok)])
        md += _table(['nodes', 'contactable', 'stored as', 'threads', 'precompute (s)', 'budget (s)', 'peak (MiB)',
                      'tensors (MiB)', 'verdict'], rows)
    else:
        md += _missing('precompute table', 'liver_bench --sizes 1500,5000,20000 --no-cg --skip-table --out OUT')

    mem = _rows(out_dir, 'node_memory')
    if mem:
        md += ['Peak resident memory of each side (`node_bench`: first use = load or build of the cache in a child; '
               'haptic side = the "haptic" block only, as the haptic node loads it; visual side = the "visual" block '
               f'only). Budget at ~21k nodes: 2 GB = {2 * MIB_PER_GB:.0f} MiB.', '']
        rows = []
        for r in mem:
            n = int(r['nodes'])
            peaks = [float(r['first_use_peak_mib']), float(r['haptic_peak_mib']), float(r['visual_peak_mib'])]
            ok = n < 15000 or max(peaks) <= 2 * MIB_PER_GB
            first = ('precompute ' if r['first_use_rebuilt'] == '1' else 'load ') + f"{float(r['first_use_s']):.1f} s"
            rows.append([n, r['precision'], first, f'{peaks[0]:.0f}', f'{peaks[1]:.0f}',
                         f"{float(r['haptic_tensor_mib']):.0f}", f'{peaks[2]:.0f}', f"{float(r['visual_tensor_mib']):.0f}",
                         _verdict(ok)])
        md += _table(['nodes', 'stored as', 'first use', 'first use peak (MiB)', 'haptic peak (MiB)',
                      'haptic tensors (MiB)', 'visual peak (MiB)', 'visual tensors (MiB)', 'verdict'], rows)
    else:
        md += _missing('node memory', 'node_bench --sizes 1500,5000,20000 --out OUT')

    tick = _rows(out_dir, 'node_tick')
    if tick:
        rows = [[r['nodes'], r['contacts'], r['tick_us_p50'], r['tick_us_p99'], r['tick_us_max'],
                 _verdict(float(r['tick_us_p99']) <= 100.0)] for r in tick if r['contacts'] == '10']
        md += ['Haptic tick with 10 contacts (`node_bench`: collision on the deformed surface + G_CC solve + force), '
               'us; budget p99 <= 100 us.', '']
        md += _table(['nodes', 'contacts', 'p50', 'p99', 'max', 'verdict'], rows)
    deform = _rows(out_dir, 'node_deform')
    if deform:
        rows = [[r.get('nodes', '?'), r['visible_nodes'], r['deform_us_p50'], r['deform_us_p99'], r['deform_us_max']]
                for r in deform]
        md += ['Visual deformation of every visible node, 10 contacts (`node_bench`), us.', '']
        md += _table(['nodes', 'visible', 'p50', 'p99', 'max'], rows)
    render = _rows(out_dir, 'node_render')
    if render:
        rows = []
        for r in render:
            if (r['width'], r['height']) != ('640', '480'):
                continue
            fps = 1000.0 / float(r['frame_ms_p99'])
            rows.append([r['visible_nodes'], r['frame_ms_p50'], r['frame_ms_p99'], f'{fps:.0f}', _verdict(fps >= 50.0)])
        md += ['Render at 640x480 (`node_bench`, OSMesa llvmpipe), ms per frame; budget >= 50 fps (at p99).', '']
        md += _table(['visible nodes', 'p50 (ms)', 'p99 (ms)', 'fps at p99', 'verdict'], rows)

    err = _rows(out_dir, 'liver_error_time')
    if err:
        rows = [[r['family'], r['variant'], r['disp_rel_error'], r['force_rel_error'], r['memory_mib'],
                 _verdict(float(r['disp_rel_error']) <= 1e-6 and float(r['force_rel_error']) <= 1e-6)]
                for r in err if 'float' in r['family'] or 'float' in r['variant']]
        if rows:
            md += ['Float storage against the reference solve (`liver_error_bench`, liver_error_time.csv); bound 1e-6 '
                   'relative.', '']
            md += _table(['family', 'variant', 'displacement rel. error', 'force rel. error', 'MiB', 'verdict'], rows)
    return md


def write(rep):
    """The section in the report, from the benches' CSV files in raw/scale/."""
    for line in markdown(os.path.join(rep.root, 'raw', 'scale')):
        rep.md(line)
    rep.md()


def main(argv):
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    print('\n'.join(['## ' + TITLE, ''] + markdown(argv[1])))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
