#!/usr/bin/python3
"""The report's section on the web view, from the CSV files scripts/web_figures.sh writes into OUT:
frame_encode.csv, frame_render_loop.csv (frame_bench), rt_floor.csv (rt_bench), web_live.csv and web_delay.csv
(web_figures.py). markdown(OUT) returns its Markdown lines (write(rep) puts them in the report, under its number);
run as a program it prints them under the title.

Budgets (docs/DESIGN.md, section 'Budgets', where it has one): the haptic node's 1 kHz missed deadlines within 0.1
percentage points of the machine's floor (rt_bench just before); the visual frame rate unchanged by the stream
(>= 99 % of the rate without it); every JPEG within the topic's bound (512 KiB, else it is dropped); the encoder
keeps up (encode p99 below the stream period); the render loop's share of a streamed frame (read-back + hand-off,
p99) within 10 % of a 50 Hz frame (2 ms). The render -> page delay has no budget (shown beside the stream period).

Usage: /usr/bin/python3 scripts/report/web.py OUT"""
import csv
import os
import sys

TITLE = 'The web view'
BOUND_KIB = 512.0
FRAME_MS_50HZ = 20.0


def _rows(path):
    if not os.path.exists(path):
        return None
    with open(path, newline='') as f:
        return list(csv.DictReader(f))


def _f(x, digits=1):
    return f'{float(x):.{digits}f}'


def _verdict(ok):
    return 'within' if ok else '**over**'


def _table(headers, rows):
    out = ['| ' + ' | '.join(headers) + ' |', '|' + '---|' * len(headers)]
    out += ['| ' + ' | '.join(str(c) for c in r) + ' |' for r in rows]
    return out + ['']


def markdown(out_dir, stream_fps=20.0):
    """Markdown lines of the web view's figures in out_dir, no heading (missing files are named, not fatal)."""
    md = []
    prov = os.path.join(out_dir, 'provenance.txt')
    if os.path.exists(prov):
        md += ['`' + line.strip() + '`  ' for line in open(prov) if line.strip()] + ['']
    period_us = 1e6 / stream_fps

    enc = _rows(os.path.join(out_dir, 'frame_encode.csv'))
    if enc:
        md += ['JPEG encode per frame on the encoder thread (libturbojpeg, the shipped liver rendered with OSMesa; '
               f'`build/bench/frame_bench`): wall time, size, against the stream period ({period_us / 1e3:.0f} ms at '
               f'{stream_fps:.0f} Hz) and the topic bound ({BOUND_KIB:.0f} KiB).', '']
        rows = []
        for r in enc:
            ok = float(r['encode_p99_us']) < period_us and float(r['kib_max']) <= BOUND_KIB
            rows.append([f"{r['width']}x{r['height']}", r['quality'], _f(r['encode_p50_us'], 0),
                         _f(r['encode_p99_us'], 0), _f(r['kib_p50']), _f(r['kib_max']), _verdict(ok)])
        md += _table(['size', 'quality', 'encode p50 (us)', 'encode p99 (us)', 'KiB p50', 'KiB max', 'verdict'], rows)
    else:
        md += ['(frame_encode.csv missing: frame_bench did not run)', '']

    loop = _rows(os.path.join(out_dir, 'frame_render_loop.csv'))
    if loop:
        md += ['What the render loop pays per streamed frame: the read-back into the preallocated slot and the hand-off '
               'to the encoder thread (budget: p99 of both within 10 % of a 50 Hz frame, 2 ms).', '']
        rows = []
        for r in loop:
            p99 = float(r['readback_p99_us']) + float(r['handoff_p99_us'])
            rows.append([f"{r['width']}x{r['height']}", _f(r['render_p50_ms'], 2), _f(r['readback_p50_us'], 0),
                         _f(r['readback_p99_us'], 0), _f(r['handoff_p50_us']), _f(r['handoff_p99_us']),
                         _verdict(p99 <= 0.1 * FRAME_MS_50HZ * 1e3)])
        md += _table(['size', 'render p50 (ms)', 'read-back p50 (us)', 'read-back p99 (us)', 'hand-off p50 (us)',
                      'hand-off p99 (us)', 'verdict'], rows)

    live = _rows(os.path.join(out_dir, 'web_live.csv'))
    floor = _rows(os.path.join(out_dir, 'rt_floor.csv'))
    if live:
        floor_pct = None
        if floor:
            r = floor[-1]
            keys = {k.lower(): k for k in r}
            miss = next((r[keys[k]] for k in keys if 'miss' in k and 'pct' in k), None)
            if miss is None:
                m = next((r[keys[k]] for k in keys if k.startswith('missed') or k == 'misses'), None)
                t = next((r[keys[k]] for k in keys if k == 'ticks'), None)
                if m is not None and t:
                    miss = 100.0 * float(m) / float(t)
            floor_pct = float(miss) if miss is not None else None
        ref_fps = float(live[0]['visual_fps'])
        md += ['The haptic node at 1 kHz (liver_press_slide.csv), the same run of `scripts/web_figures.sh`, three '
               'conditions back to back: the two nodes alone; with the frame stream and surgsim-web; and with a '
               'headless chromium showing the page. Budget: missed deadlines within 0.1 percentage points of the '
               'floor (rt_bench just before' + (f': {floor_pct:.3f} %' if floor_pct is not None else ', missing') +
               '); visual frame rate >= 99 % of the first condition\'s.', '']
        rows = []
        ref_pct = float(live[0]['miss_pct'])
        for r in live:
            pct = float(r['miss_pct'])
            ok_miss = floor_pct is not None and pct <= floor_pct + 0.1
            ok_fps = float(r['visual_fps']) >= 0.99 * ref_fps
            rows.append([r['condition'], f"{r['deadline_misses']} / {r['ticks']}", _f(pct, 3),
                         f'{pct - ref_pct:+.3f}', _f(r['tick_p99_us'], 0), _f(r['visual_fps']), r['stream_sent'], r['stream_dropped_busy'],
                         r['frames_shown_in_page'], _verdict(ok_miss and ok_fps)])
        md += _table(['condition', 'missed / ticks', 'missed %', 'vs the nodes alone (pp)', 'tick p99 (us)', 'visual fps', 'frames streamed',
                      'dropped (encoder busy)', 'shown in the page', 'verdict'], rows)
    else:
        md += ['(web_live.csv missing: web_figures.py did not run)', '']

    delay = _rows(os.path.join(out_dir, 'web_delay.csv'))
    if delay:
        md += ['Delay from the end of the render to the picture (same host clock; the page reports each frame it drew '
               'and surgsim-web takes the time on arrival of that report, so the last figure includes the way back '
               'over the loopback WebSocket). No budget; the stream period is ' + f'{period_us / 1e3:.0f} ms.', '']
        md += _table(['path', 'frames', 'p50 (ms)', 'p99 (ms)', 'max (ms)'],
                     [[r['path'], r['count'], _f(r['p50_ms']), _f(r['p99_ms']), _f(r['max_ms'])] for r in delay])
    return md


def write(rep):
    """The section in the report, from scripts/web_figures.sh's files in raw/web/."""
    for line in markdown(os.path.join(rep.root, 'raw', 'web')):
        rep.md(line)
    rep.md()


if __name__ == '__main__':
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    print('\n'.join(['## ' + TITLE, ''] + markdown(sys.argv[1])))
