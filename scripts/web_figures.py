#!/usr/bin/python3
"""The web view's live figures, one run of three conditions back to back on the same machine, each with the
haptic node at 1 kHz replaying config/trajectories/liver_press_slide.csv (held at its end) for --seconds:
  nodes        haptic node + visual node (no frame stream, no surgsim-web): the reference
  web          + the visual node streaming JPEG frames at --fps and surgsim-web (no page open)
  web+browser  + a headless chromium showing the page (decoding every frame, plotting, reporting each frame shown)
It writes OUT/web_live.csv (the haptic node's missed deadlines, ticks, tick p99, the visual node's frame rate and the
stream's counters per condition) and OUT/web_delay.csv (render -> surgsim-web and render -> page shown, p50/p99/max,
from the web+browser condition). Run it under the build lock: scripts/web_figures.sh does, with rt_bench's floor
just before and frame_bench.

Usage: web_figures.py OUT [--seconds S] [--fps F] [--build DIR]"""
import argparse
import csv
import os
import sys
import time

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(root, 'tests', 'integration'))
from web_support import Run, browser, page_state, wait_for  # noqa: E402  (the browser tests' process helpers)


def run_condition(name, args, out):
    cond_out = os.path.join(out, 'live_' + name.replace('+', '_'))
    trajectory = os.path.join(root, 'config', 'trajectories', 'liver_press_slide.csv')
    web = name != 'nodes'
    run = Run(os.path.join(args.build, 'bin'), cond_out, os.path.join(root, 'config'),
              os.path.join(args.build, 'cache'), trajectory=trajectory, stream_fps=args.fps if web else 0,
              salt=len(name), start_haptic=False)
    run.haptic_args = ['--rate', '1000', '--duration', str(args.seconds)]
    d = None
    with run:
        if not web:
            run.stop('web')  # the reference has no bridge at all
        if name == 'web+browser':
            d = browser(cond_out, 'figures')
            d.get(run.url)
            wait_for('frames on the page', lambda: (page_state(d) or {}).get('lastFrame', 0) > 0, 30)
        else:
            time.sleep(2.0)
        run.start_haptic()
        rc = run.procs['haptic'].wait(args.seconds + 60)
        if d is not None:
            shown = page_state(d)['frames']
            d.quit()
        else:
            shown = 0
        if rc != 0:
            raise SystemExit(f'web_figures: haptic_node failed in condition {name} (see {cond_out}/haptic.log)')
    h = run.json('haptic.json')
    v = run.json('visual.json')
    if not (v.get('scene_confirmed') and v.get('tensor_hash_ok')):
        raise SystemExit(f'web_figures: the visual node did not draw the haptic node\'s frames in condition {name} '
                         f'(scene or tensors differ: rebuild haptic_node and visual_node together; {cond_out}/visual.log)')
    s = v.get('stream', {})
    w = run.json('web.json') if web else {}
    row = {
        'condition': name,
        'ticks': h['ticks'],
        'deadline_misses': h['deadline_misses'],
        'miss_pct': 100.0 * h['deadline_misses'] / max(1, h['ticks']),
        'tick_p99_us': h['tick_us']['p99'],
        'visual_fps': v['fps'],
        'stream_sent': s.get('sent', 0),
        'stream_dropped_busy': s.get('dropped_busy', 0),
        'encode_p50_us': s.get('encode_us', {}).get('p50', 0),
        'encode_p99_us': s.get('encode_us', {}).get('p99', 0),
        'frames_shown_in_page': shown,
    }
    return row, w


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('out')
    ap.add_argument('--seconds', type=float, default=20)
    ap.add_argument('--fps', type=float, default=20)
    ap.add_argument('--build', default=os.path.join(root, 'build'))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rows = []
    delay = None
    for name in ('nodes', 'web', 'web+browser'):
        row, w = run_condition(name, args, args.out)
        rows.append(row)
        if name == 'web+browser':
            delay = w
        print(f'web_figures: {name:12s} {row["deadline_misses"]} missed of {row["ticks"]} ticks '
              f'({row["miss_pct"]:.3f} %), tick p99 {row["tick_p99_us"]:.0f} us, visual {row["visual_fps"]:.1f} fps, '
              f'stream sent {row["stream_sent"]} dropped {row["stream_dropped_busy"]}', flush=True)
    with open(os.path.join(args.out, 'web_live.csv'), 'w', newline='') as f:
        wr = csv.DictWriter(f, fieldnames=list(rows[0]))
        wr.writeheader()
        wr.writerows(rows)
    with open(os.path.join(args.out, 'web_delay.csv'), 'w', newline='') as f:
        wr = csv.writer(f)
        wr.writerow(['path', 'count', 'p50_ms', 'p99_ms', 'max_ms'])
        for key, label in (('render_to_server_us', 'render -> surgsim-web (DDS)'),
                           ('render_to_page_us', 'render -> shown in the page (echoed back)')):
            p = delay[key]
            wr.writerow([label, p['count'], p['p50'] / 1e3, p['p99'] / 1e3, p['max'] / 1e3])
            print(f'web_figures: {label}: p50 {p["p50"] / 1e3:.1f} ms, p99 {p["p99"] / 1e3:.1f} ms '
                  f'({p["count"]} frames)')


if __name__ == '__main__':
    main()
