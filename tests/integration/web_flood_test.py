#!/usr/bin/python3
"""surgsim-web keeps serving the token holder through a flood of connections without the token, under Debian's
default limit of 1024 open files (set on the server as `ulimit -n 1024` would):

1. 3000 tokenless connections, half of them never finishing their headers, the others asking for /stats without
   the token, all held open by the flood: the token holder's /stats is answered within 1 s each time it asks, while
   the flood connects and while it holds; the server counts the connections it closed to make room.
2. The server's limit lowered below its connection cap while it runs (as when DDS takes descriptors), and the same
   flood again: accept() runs out of descriptors, the server closes tokenless connections to make room (counted
   accept errors, a handful, never a spin) and the token holder is still answered within 1 s.
3. One request that never finishes is closed by the server's deadline, well before the 10 s of before.

The 1 s is the token holder's client timeout: a functional deadline (answered while the flood is open), not a speed
measurement. Only surgsim-web runs. The flood runs in several processes (each raises its own open-file limit), so
this test needs no more than Debian's default limits itself.

Usage: web_flood_test.py BIN_DIR CONFIG_DIR OUT_DIR"""
import json
import multiprocessing
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import time

from web_support import private_domain, reserved_fds, wait_for

TOKEN = 'floodtest0123456789'
SERVER_FILES = 1024          # the server's soft limit of open files (Debian's default)
FLOOD = 3000                 # tokenless connections per flood
WORKERS = 4                  # processes opening them
HOLDER_TIMEOUT = 1.0         # s: the token holder's client timeout
# Half the flood never finishes its headers; the other half asks without the token (403).
UNFINISHED = b'GET /stats HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: '
TOKENLESS = b'GET /stats HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n'


def server_limits():
    """In the server's child process before exec: `ulimit -n 1024` (the soft limit; the hard one as it was)."""
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (SERVER_FILES, hard))


