#!/usr/bin/python3
"""surgsim-web refuses bad requests and counts them, and nothing crashes: an unknown path (404), a wrong
or missing token (403) on the page, /stats and the WebSocket, a method other than GET (405), a malformed request
(400), an oversized header (413), a WebSocket message above the limit (the socket is closed with 1009 "too big"),
malformed messages and poses from a page that does not drive (ignored, counted), more pages than --max-clients.
Afterwards the server still serves the page and its counters say what was refused. Only surgsim-web runs (the
refusals need no simulator).

Usage: web_requests_test.py BIN_DIR CONFIG_DIR OUT_DIR"""
import base64
import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys

from web_support import private_domain, reserved_fds

TOKEN = 'reqtest0123456789'


def http(port, raw):
    """Sends raw bytes, returns the status code of the answer (0: connection closed without one)."""
    with socket.create_connection(('127.0.0.1', port), timeout=5) as s:
        s.sendall(raw)
        data = b''
        try:
            while b'\r\n' not in data:
                chunk = s.recv(4096)
                if not chunk:
                    break
                data += chunk
        except (ConnectionResetError, socket.timeout):
            pass
    m = re.match(rb'HTTP/1\.[01] (\d+)', data)
    return int(m.group(1)) if m else 0


def get(port, target):
    return http(port, f'GET {target} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n'.encode())


class WebSocket:
    """A minimal RFC 6455 client: handshake, masked text frames out, frames in."""

    def __init__(self, port, token=TOKEN):
        self.s = socket.create_connection(('127.0.0.1', port), timeout=5)
        key = base64.b64encode(os.urandom(16)).decode()
        self.s.sendall((f'GET /ws?token={token} HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n'
                        f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n')
                       .encode())
        head = b''
        while b'\r\n\r\n' not in head:
            chunk = self.s.recv(1)
            if not chunk:
                break
            head += chunk
        self.status = int(re.match(rb'HTTP/1\.[01] (\d+)', head).group(1)) if head else 0

    def send(self, payload, opcode=1):
        if isinstance(payload, str):
            payload = payload.encode()
        mask = os.urandom(4)
        n = len(payload)
        header = bytes([0x80 | opcode])
        if n < 126:
            header += bytes([0x80 | n])
        elif n < 65536:
            header += bytes([0x80 | 126]) + struct.pack('>H', n)
        else:
            header += bytes([0x80 | 127]) + struct.pack('>Q', n)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.s.sendall(header + mask + masked)

    def _exact(self, n):
        data = b''
        while len(data) < n:
            chunk = self.s.recv(n - len(data))
            if not chunk:
                raise ConnectionError('closed')
            data += chunk
        return data

    def recv(self):
        """(opcode, payload) of the next frame."""
        b0, b1 = self._exact(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack('>H', self._exact(2))[0]
        elif n == 127:
            n = struct.unpack('>Q', self._exact(8))[0]
        return b0 & 0x0F, self._exact(n)

    def recv_json(self, type_):
        while True:
            op, data = self.recv()
            if op == 1:
                m = json.loads(data)
                if m.get('type') == type_:
                    return m

    def close(self):
        self.s.close()


def stats(port):
    with socket.create_connection(('127.0.0.1', port), timeout=5) as s:
        s.sendall(f'GET /stats?token={TOKEN} HTTP/1.1\r\nHost: x\r\n\r\n'.encode())
        data = b''
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    return json.loads(data.split(b'\r\n\r\n', 1)[1])


def main():
    bin_dir, config_dir, out = sys.argv[1:4]
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    env = dict(os.environ, SURGSIM_CONFIG_DIR=config_dir, SURGSIM_DOMAIN=str(private_domain(41)))
    log = open(os.path.join(out, 'web.log'), 'w')
    web = subprocess.Popen([f'{bin_dir}/surgsim-web', '--scene', 'liver', '--port', '0', '--token', TOKEN,
                            '--max-clients', '3', '--max-message', '1024', '--stats', f'{out}/web.json'],
                           env=env, stdout=subprocess.PIPE, stderr=log, text=True, pass_fds=reserved_fds())
    try:
        port = int(re.search(r':(\d+)/', web.stdout.readline()).group(1))
        # --- HTTP ---
        assert get(port, f'/?token={TOKEN}') == 200
        assert get(port, '/app.js') == 200
        assert get(port, '/nope') == 404
        assert get(port, '/../../etc/passwd') == 404
        assert get(port, '/') == 403                      # no token
        assert get(port, '/?token=wrong') == 403
        assert get(port, '/stats?token=wrong') == 403
        assert get(port, f'/stats?token={TOKEN}x') == 403
        assert http(port, f'POST /?token={TOKEN} HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\n\r\nhi'.encode()) == 405
        assert http(port, b'BLAH\r\n\r\n') == 400
        assert http(port, b'GET / HTTP/1.1\r\nX-Big: ' + b'a' * 20000 + b'\r\n\r\n') in (413, 400)
        assert get(port, f'/ws?token={TOKEN}') == 400     # no upgrade
        # --- WebSocket ---
        assert WebSocket(port, token='wrong').status == 403
        a = WebSocket(port)
        assert a.status == 101
        hello = a.recv_json('hello')
        a.send('{"type":"take"}')
        b = WebSocket(port)
        b.recv_json('hello')
        b.send('{"type":"take"}')                         # refused: a drives
        b.send('{"type":"pose","pitch":0,"yaw":0,"insertion":0.2,"jaw":0}')   # not the driver: ignored
        for bad in ('not json', '{"type":"fly"}', '{"type":"pose","pitch":"x","yaw":0,"insertion":0,"jaw":0}',
                    '{"type":"pose","pitch":1e999,"yaw":0,"insertion":0,"jaw":0}'):
            b.send(bad)
        b.send(b'\x00\x01binary', opcode=2)               # a binary message: malformed
        c = WebSocket(port)
        c.recv_json('hello')
        d = WebSocket(port)                               # the fourth page: over --max-clients 3
        op, data = d.recv()
        assert op == 8 and struct.unpack('>H', data[:2])[0] == 1013, (op, data)
        d.close()
        # An oversized message closes that socket with 1009 (too big); the others go on.
        c.send('{"type":"pose",' + ' ' * 2000 + '}')
        while True:
            op, data = c.recv()
            if op == 8:
                assert struct.unpack('>H', data[:2])[0] == 1009, data
                break
        c.close()
        tele = a.recv_json('telemetry')
        assert tele['driver'] == hello['id'], (tele, hello)
        a.send('{"type":"pose","pitch":0,"yaw":0,"insertion":0.13,"jaw":0.5}')
        a.recv_json('telemetry')
        st = stats(port)
        r = st['refused']
        assert r['not_found'] == 2 and r['forbidden'] == 5, r
        assert r['method_not_allowed'] == 1 and r['bad_request'] >= 3, r
        assert r['drive_refused'] == 1 and r['ws_not_driver'] == 1, r
        assert r['ws_malformed'] == 5 and r['ws_oversize'] == 1 and r['too_many_clients'] == 1, r
        assert st['poses_received'] >= 1 and st['driver'] == hello['id'], st
        a.close()
        b.close()
        assert get(port, f'/?token={TOKEN}') == 200       # still serving
        assert web.poll() is None, 'surgsim-web died'
    finally:
        web.send_signal(signal.SIGINT)
        rc = web.wait(15)
    assert rc == 0, rc
    print('web_requests_test: every bad request refused and counted; still serving; clean exit')


if __name__ == '__main__':
    main()
