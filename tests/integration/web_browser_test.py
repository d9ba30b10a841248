#!/usr/bin/python3
"""The web view in a real browser: headless Debian chromium through selenium against the three real
processes (haptic node, visual node streaming JPEG frames, surgsim-web).

  watch: the page loads, frames arrive and change while the liver_poke trajectory plays, the scene's name and hashes
         and the contacts show.
  drive: the first page drives; a second page cannot take the tool (it watches and says so); a key held on the
         driving page moves the tool down until a contact appears in the haptic node's stats and the force plot shows
         it (screenshot saved); closing the driving page stops the commands and the haptic node's input timeout zeroes
         the force.

  field: the several-organs scene (abdomen) plays in the page, its organs listed.

Usage: web_browser_test.py watch|drive|field BIN_DIR CONFIG_DIR CACHE_DIR OUT_DIR [SCREENSHOT]"""
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from web_support import TOKEN, Run, browser, page_state, wait_for  # noqa: E402


def image_checksum(driver):
    """A checksum of the pixels the page shows (the view canvas the decoded JPEG is drawn on)."""
    return driver.execute_script('''
        const c = document.getElementById('view');
        if (!window.surgsim || !window.surgsim.lastFrame) return null;
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let h = 0; for (let i = 0; i < d.length; i += 7) h = (h * 31 + d[i]) >>> 0;
        return h;''')


def pictures_until_contact(driver, trajectory, timeout):
    """Waits until the page has shown 4 different pictures and a contact; returns the pictures' checksums."""
    seen = set()

    def changed():
        seen.add(image_checksum(driver))
        return len(seen) >= 4 and page_state(driver)['contactsMax'] > 0

    wait_for(f'the view to change (4 different pictures) and a contact while {trajectory} plays', changed, timeout,
             poll=0.1)
    return seen


def watch(bin_dir, config_dir, cache_dir, out):
    trajectory = os.path.join(config_dir, 'trajectories', 'liver_poke.csv')
    with Run(bin_dir, out, config_dir, cache_dir, trajectory=trajectory, salt=31, start_haptic=False) as run:
        d = browser(out, 'watch')
        try:
            d.get(run.url)
            wait_for('the page to connect', lambda: (page_state(d) or {}).get('connected'), 20)
            # Frames arrive before the haptic node starts (the visual node renders its rest state).
            wait_for('a first frame on the page', lambda: page_state(d)['lastFrame'] > 0, 30)
            first = image_checksum(d)
            run.start_haptic()
            # While the trajectory plays the tool moves: the picture changes, frame numbers grow, contacts show.
            seen = pictures_until_contact(d, 'liver_poke', 40)
            s = page_state(d)
            assert s['frames'] >= 4, s
            assert first in seen or len(seen) >= 4
            scene = d.find_element('id', 'scene').text
            assert 'liver' in scene and 'tensors' in scene, scene
            assert 'connected' in d.find_element('id', 'conn').text
            stats = run.stats()
            assert stats['frames_to_pages'] >= 4, stats
            assert stats['render_to_page_us']['count'] >= 1, stats
            print(f'watch: {s["frames"]} frames shown, {len(seen)} distinct pictures, contacts max '
                  f'{s["contactsMax"]}, render->page p50 {stats["render_to_page_us"]["p50"]:.0f} us')
        finally:
            d.quit()
        assert run.procs['haptic'].wait(30) == 0
    check_visual(run)


def field(bin_dir, config_dir, cache_dir, out):
    """Several organs (config/abdomen.yaml): the page shows the field while abdomen.csv plays (the probe on the liver,
    the grasper in the bowel's folds, then the probe along the wall), its organs listed with their models."""
    trajectory = os.path.join(config_dir, 'trajectories', 'abdomen.csv')
    with Run(bin_dir, out, config_dir, cache_dir, trajectory=trajectory, salt=41, scene='abdomen',
             start_haptic=False) as run:
        d = browser(out, 'field')
        try:
            d.get(run.url)
            wait_for('the page to connect', lambda: (page_state(d) or {}).get('connected'), 20)
            wait_for('a first frame on the page', lambda: page_state(d)['lastFrame'] > 0, 30)
            run.start_haptic()  # the probe presses the liver 0.3-2.4 s in: the page watches from the start
            seen = pictures_until_contact(d, 'abdomen.csv', 60)
            wait_for('the organs in the scene table', lambda: 'rigid' in d.find_element('id', 'scene').text, 20)
            scene = d.find_element('id', 'scene').text
            for organ in ('liver (liver)', 'bowel (intestine)', 'wall (rigid)', 'floor (rigid)', 'ribs (rigid)'):
                assert organ in scene, scene
            s = page_state(d)
            print(f'field: {s["frames"]} frames shown, {len(seen)} distinct pictures, contacts max {s["contactsMax"]}')
        finally:
            d.quit()
        assert run.procs['haptic'].wait(60) == 0
    v = run.json('visual.json')
    assert v['scene_confirmed'] and v['frames_shown'] > 0, {k: v.get(k) for k in ('scene_confirmed', 'frames_shown')}
    assert [o['name'] for o in v['organs']] == ['liver', 'bowel', 'wall', 'floor', 'ribs'], v['organs']