def flood_worker(port, count, report, stop):
    """Opens `count` tokenless connections (even ones never finish their headers), reports how many it opened, holds
    them until `stop` is set, then closes them."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = count + 64
    if soft != resource.RLIM_INFINITY and soft < want:
        resource.setrlimit(resource.RLIMIT_NOFILE, (want if hard == resource.RLIM_INFINITY else min(want, hard), hard))
    socks = []
    opened = 0
    for i in range(count):
        try:
            s = socket.create_connection(('127.0.0.1', port), timeout=10)
            opened += 1
            socks.append(s)
            s.sendall(UNFINISHED if i % 2 == 0 else TOKENLESS)
        except OSError:
            pass  # the server closed it to make room before the request went out: it still counts as flood
    report.put(opened)
    stop.wait(60)
    for s in socks:
        s.close()


def holder_stats(port):
    """The token holder's /stats (parsed), or an AssertionError when the whole answer does not come within
    HOLDER_TIMEOUT seconds of asking (the connect, the request and the answer together)."""
    end = time.monotonic() + HOLDER_TIMEOUT
    data = b''
    try:
        with socket.create_connection(('127.0.0.1', port), timeout=HOLDER_TIMEOUT) as s:
            s.sendall(f'GET /stats?token={TOKEN} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n'.encode())
            while True:
                left = end - time.monotonic()
                if left <= 0:
                    raise socket.timeout()
                s.settimeout(left)
                chunk = s.recv(65536)
                if not chunk:
                    break
                data += chunk
    except (socket.timeout, OSError) as e:
        raise AssertionError(f'the token holder\'s /stats was not answered within {HOLDER_TIMEOUT} s during the '
                             f'flood ({type(e).__name__}: {e}; {len(data)} bytes received)') from None
    head, _, body = data.partition(b'\r\n\r\n')
    assert head.startswith(b'HTTP/1.1 200'), head[:80]
    return json.loads(body)


def flood(port, name):
    """One flood of FLOOD tokenless connections from WORKERS processes; the token holder asks for /stats while they
    connect and while they hold. Returns the holder's answers (the last one after the flood is fully open)."""
    ctx = multiprocessing.get_context('fork')
    report, stop = ctx.Queue(), ctx.Event()
    workers = [ctx.Process(target=flood_worker, args=(port, FLOOD // WORKERS, report, stop)) for _ in range(WORKERS)]
    for w in workers:
        w.start()
    answers = []
    opened = []
    try:
        # While the flood connects...
        while len(opened) < WORKERS:
            answers.append(holder_stats(port))
            try:
                opened.append(report.get(timeout=0.1))
            except Exception:  # queue.Empty
                pass
        # ...and while it holds every connection it opened.
        for _ in range(3):
            time.sleep(0.2)
            answers.append(holder_stats(port))
        assert all(w.is_alive() for w in workers), 'a flood process ended before the token holder was answered'
    finally:
        stop.set()
        for w in workers:
            w.join(30)
    print(f'web_flood_test: {name}: {sum(opened)} tokenless connections opened; the token holder answered '
          f'{len(answers)} times within {HOLDER_TIMEOUT} s, while they connected and while they were held')
    assert sum(opened) >= FLOOD * 9 // 10, opened  # a few may be closed by the server before their connect returns
    return answers


def settled(port, accepted):
    """The server's connection counters once it accepted at least `accepted` connections and only the token holder's
    is open (the flood seen to its end), else None."""
    c = holder_stats(port)['connections']
    return c if c['accepted'] >= accepted and c['open'] <= 1 else None


def main():
    bin_dir, config_dir, out = sys.argv[1:4]
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    env = dict(os.environ, SURGSIM_CONFIG_DIR=config_dir, SURGSIM_DOMAIN=str(private_domain(59)))
    log = open(os.path.join(out, 'web.log'), 'w')
    web = subprocess.Popen([f'{bin_dir}/surgsim-web', '--scene', 'liver', '--port', '0', '--token', TOKEN,
                            '--stats', f'{out}/web.json'],
                           env=env, stdout=subprocess.PIPE, stderr=log, text=True, preexec_fn=server_limits,
                           pass_fds=reserved_fds())
    try:
        port = int(re.search(r':(\d+)/', web.stdout.readline()).group(1))
        assert resource.prlimit(web.pid, resource.RLIMIT_NOFILE)[0] == SERVER_FILES

        # --- 1: the cap is met before the descriptors run out ---
        flood(port, 'under the cap')
        c = wait_for('the server to accept the whole flood and see it close',
                     lambda: settled(port, FLOOD * 9 // 10), 20)
        print(f'web_flood_test: after the first flood: {c}')
        assert c['max'] < SERVER_FILES, c            # the cap, below the limit of open files
        assert c['closed_for_room'] > 0, c           # the cap was met: tokenless connections closed for newer ones
        assert c['accept_errors'] == 0, c            # never out of descriptors: the cap stays below the limit

        # --- 2: the descriptors run out below the cap ---
        used = len(os.listdir(f'/proc/{web.pid}/fd'))
        lowered = used + c['max'] // 2
        hard = resource.prlimit(web.pid, resource.RLIMIT_NOFILE)[1]
        resource.prlimit(web.pid, resource.RLIMIT_NOFILE, (lowered, hard))
        flood(port, f'out of descriptors (the server\'s limit lowered to {lowered} files)')
        c2 = wait_for('the server to accept the second flood and see it close',
                      lambda: settled(port, c['accepted'] + FLOOD * 9 // 10), 20)
        print(f'web_flood_test: after the second flood: {c2}')
        assert c2['accept_errors'] > 0, c2           # accept() did run out of descriptors...
        assert c2['max'] < c['max'], c2              # ...so the cap came down to what fits
        assert c2['accept_errors'] < 1000, c2        # a handful, never a retry loop at full speed

        # --- 3: a request that never finishes is closed by the deadline ---
        with socket.create_connection(('127.0.0.1', port), timeout=8) as s:
            s.sendall(UNFINISHED)
            t0 = time.monotonic()
            try:
                closed = s.recv(4096) == b''
            except ConnectionResetError:
                closed = True
            except socket.timeout:
                closed = False
            assert closed, 'an unfinished request was still open after 8 s'
            print(f'web_flood_test: an unfinished request closed by the server after {time.monotonic() - t0:.1f} s')
        c3 = holder_stats(port)['connections']
        assert c3['request_timeouts'] > c2['request_timeouts'], (c2, c3)
        assert web.poll() is None, 'surgsim-web died'
    finally:
        web.send_signal(signal.SIGINT)
        rc = web.wait(15)
    assert rc == 0, rc
    print('web_flood_test: the token holder served within 1 s through both floods; connections capped and closed '
          'for room, never a spin on accept errors; unfinished requests closed by the deadline; clean exit')


if __name__ == '__main__':
    main()
