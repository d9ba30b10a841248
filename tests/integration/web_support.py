"""What the web view's tests share: the three real processes on a private DDS domain, surgsim-web's URL and
/stats, a headless Debian chromium through selenium, and waiting for a condition with a timeout (never a speed
assertion). Usage from a test: `with Run(bin_dir, out_dir, ...) as run: ...`."""
import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import time
import urllib.error
import urllib.request

TOKEN = 'webtest0123456789'


def wait_for(what, condition, timeout, poll=0.05):
    """Polls `condition()` until it returns a true value (returned) or `timeout` seconds pass (AssertionError)."""
    end = time.monotonic() + timeout
    last = None
    while time.monotonic() < end:
        last = condition()
        if last:
            return last
        time.sleep(poll)
    raise AssertionError(f'timed out after {timeout} s waiting for {what} (last: {last!r})')


DOMAIN_DIR = '/tmp/surgsim-test-domains'
DOMAIN_COUNT = 200
_domains = {}  # salt -> (domain, descriptor holding its lock): kept open until this process exits


def private_domain(salt=0):
    """A DDS domain of 1..200 reserved for this process across the machine (tests/support/test_domain.h takes the
    same locks for the C++ tests): an exclusive flock on DOMAIN_DIR/<d>.lock, held until the process exits. The
    search starts at 1 + (pid * 7 + salt) % 200 and takes the next free domain; the same salt gets the same domain
    again, another salt another domain. Pass reserved_fds() to the programs started on it (Popen's pass_fds), so that
    the domain stays taken while they run. AssertionError when all 200 are taken."""
    if salt in _domains:
        return _domains[salt][0]
    try:
        os.mkdir(DOMAIN_DIR, 0o1777)
        os.chmod(DOMAIN_DIR, 0o1777)  # mkdir's mode went through the umask
    except FileExistsError:
        pass
    start = (os.getpid() * 7 + salt) % DOMAIN_COUNT
    for i in range(DOMAIN_COUNT):
        d = 1 + (start + i) % DOMAIN_COUNT
        path = f'{DOMAIN_DIR}/{d}.lock'
        try:  # read-only, created only when missing: another user's lock file can still be opened
            fd = os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            fd = os.open(path, os.O_RDONLY | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        _domains[salt] = (d, fd)
        return d
    raise AssertionError(f'no free DDS test domain: all {DOMAIN_COUNT} (1..{DOMAIN_COUNT}) are held by other '
                         f'processes (locks in {DOMAIN_DIR}/<domain>.lock)')


def reserved_fds():
    """The descriptors holding this process's domains (for Popen's pass_fds)."""
    return tuple(fd for _, fd in _domains.values())


class Run:
    """The haptic node (replaying `trajectory`, or live from the device topic when None), the visual node streaming
    frames, and surgsim-web, on a private domain. Logs and stats in out_dir."""

    def __init__(self, bin_dir, out_dir, config_dir, cache_dir, trajectory=None, haptic_duration=60,
                 stream_fps=20, salt=0, start_haptic=True, scene='liver'):
        self.bin = bin_dir
        self.out = out_dir
        shutil.rmtree(out_dir, ignore_errors=True)
        os.makedirs(out_dir)
        self.env = dict(os.environ, SURGSIM_DOMAIN=str(private_domain(salt)), SURGSIM_CONFIG_DIR=config_dir,
                        SURGSIM_CACHE_DIR=cache_dir)
        self.trajectory = trajectory
        self.scene = scene
        self.haptic_duration = haptic_duration
        self.stream_fps = stream_fps
        self.start_haptic_now = start_haptic
        self.procs = {}
        self.haptic_args = []            # extra haptic_node flags (e.g. --rate 1000)
        self.url = None
        self.port = None

    def _start(self, name, args):
        log = open(os.path.join(self.out, name + '.log'), 'w')
        self.procs[name] = subprocess.Popen(args, env=self.env, stdout=subprocess.PIPE if name == 'web' else log,
                                            stderr=log, text=True, pass_fds=reserved_fds())
        return self.procs[name]

    def __enter__(self):
        self._start('visual', [f'{self.bin}/visual_node', '--scene', self.scene, '--out', f'{self.out}/frames',
                               '--png-every', '0', '--stream-fps', str(self.stream_fps), '--stats',
                               f'{self.out}/visual.json'])
        web = self._start('web', [f'{self.bin}/surgsim-web', '--scene', self.scene, '--port', '0', '--token', TOKEN,
                                  '--stats', f'{self.out}/web.json'])
        line = web.stdout.readline()
        m = re.search(r'(http://\S+)', line)
        assert m, f'surgsim-web printed no URL: {line!r} (see {self.out}/web.log)'
        self.url = m.group(1)
        self.port = int(re.search(r':(\d+)/', self.url).group(1))
        if self.start_haptic_now:
            self.start_haptic()
        return self

    def start_haptic(self):
        args = [f'{self.bin}/haptic_node', '--scene', self.scene, '--stats', f'{self.out}/haptic.json',
                '--wait-for-visual', '20']
        if self.trajectory:
            args += ['--replay', self.trajectory]
        else:
            args += ['--input', 'device', '--duration', str(self.haptic_duration), '--input-timeout', '0.1']
        self._start('haptic', args + self.haptic_args)

    def stop(self, name, timeout=15):
        p = self.procs.get(name)
        if p is None or p.poll() is not None:
            return p.returncode if p else None
        p.send_signal(signal.SIGINT)
        try:
            return p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            raise AssertionError(f'{name} did not stop within {timeout} s of SIGINT')

    def __exit__(self, *exc):
        for name in ('haptic', 'visual', 'web'):
            try:
                self.stop(name)
            except AssertionError:
                if exc[0] is None:
                    raise
        return False

    def stats(self):
        """surgsim-web's /stats."""
        with urllib.request.urlopen(f'http://127.0.0.1:{self.port}/stats?token={TOKEN}', timeout=5) as r:
            return json.loads(r.read())

    def json(self, name):
        with open(os.path.join(self.out, name)) as f:
            return json.load(f)


def browser(out_dir, name):
    """A headless Debian chromium driven by chromedriver (python3-selenium)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    opts = webdriver.ChromeOptions()
    opts.binary_location = '/usr/bin/chromium'
    for a in ('--headless=new', '--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage', '--window-size=930,900',
              f'--user-data-dir={out_dir}/chromium-{name}', '--disable-background-timer-throttling',
              '--disable-renderer-backgrounding', '--disable-backgrounding-occluded-windows'):
        opts.add_argument(a)
    service = Service('/usr/bin/chromedriver', log_path=os.path.join(out_dir, f'chromedriver-{name}.log'))
    return webdriver.Chrome(service=service, options=opts)


def page_state(driver):
    return driver.execute_script('return window.surgsim ? JSON.parse(JSON.stringify(window.surgsim)) : null;')
