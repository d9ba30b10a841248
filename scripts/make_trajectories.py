#!/usr/bin/python3
"""Writes the shipped tool trajectories (config/trajectories/liver_*.csv, intestine_*.csv) from smooth scripted motions.

Liver geometry (config/liver.yaml): trocar at (0.03, 0, 0.20), shaft straight down at pitch = yaw = 0; the generated
liver's top surface under the trocar is at z ~ 0.042, i.e. insertion ~ 0.158 m touches it.
Two hands (config/liver_two_tools.yaml): at pitch = yaw = 0 the grasper's tip touches the rest surface of the free left
lobe at insertion 0.1727 m (at (-0.100, 0.010, 0.020)) and the probe's at 0.1770 m (at (-0.071, 0.011, 0.027)), found
by casting each shaft's ray on the generated 1500-node liver; tests/common/scene/scene_test.cpp checks them.
Intestine geometry (config/intestine.yaml): vessel along x through the origin; the rest shape spans x in [-0.28, 0.28],
y in [-0.15, 0.15], z in [-0.12, 0.15] m (with the tapered mesentery), then the folds hang below the vessel under
gravity; intestine radius 2 cm. (The motions were designed on the untapered shape and still reach the folds.) Trocar
at (0, 0.40, -0.12), shaft along -y at pitch = yaw = 0 (tip at y = 0.40 - insertion); positive pitch raises the tip,
yaw swings it along x. Units: s, rad, m.
Run: /usr/bin/python3 scripts/make_trajectories.py [liver|intestine|abdomen]   (stdlib only; no argument: all)
"""
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "config", "trajectories")
RATE = 100.0  # samples per second


def ramp(t, t0, t1, a, b):
    """Half-cosine from a (t <= t0) to b (t >= t1)."""
    if t <= t0:
        return a
    if t >= t1:
        return b
    s = 0.5 - 0.5 * math.cos(math.pi * (t - t0) / (t1 - t0))
    return a + (b - a) * s


def write(name, duration, pose, note, instruments=None):
    """One instrument (v1: pose(t) gives 5 values), or several named ones (v2: pose(t) gives one 5-tuple each)."""
    path = os.path.join(OUT, name)
    n = int(round(duration * RATE))
    dof = ("pitch", "yaw", "insertion", "roll", "jaw")
    with open(path, "w") as f:
        f.write("# surgsim-trajectory %s\n" % ("v1" if instruments is None else "v2"))
        f.write("# %s\n" % note)
        f.write("# made by scripts/make_trajectories.py\n")
        if instruments is None:
            f.write("t,%s\n" % ",".join(dof))
        else:
            f.write("t,%s\n" % ",".join("%s.%s" % (i, d) for i in instruments for d in dof))
        for i in range(n + 1):
            t = i / RATE
            groups = [pose(t)] if instruments is None else pose(t)
            f.write("%.2f" % t + "".join(",%.6f,%.6f,%.6f,%.6f,%.6f" % tuple(p) for p in groups) + "\n")
    print("wrote", path)


def press_and_slide(t):
    # Press 1 cm in, slide 4 cm sideways (yaw) while pressed, come back out.
    ins = ramp(t, 0.5, 1.5, 0.13, 0.168) if t < 4.0 else ramp(t, 4.0, 5.0, 0.168, 0.13)
    yaw = ramp(t, 1.8, 3.6, 0.0, 0.22)
    return (0.0, yaw, ins, 0.0, 0.5)


def grasp_and_pull(t):
    # Approach with the jaw open, press 4 mm, close the jaw, pull 1.5 cm up, hold, open, withdraw.
    if t < 1.6:
        ins = ramp(t, 0.3, 1.5, 0.13, 0.162)
    elif t < 3.6:
        ins = ramp(t, 2.2, 3.4, 0.162, 0.147)
    else:
        ins = ramp(t, 4.3, 5.0, 0.147, 0.12)
    jaw = 0.5 if t < 1.7 else (ramp(t, 1.7, 2.0, 0.5, 0.0) if t < 3.8 else ramp(t, 3.8, 4.1, 0.0, 0.5))
    return (0.0, 0.0, ins, 0.0, jaw)