def check_visual(run):
    """The visual node drew the haptic node's contact frames (same scene and tensors), so the view showed them."""
    v = run.json('visual.json')
    assert v['scene_confirmed'] and v['tensor_hash_ok'] and v['frames_shown'] > 0, \
        {k: v.get(k) for k in ('scene_confirmed', 'scene_hash_ok', 'tensor_hash_ok', 'frames_shown')}
    assert v['stream']['sent'] > 0 and v['stream']['dropped_oversize'] == 0, v['stream']


def drive(bin_dir, config_dir, cache_dir, out, screenshot):
    from selenium.webdriver.common.action_chains import ActionChains
    with Run(bin_dir, out, config_dir, cache_dir, trajectory=None, haptic_duration=90, salt=37) as run:
        a = browser(out, 'driver')
        b = browser(out, 'watcher')
        try:
            a.get(run.url)
            wait_for('the first page to drive', lambda: (page_state(a) or {}).get('drives'), 20)
            wait_for('frames on the first page', lambda: page_state(a)['lastFrame'] > 0, 30)
            b.get(run.url)
            wait_for('the second page to connect and hear the driver',
                     lambda: (page_state(b) or {}).get('driver', 0) != 0, 20)
            # The second page asked for the tool on load and was refused; a click on "Take the tool" is refused too.
            b.find_element('id', 'take').click()
            wait_for('both refusals counted', lambda: run.stats()['refused']['drive_refused'] >= 2, 10)
            sb = page_state(b)
            assert not sb['drives'] and sb['driver'] == page_state(a)['id'], sb
            assert 'Another browser drives' in b.find_element('id', 'role').text
            assert page_state(a)['drives']

            # Hold E (insertion): the tool goes down until it touches the liver.
            start_insertion = run.stats()['command_pose'][2]
            body = a.find_element('tag name', 'body')
            ActionChains(a).move_to_element(body).key_down('e').perform()
            try:
                wait_for('a contact in the haptic node and a force on the page',
                         lambda: run.stats()['instrument_contacts'] > 0 and page_state(a)['forceNorm'] > 0.2, 40,
                         poll=0.1)
            finally:
                ActionChains(a).key_up('e').perform()
            st = run.stats()
            assert st['command_pose'][2] > start_insertion + 0.01, (start_insertion, st['command_pose'])
            assert st['commands_sent'] > 0 and st['refused']['ws_not_driver'] == 0, st
            # The force plot holds the force (its samples are what the canvas draws).
            plotted = a.execute_script('return Math.max(...window.surgsimPlots.force.v);')
            assert plotted > 0.2, plotted
            wait_for('the watcher to see the force too', lambda: page_state(b)['forceNorm'] > 0.2, 10)
            time.sleep(1.0)  # a second of force on the plots for the picture
            if screenshot:
                os.makedirs(os.path.dirname(os.path.abspath(screenshot)), exist_ok=True)
                a.save_screenshot(screenshot)
            a.save_screenshot(os.path.join(out, 'web_view.png'))
            force_before = run.stats()['force']
            print(f'drive: contact after holding E, force {force_before} N, plot max {plotted:.3f} N')

            # Close the driving page: the commands stop and the haptic node's input timeout zeroes the force.
            sent = run.stats()['commands_sent']
            t0 = time.monotonic()
            a.quit()
            a = None
            wait_for('the force zeroed and flagged input-lost after the driving page closed',
                     lambda: (lambda s: s['force'] == [0.0, 0.0, 0.0] and s['force_flags'] & 8)(run.stats()), 10)
            elapsed = time.monotonic() - t0
            after = run.stats()['commands_sent']
            time.sleep(0.3)
            assert run.stats()['commands_sent'] == after, 'commands still sent after the driving page closed'
            assert after - sent < 200, (sent, after)  # at most the last second's commands (200 Hz)
            wait_for('the watcher to see the zero force', lambda: page_state(b)['forceNorm'] == 0, 10)
            print(f'drive: force zero {elapsed:.2f} s after the page closed (input timeout 0.1 s, plus the '
                  f'WebSocket close and the /stats polling)')
        finally:
            if a is not None:
                a.quit()
            b.quit()
        assert run.stop('haptic') == 0
    h = run.json('haptic.json')
    assert h['contacts_max'] > 0, h['contacts_max']
    tool = h['tools'][0]
    assert tool['input_lost_ticks'] > 0, tool
    check_visual(run)
    w = run.json('web.json')
    assert w['ws_opened'] == 2 and w['refused']['drive_refused'] >= 2, w


def main():
    case, bin_dir, config_dir, cache_dir, out = sys.argv[1:6]
    screenshot = sys.argv[6] if len(sys.argv) > 6 else None
    if case == 'watch':
        watch(bin_dir, config_dir, cache_dir, out)
    elif case == 'drive':
        drive(bin_dir, config_dir, cache_dir, out, screenshot)
    elif case == 'field':
        field(bin_dir, config_dir, cache_dir, out)
    else:
        sys.exit(f'unknown case {case}: watch, drive or field')
    print(f'web_browser_test {case}: ok')


if __name__ == '__main__':
    main()
