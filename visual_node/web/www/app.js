// surgsim-web page: the live view, the plots, the scene and the virtual device. Plain JavaScript, no
// library. The WebSocket carries binary frames (48-byte header + JPEG, see web_dds.h) and JSON text (hello,
// telemetry); the page sends JSON: take / release the tool, the pose it asks for (absolute, 50 Hz while it drives),
// and the number of each frame it has displayed (the server measures render -> shown from it).
'use strict';

const token = new URLSearchParams(location.search).get('token') || '';
const S = {                      // the page's state (also read by the browser tests through window.surgsim)
  connected: false, id: 0, driver: 0, drives: false, hello: null,
  frames: 0, lastFrame: 0, frameSize: 0,
  force: [0, 0, 0], forceNorm: 0, forceMax: 0, contacts: 0, contactsMax: 0, flags: 0,
  target: { pitch: 0, yaw: 0, insertion: 0, roll: 0, jaw: 0.5 },
  posesSent: 0, telemetry: 0,
};
window.surgsim = S;

const $ = (id) => document.getElementById(id);
const view = $('view');

// --- scrolling plots (last 20 s) ---
class Plot {
  constructor(canvas, color, fixedMax) {
    this.c = canvas; this.ctx = canvas.getContext('2d'); this.color = color; this.fixedMax = fixedMax;
    this.t = []; this.v = []; this.span = 20;
  }
  add(t, v) {
    this.t.push(t); this.v.push(v);
    while (this.t.length && this.t[0] < t - this.span) { this.t.shift(); this.v.shift(); }
  }
  draw() {
    const { ctx, c } = this; const w = c.width, h = c.height;
    ctx.clearRect(0, 0, w, h);
    if (!this.t.length) return;
    let max = this.fixedMax || 0;
    for (const x of this.v) if (x > max) max = x;
    if (!(max > 0)) max = 1;
    const t1 = this.t[this.t.length - 1], t0 = t1 - this.span;
    ctx.strokeStyle = '#333'; ctx.beginPath(); ctx.moveTo(0, h - 14.5); ctx.lineTo(w, h - 14.5); ctx.stroke();
    ctx.strokeStyle = this.color; ctx.lineWidth = 1.5; ctx.beginPath();
    this.t.forEach((t, i) => {
      const x = (t - t0) / this.span * w, y = (h - 15) - this.v[i] / max * (h - 25);
      if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y);
    });
    ctx.stroke();
    ctx.fillStyle = '#aaa'; ctx.font = '11px monospace';
    const last = this.v[this.v.length - 1];
    ctx.fillText(`max ${max.toPrecision(3)}   now ${last.toPrecision(3)}`, 4, 11);
  }
}
const plots = {
  force: new Plot($('plot_force'), '#e0a030'),
  contacts: new Plot($('plot_contacts'), '#7fd37f'),
  rate: new Plot($('plot_rate'), '#9fc3ff'),
  latency: new Plot($('plot_latency'), '#ff8080'),
};
window.surgsimPlots = plots;

// --- the force: an arrow (x right, z up: the front view) and a bar against the device limit ---
function drawForce() {
  const c = $('arrow'), ctx = c.getContext('2d');
  ctx.clearRect(0, 0, c.width, c.height);
  const limit = (S.hello && S.hello.force_limit) || 8;
  const [fx, , fz] = S.force;
  // The circle is the larger of 2 N and the largest force seen (the bar below is against the device limit).
  const ring = Math.min(limit, Math.max(2, S.forceMax)), cx = c.width / 2, cy = c.height / 2;
  const scale = (c.height / 2 - 12) / ring;
  ctx.strokeStyle = '#444'; ctx.beginPath(); ctx.arc(cx, cy, ring * scale, 0, 2 * Math.PI); ctx.stroke();
  ctx.fillStyle = '#777'; ctx.font = '10px monospace';
  ctx.fillText(`${ring.toFixed(1)} N`, 4, 12); ctx.fillText('x \u2192  z \u2191 (front view)', 4, c.height - 4);
  const x = cx + fx * scale, y = cy - fz * scale;
  ctx.strokeStyle = '#e0a030'; ctx.fillStyle = '#e0a030'; ctx.lineWidth = 3; ctx.lineCap = 'round';
  ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(x, y); ctx.stroke();
  const a = Math.atan2(y - cy, x - cx);
  if (S.forceNorm > 1e-3) {
    ctx.beginPath(); ctx.moveTo(x, y);
    ctx.lineTo(x - 9 * Math.cos(a - 0.4), y - 9 * Math.sin(a - 0.4));
    ctx.lineTo(x - 9 * Math.cos(a + 0.4), y - 9 * Math.sin(a + 0.4)); ctx.fill();
  }
  $('forcebar').style.width = `${Math.min(100, 100 * S.forceNorm / limit)}%`;
  $('forcetext').textContent =
    `|F| ${S.forceNorm.toFixed(3)} N  (${S.force.map((v) => v.toFixed(2)).join(', ')})  limit ${limit} N` +
    (S.flags & 8 ? '  INPUT LOST' : '') + (S.flags & 1 ? '  SATURATED' : '');
}