def sweep(t):
    # Touch several points: three dips at different pitch/yaw, each 8 mm deep.
    targets = [(0.0, -0.18), (0.12, 0.0), (-0.10, 0.15)]
    seg = 2.0
    k = min(int(t // seg), len(targets) - 1)
    local = t - k * seg
    pitch, yaw = targets[k]
    ins = ramp(local, 0.2, 0.8, 0.13, 0.166) if local < 1.0 else ramp(local, 1.1, 1.8, 0.166, 0.13)
    return (pitch, yaw, ins, 0.0, 0.5)


def fast_stab(t):
    # 0.10 m -> 0.17 m in 20 ms (3.5 m/s: several triangles per 300 Hz tick), hold, withdraw slowly.
    ins = ramp(t, 0.50, 0.52, 0.10, 0.17) if t < 1.0 else ramp(t, 1.5, 2.5, 0.17, 0.10)
    return (0.0, 0.0, ins, 0.0, 0.5)


def intestine_push(t):
    # Wait for the folds to settle, push 22 cm in from the side (tip y 0.24 -> 0.02, through the near folds towards
    # the vessel), swing 0.2 rad along the vessel and back while pushed, withdraw.
    ins = ramp(t, 0.8, 2.8, 0.16, 0.38) if t < 4.6 else ramp(t, 4.6, 5.6, 0.38, 0.16)
    yaw = ramp(t, 3.0, 3.7, 0.0, 0.2) if t < 3.8 else ramp(t, 3.8, 4.5, 0.2, 0.0)
    return (0.0, yaw, ins, 0.0, 0.5)


def intestine_lift(t):
    # Slide in under the folds (pitch -0.25: the tip passes 4 cm below them), tilt up to pitch +0.15 (the tip rises
    # about 14 cm and lifts the folds it carries), hold, lower them again, withdraw.
    ins = ramp(t, 0.8, 2.4, 0.16, 0.36) if t < 5.9 else ramp(t, 5.9, 6.8, 0.36, 0.16)
    pitch = ramp(t, 2.5, 4.3, -0.25, 0.15) if t < 4.8 else ramp(t, 4.8, 5.8, 0.15, -0.25)
    return (pitch, 0.0, ins, 0.0, 0.5)


# Grasp and lift (config/liver_multirate.yaml): the tool's trocar at LIFT_TROCAR above the free left lobe, shaft
# straight down at pitch 0 (positive pitch swings the tip towards +x); the tip touches the rest surface at
# (-0.100, 0.010, 0.020), insertion 0.18 m. The grasped point is carried along a circle about the lobe's hinge
# (large_deformation_bench's lift cases: about y through (-0.070, 0.010, -0.010)), i.e. the lobe turned by LIFT_DEG.
LIFT_TROCAR = (-0.10, 0.01, 0.20)
LIFT_HINGE = (-0.070, 0.010, -0.010)
LIFT_GRASP = (-0.100, 0.010, 0.018)  # 2 mm below the rest surface
LIFT_DEG = 60.0


def lift_pose(theta):
    """(pitch, insertion) that put the tip at the grasp point turned by theta (rad) about the hinge."""
    vx, vz = LIFT_GRASP[0] - LIFT_HINGE[0], LIFT_GRASP[2] - LIFT_HINGE[2]
    c, s = math.cos(theta), math.sin(theta)
    px, pz = LIFT_HINGE[0] + c * vx + s * vz, LIFT_HINGE[2] - s * vx + c * vz
    dx, dz = px - LIFT_TROCAR[0], pz - LIFT_TROCAR[2]
    return math.atan2(dx, -dz), math.hypot(dx, dz)


def grasp_and_lift(t):
    # Come down over the free lobe with the jaw open, 2 mm in, close the jaw (grasp), lift the lobe by LIFT_DEG
    # over 1.5 s, hold 1 s, open the jaw (release), withdraw 3 cm along the shaft.
    _, touch = lift_pose(0.0)
    theta = math.radians(LIFT_DEG) * (ramp(t, 1.4, 2.9, 0.0, 1.0))
    pitch, ins = lift_pose(theta)
    if t < 1.4:
        ins = ramp(t, 0.3, 1.0, touch - 0.022, touch)
    elif t >= 4.2:
        ins = ramp(t, 4.2, 5.0, ins, ins - 0.03)
    jaw = ramp(t, 1.0, 1.3, 0.5, 0.0) if t < 3.9 else ramp(t, 3.9, 4.2, 0.0, 0.5)
    return (pitch, 0.0, ins, 0.0, jaw)


# Two hands (config/liver_two_tools.yaml): insertions where each tip touches the rest surface (module docstring).
GRASPER_TOUCH = 0.1727
PROBE_TOUCH = 0.1770


def two_hands(t):
    # The grasper comes down on the free lobe with the jaw open, goes 2 mm in, closes the jaw (grasp), pulls back
    # 6 mm (lifting the lobe 4 mm above rest) and holds; meanwhile the probe comes down 3 cm away, presses 8 mm
    # along its shaft, holds, comes back out; then the grasper opens (letting go) and withdraws.
    g_start, g_grasp, g_pull = GRASPER_TOUCH - 0.0227, GRASPER_TOUCH + 0.002, GRASPER_TOUCH - 0.004
    if t < 1.8:
        g_ins = ramp(t, 0.3, 1.3, g_start, g_grasp)
    elif t < 4.2:
        g_ins = ramp(t, 1.8, 2.5, g_grasp, g_pull)
    else:
        g_ins = ramp(t, 4.2, 4.9, g_pull, g_start)
    g_jaw = ramp(t, 1.35, 1.65, 0.5, 0.0) if t < 3.9 else ramp(t, 3.9, 4.2, 0.0, 0.5)
    p_start, p_press = PROBE_TOUCH - 0.022, PROBE_TOUCH + 0.008
    p_ins = ramp(t, 1.6, 2.8, p_start, p_press) if t < 3.2 else ramp(t, 3.2, 3.8, p_press, p_start)
    # The probe's jaw stays open: a closed jaw on the tissue would grasp.
    return [(0.0, 0.0, g_ins, 0.0, g_jaw), (0.0, 0.0, p_ins, 0.0, 0.5)]


# --- config/abdomen.yaml: the probe presses the liver, the grasper pushes into the bowel, the probe slides on the wall ---
ABD_DOME = (0.21, 0.28, 0.16)        # the wall: ellipsoid radii, centre (0, 0, -0.08), cavity inside
ABD_DOME_Z = -0.08
ABD_TIP = 0.005                      # m, both instruments' tip radius
ABD_PROBE_TROCAR = (0.05, 0.0, 0.078)
ABD_PROBE_AXIS = (-0.04, 0.07, -0.0778)
ABD_GRASPER_TROCAR = (-0.08, -0.06, 0.066)
ABD_GRASPER_AXIS = (0.07, -0.07, -0.106)
ABD_LIVER_AT = (-0.03, 0.07, -0.043)  # the liver's placement (translation)


def _v(a, b, op):
    return tuple(op(x, y) for x, y in zip(a, b))


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _unit(a):
    n = math.sqrt(_dot(a, a))
    return tuple(x / n for x in a)


def _rotate(v, axis, angle):
    """Rodrigues: v turned by angle about the unit axis."""
    c, s = math.cos(angle), math.sin(angle)
    k = _cross(axis, v)
    d = _dot(axis, v) * (1 - c)
    return tuple(v[i] * c + k[i] * s + axis[i] * d for i in range(3))


def tool_direction(axis, pitch, yaw):
    """common/tool/tool.cpp: pitch about e1, then yaw about e2, of the base axis."""
    a = _unit(axis)
    helper = (0.0, 0.0, 1.0) if abs(a[2]) < 0.9 else (1.0, 0.0, 0.0)
    e1 = _unit(_cross(a, helper))
    e2 = _unit(_cross(a, e1))
    return _rotate(_rotate(a, e1, pitch), e2, yaw)


def aim(axis, direction):
    """(pitch, yaw) that turn the base axis onto `direction` (Newton on the two angles, numeric Jacobian)."""
    want = _unit(direction)
    p, y = 0.0, 0.0
    for _ in range(50):
        d = tool_direction(axis, p, y)
        r = _v(d, want, lambda a, b: a - b)
        if _dot(r, r) < 1e-24:
            break
        h = 1e-7
        jp = _v(tool_direction(axis, p + h, y), d, lambda a, b: (a - b) / h)
        jy = _v(tool_direction(axis, p, y + h), d, lambda a, b: (a - b) / h)
        # least squares 2x2: [jp jy]^T [jp jy] [dp dy] = -[jp jy]^T r
        a11, a12, a22 = _dot(jp, jp), _dot(jp, jy), _dot(jy, jy)
        b1, b2 = -_dot(jp, r), -_dot(jy, r)
        det = a11 * a22 - a12 * a12
        p += (a22 * b1 - a12 * b2) / det
        y += (a11 * b2 - a12 * b1) / det
    return p, y


def liver_field_local(x, y, z):
    """common/mesher/organ_mesher.cpp liver_field (the generated liver's implicit solid, > 0 inside)."""
    blobs = [((0.045, -0.006, -0.008), (0.082, 0.080, 0.050), 1.0), ((0.055, 0.025, -0.010), (0.060, 0.050, 0.042), 0.6),
             ((-0.045, 0.004, 0.000), (0.060, 0.060, 0.030), 0.9), ((-0.095, 0.012, 0.000), (0.040, 0.035, 0.016), 0.8),
             ((0.000, -0.094, 0.000), (0.020, 0.040, 0.080), -1.5)]
    f = 0.0
    for c, r, w in blobs:
        u, v, q = (x - c[0]) / r[0], (y - c[1]) / r[1], (z - c[2]) / r[2]
        f += w * math.exp(-(u * u + v * v + q * q))
    f /= 1.0 + math.exp(-(z + 0.035) / 0.003)
    return f - 0.45


def liver_touch(trocar, direction):
    """Insertion at which the tip (the leading point of the tip sphere) reaches the placed liver (0.1 mm steps)."""
    s = 0.0
    while s < 0.3:
        p = tuple(trocar[i] + s * direction[i] - ABD_LIVER_AT[i] for i in range(3))
        if liver_field_local(*p) > 0:
            return s
        s += 1e-4
    raise RuntimeError("the probe's shaft misses the liver")


def wall_insertion(trocar, direction, depth):
    """Insertion putting the tip sphere `depth` past the inside of the dome along the wall's normal (its far crossing
    along the shaft; the wall's plane at that point). The sphere's centre is ABD_TIP behind the tip, its leading
    point."""
    a, b, c = ABD_DOME
    o = (trocar[0] / a, trocar[1] / b, (trocar[2] - ABD_DOME_Z) / c)
    d = (direction[0] / a, direction[1] / b, direction[2] / c)
    qa, qb, qc = _dot(d, d), 2 * _dot(o, d), _dot(o, o) - 1
    s_exit = (-qb + math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    w = tuple(trocar[i] + s_exit * direction[i] for i in range(3))
    n = _unit((w[0] / a ** 2, w[1] / b ** 2, (w[2] - ABD_DOME_Z) / c ** 2))  # outward
    return s_exit + ABD_TIP - (ABD_TIP - depth) / _dot(n, direction)


def wall_point(y, z):
    """The dome's point on its +x side at (y, z)."""
    a, b, c = ABD_DOME
    x = a * math.sqrt(1 - (y / b) ** 2 - ((z - ABD_DOME_Z) / c) ** 2)
    return (x, y, z)


def abdomen(t):
    # Probe: onto the liver along its base axis (pitch = yaw = 0), 8 mm along the shaft past touching, hold, out.
    probe_dir = _unit(ABD_PROBE_AXIS)
    touch = liver_touch(ABD_PROBE_TROCAR, probe_dir)
    p_far, p_press = touch - 0.02, touch + 0.008
    if t < 3.0:
        probe = (0.0, 0.0, ramp(t, 0.3, 1.3, p_far, p_press) if t < 2.4 else ramp(t, 2.4, 3.0, p_press, p_far), 0.0, 0.5)
    else:
        # Then to the side wall: out to 4 cm, turn towards the wall point at y = -0.05, in to 0.5 mm past the wall,
        # slide to y = +0.05 along it (the depth kept along the shaft), out.
        def at(y):
            w = wall_point(y, -0.03)
            d = _unit(_v(w, ABD_PROBE_TROCAR, lambda a, b: a - b))
            pitch, yaw = aim(ABD_PROBE_AXIS, d)
            return pitch, yaw, wall_insertion(ABD_PROBE_TROCAR, d, 0.0005)
        out = 0.04
        if t < 3.6:
            probe = (0.0, 0.0, ramp(t, 3.0, 3.6, p_far, out), 0.0, 0.5)
        else:
            p0, y0, i0 = at(-0.05)
            if t < 4.2:
                k = ramp(t, 3.6, 4.2, 0.0, 1.0)
                probe = (k * p0, k * y0, out, 0.0, 0.5)
            elif t < 5.2:
                probe = (p0, y0, ramp(t, 4.2, 5.2, out, i0), 0.0, 0.5)
            elif t < 7.2:
                pw, yw, iw = at(ramp(t, 5.2, 7.2, -0.05, 0.05))
                probe = (pw, yw, iw, 0.0, 0.5)
            else:
                p1, y1, i1 = at(0.05)
                probe = (p1, y1, ramp(t, 7.2, 7.8, i1, out), 0.0, 0.5)
    # Grasper, jaw open: along its base axis into the hanging folds under the vessel and back out.
    g = ramp(t, 1.0, 2.2, 0.03, 0.15) if t < 2.6 else ramp(t, 2.6, 3.6, 0.15, 0.03)
    grasper = (0.0, 0.0, g, 0.0, 0.5)
    return [probe, grasper]


# --- config/abdomen.yaml, second trajectory: the probe lifts the liver's edge into the ribs ---
# The ribs: arcs of radius 0.12 m about y through (0, y, -0.08) at y = 0.10, 0.13, 0.16, each spanning x in
# [-0.085, 0.085] over the top (bars 6 mm thick). The liver's right lobe runs out under the first one: its top at
# (0.07, 0.09) is at z = -0.0125, 2 cm under the rib's underside (z ~ 0.010 at x = 0.07).
ABD_LIFT_AIM = (0.072, 0.108, -0.03)  # the probe's line onto the right lobe's anterior edge: it touches the liver's
                                      # top at about (0.068, 0.089, -0.011), under the first rib's caudal side
ABD_LIFT_UP = (0.0, -0.004, 0.06)  # m, the grasped point carried up, past the rib's top, its tip caudal of the rib
ABD_LIFT_OVER = 0.028             # m, then cranially over the rib (the tip between the first two): the lifted edge
                                  # is drawn onto the first rib's caudal face


def _probe_at(point):
    """(pitch, yaw, insertion) of the probe whose tip is at `point`."""
    d = _v(point, ABD_PROBE_TROCAR, lambda a, b: a - b)
    pitch, yaw = aim(ABD_PROBE_AXIS, d)
    return pitch, yaw, math.sqrt(_dot(d, d))


def abdomen_lift(t):
    # Probe: turned onto the right lobe's anterior edge under the first rib with its jaw open, in 3 mm past touching,
    # the jaw closed (grasp), the grasped edge lifted ABD_LIFT_UP in 1.5 s and carried ABD_LIFT_OVER cranially over the
    # rib in 1 s (the edge drawn onto it), held 0.9 s, back the same way, released, out.
    d = _unit(_v(ABD_LIFT_AIM, ABD_PROBE_TROCAR, lambda a, b: a - b))
    touch = liver_touch(ABD_PROBE_TROCAR, d)
    grasp = tuple(ABD_PROBE_TROCAR[i] + (touch + 0.003) * d[i] for i in range(3))
    pitch, yaw = aim(ABD_PROBE_AXIS, d)
    if t < 1.5:
        probe = (ramp(t, 0.0, 0.5, 0.0, pitch), ramp(t, 0.0, 0.5, 0.0, yaw),
                 ramp(t, 0.4, 1.4, touch - 0.02, touch + 0.003), 0.0, 0.5)
    else:
        up = ramp(t, 2.0, 3.5, 0.0, 1.0) if t < 5.0 else ramp(t, 6.4, 7.4, 1.0, 0.0)
        over = ramp(t, 3.5, 4.5, 0.0, ABD_LIFT_OVER) if t < 5.0 else ramp(t, 5.4, 6.4, ABD_LIFT_OVER, 0.0)
        at = tuple(grasp[i] + up * ABD_LIFT_UP[i] + (over if i == 1 else 0.0) for i in range(3))
        pw, yw, iw = _probe_at(at)
        if t >= 8.0:
            iw = ramp(t, 8.0, 9.0, iw, iw - 0.03)
        jaw = ramp(t, 1.5, 1.8, 0.5, 0.0) if t < 7.6 else ramp(t, 7.6, 7.9, 0.0, 0.5)
        probe = (pw, yw, iw, 0.0, jaw)
    # Grasper, jaw open: along its base axis into the bowel's folds, a loop pushed onto the liver's lower edge and held
    # there while the edge is lifted, back out.
    g = ramp(t, 1.0, 2.2, 0.03, 0.15) if t < 7.6 else ramp(t, 7.6, 8.6, 0.15, 0.03)
    return [probe, (0.0, 0.0, g, 0.0, 0.5)]


def abdomen_loop(t):
    """abdomen() six times, 9 s apart: each 8 s run, then 1 s back to its start pose along a straight line (a load
    for paired live runs as long as rt_bench's: not shipped, written only when asked for)."""
    k = t % 9.0
    if k <= 8.0:
        return abdomen(k)
    s = k - 8.0
    end, start = abdomen(8.0), abdomen(0.0)
    return [tuple(e + (b - e) * s for e, b in zip(pe, pb)) for pe, pb in zip(end, start)]


if __name__ == "__main__":
    import sys
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    if which in ("all", "abdomen"):
        write("abdomen.csv", 8.0, abdomen,
              "abdomen: the probe presses the liver 8 mm while the grasper pushes into the bowel's folds, then the "
              "probe slides 10 cm along the side wall 0.5 mm deep", instruments=("probe", "grasper"))
        write("abdomen_lift.csv", 9.5, abdomen_lift,
              "abdomen: the probe grasps the right lobe's anterior edge and lifts it %.0f mm and over the first rib (the "
              "edge onto it) while the grasper pushes a loop of bowel onto the liver's lower edge" % (1e3 * ABD_LIFT_UP[2]),
              instruments=("probe", "grasper"))
    if which == "abdomen_loop":  # not in "all": a measurement load, not a shipped trajectory (git ignores it)
        write("abdomen_loop.csv", 53.0, abdomen_loop,
              "abdomen.csv six times, 9 s apart (1 s back to the start pose between): a 53 s load for paired live "
              "runs", instruments=("probe", "grasper"))
        sys.exit(0)
    if which in ("all", "intestine"):
        write("intestine_push.csv", 6.0, intestine_push,
              "intestine: push the folds 22 cm in from the side, swing along the vessel, withdraw")
        write("intestine_lift.csv", 7.0, intestine_lift,
              "intestine: slide under the folds, tilt up 0.4 rad to lift them, lower, withdraw")
    if which not in ("all", "liver"):
        sys.exit(0)
    write("liver_press_slide.csv", 5.5, press_and_slide, "press 1 cm into the liver top, slide 4 cm (yaw), withdraw")
    write("liver_grasp_pull.csv", 5.5, grasp_and_pull, "press, close the jaw (grasp), pull 1.5 cm up, open, withdraw")
    write("liver_sweep.csv", 6.0, sweep, "three 8 mm dips at different pitch/yaw")
    write("liver_fast_stab.csv", 3.0, fast_stab, "stab at 3.5 m/s to 1.2 cm deep, hold, withdraw")
    write("liver_grasp_lift.csv", 5.5, grasp_and_lift,
          "liver_multirate: grasp the free lobe, lift it %g degrees about its hinge in 1.5 s, hold, release, withdraw"
          % LIFT_DEG)
    write("liver_two_hands.csv", 5.0, two_hands,
          "liver_two_tools: the grasper holds the free lobe and lifts it 4 mm while the probe presses 8 mm 3 cm away",
          instruments=("grasper", "probe"))