// --- the WebSocket ---
let ws = null;
let pending = null, decoding = false;
function connect() {
  const proto = location.protocol === 'https:' ? 'wss' : 'ws';
  ws = new WebSocket(`${proto}://${location.host}/ws?token=${encodeURIComponent(token)}`);
  ws.binaryType = 'arraybuffer';
  ws.onopen = () => { S.connected = true; $('conn').textContent = 'connected'; $('conn').className = 'ok'; };
  ws.onclose = () => {
    S.connected = false; S.drives = false;
    $('conn').textContent = 'disconnected (reload the page)'; $('conn').className = 'bad';
  };
  ws.onmessage = (ev) => {
    if (typeof ev.data === 'string') onText(JSON.parse(ev.data)); else onFrame(ev.data);
  };
}
function send(obj) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(obj)); }

function onFrame(buf) {
  const d = new DataView(buf);
  if (buf.byteLength < 48 || d.getUint32(0, true) !== 0x31464753) return;  // "SGF1"
  S.frames++; S.frameSize = buf.byteLength - 48;
  const f = { number: Number(d.getBigUint64(16, true)), w: d.getUint32(4, true), h: d.getUint32(8, true),
              q: d.getUint32(12, true), blob: new Blob([buf.slice(48)], { type: 'image/jpeg' }) };
  if (decoding) { pending = f; return; }   // still decoding the previous one: keep only the newest
  show(f);
}
// Decoded off the main thread (createImageBitmap), drawn on the canvas, then reported as shown.
function show(f) {
  decoding = true;
  createImageBitmap(f.blob).then((bitmap) => {
    if (view.width !== f.w || view.height !== f.h) { view.width = f.w; view.height = f.h; }
    view.getContext('2d').drawImage(bitmap, 0, 0);
    bitmap.close();
    S.lastFrame = f.number;
    send({ type: 'shown', frame: f.number });
    $('frameinfo').textContent = `frame ${f.number}  ${f.w}x${f.h}  JPEG q${f.q} ${(S.frameSize / 1024).toFixed(1)} KiB` +
      `  (${S.frames} received)`;
  }).catch(() => { S.badFrames = (S.badFrames || 0) + 1; }).finally(() => {
    decoding = false;
    if (pending) { const p = pending; pending = null; show(p); }
  });
}

const seqs = [];                           // [server time s, contact frame seq] of the last second
function onText(m) {
  if (m.type === 'hello') {
    S.hello = m; S.id = m.id;
    Object.assign(S.target, m.pose);
    send({ type: 'take' });                // drive when nobody does; else watch
  } else if (m.type === 'telemetry') {
    S.telemetry++;
    S.driver = m.driver; S.drives = m.driver === S.id;
    S.force = m.force; S.forceNorm = Math.hypot(...m.force); S.flags = m.force_flags;
    S.forceMax = Math.max(S.forceMax, S.forceNorm);
    S.contacts = m.contacts; S.contactsMax = Math.max(S.contactsMax, m.contacts);
    const t = m.t;
    // The haptic rate: contact frames (one per tick) over the last second.
    seqs.push([t, m.contact_seq]);
    while (seqs.length > 2 && seqs[1][0] <= t - 1) seqs.shift();
    if (seqs.length > 1 && t - seqs[0][0] >= 0.5) plots.rate.add(t, (m.contact_seq - seqs[0][1]) / (t - seqs[0][0]));
    plots.force.add(t, S.forceNorm);
    plots.contacts.add(t, m.contacts);
    if (m.haptic_visual_latency_us >= 0) plots.latency.add(t, m.haptic_visual_latency_us);
    for (const p of Object.values(plots)) p.draw();
    drawForce();
    if (m.scene) {
      const s = m.scene;
      $('scene').innerHTML = [['name', s.name], ['scene', s.scene_hash], ['mesh', s.mesh_hash],
        ['material', s.material_hash], ['tensors', s.tensor_hash], ['instruments', s.instruments],
        ['organs', s.organs || ''], ['haptic', `${s.haptic_rate_hz} Hz`]].map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join('');
    }
    const p = m.tool_pose;
    $('pose').textContent = `pitch ${p[0].toFixed(3)} yaw ${p[1].toFixed(3)} ins ${p[2].toFixed(4)} m jaw ` +
      `${p[4].toFixed(2)}  contacts ${m.contacts}`;
    const role = $('role');
    if (S.drives) { role.textContent = `You drive '${S.hello.instrument_name}'`; role.className = 'ok'; }
    else if (m.driver) { role.textContent = 'Another browser drives the tool: you are watching'; role.className = 'bad'; }
    else { role.textContent = 'Nobody drives: press "Take the tool"'; role.className = ''; }
  }
}

// --- the virtual device: keys, mouse drag, wheel, gamepad; the pose is sent at 50 Hz while this page drives ---
const keys = new Set();
const keyOf = (e) => (e.key.length === 1 ? e.key.toLowerCase() : e.key);
document.addEventListener('keydown', (e) => {
  const k = keyOf(e);
  if (k === ' ') { S.target.jaw = S.target.jaw > 0.05 ? 0 : 0.5; e.preventDefault(); return; }
  keys.add(k);
  if (k.startsWith('Arrow')) e.preventDefault();
});
document.addEventListener('keyup', (e) => keys.delete(keyOf(e)));
window.addEventListener('blur', () => keys.clear());
let drag = null;
view.addEventListener('mousedown', (e) => { drag = { x: e.clientX, y: e.clientY }; e.preventDefault(); });
window.addEventListener('mouseup', () => { drag = null; });
window.addEventListener('mousemove', (e) => {
  if (!drag) return;
  S.target.yaw += (e.clientX - drag.x) * 0.004;
  S.target.pitch += (e.clientY - drag.y) * 0.004;
  drag = { x: e.clientX, y: e.clientY };
});
view.addEventListener('wheel', (e) => { S.target.insertion -= Math.sign(e.deltaY) * 0.002; e.preventDefault(); },
  { passive: false });

let lastTick = performance.now();
function tick() {
  const now = performance.now(), dt = Math.min(0.1, (now - lastTick) / 1000);
  lastTick = now;
  const L = (S.hello && S.hello.limits) || { max_angle: 0.8, max_insertion: 0.35, max_jaw: 1, angle_rate: 1, insertion_rate: 0.05 };
  const w = 0.5 * L.angle_rate * dt, v = 0.5 * L.insertion_rate * dt, T = S.target;
  if (keys.has('w') || keys.has('ArrowUp')) T.pitch -= w;
  if (keys.has('s') || keys.has('ArrowDown')) T.pitch += w;
  if (keys.has('a') || keys.has('ArrowLeft')) T.yaw -= w;
  if (keys.has('d') || keys.has('ArrowRight')) T.yaw += w;
  if (keys.has('e') || keys.has('+') || keys.has('=')) T.insertion += v;
  if (keys.has('q') || keys.has('-')) T.insertion -= v;
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  const g = pads && pads[0];
  if (g) {
    const dz = (x) => (Math.abs(x) > 0.15 ? x : 0);
    T.yaw += dz(g.axes[0] || 0) * w * 2; T.pitch += dz(g.axes[1] || 0) * w * 2;
    const push = (g.buttons[7] ? g.buttons[7].value : 0) - (g.buttons[6] ? g.buttons[6].value : 0);
    T.insertion += push * v * 2;
  }
  const clamp = (x, lo, hi) => Math.min(hi, Math.max(lo, x));
  T.pitch = clamp(T.pitch, -L.max_angle, L.max_angle); T.yaw = clamp(T.yaw, -L.max_angle, L.max_angle);
  T.insertion = clamp(T.insertion, 0, L.max_insertion); T.jaw = clamp(T.jaw, 0, L.max_jaw);
  if (S.drives) { send({ type: 'pose', ...T }); S.posesSent++; }
}
setInterval(tick, 20);

$('take').onclick = () => send({ type: 'take' });
$('release').onclick = () => send({ type: 'release' });
connect();
