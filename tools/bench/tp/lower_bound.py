#!/usr/bin/python3
"""Lower bound on the traverse time of ANY planner on the tp_compare programs (issue 23), and
LinuxCNC's and contourd's times (results.json of tp_compare.sh) divided by it.

Each program goes through LinuxCNC's standalone interpreter (`rs274 -g -t TOOL_TABLE PROGRAM`);
its canonical calls (STRAIGHT_TRAVERSE/FEED, ARC_FEED in any plane, G20/G21, DWELL, M0/M1) give
the path from X0 Y0 Z0: one piece per line, arcs/helices cut into pieces of <= 2 degrees with
their true length and curvature. The bound is the time of the time-optimal speed profile along
the pieces (backward and forward passes, closed-form accelerate / cruise / decelerate per piece)
plus the dwells between the first and last motion. Each constraint relaxes one that a planner with
the same per-axis limits (vmax_i, a_i, rapid from --config) and path tolerance P must obey:
  - speed <= feed (rapid for G0) and vmax_i/|u_i|, u the direction (on arcs its smallest |u_i|);
  - tangential acceleration <= min_i a_i/|u_i| on lines (exact), <= min(|a|_2, sum_i a_i max|u_i|)
    on arcs; arcs: v <= sqrt(|a|_2 R'), R' = R + P(1+s)/(1-s), s = cos(min(sweep, 180)/2), the
    largest circle within P of the arc tangent to the outer offsets of its end tangents;
  - corner of deflection theta: v <= sqrt(|a|_2 R_j) at the vertex, R_j = 2P/(1-cos(t/2)), the
    largest circle within P of both legs (tangent to their outer offsets, innermost point at the
    inner offsets' crossing), t = theta - asin(2P/L) per leg of length L (a zig-zag or spike
    smaller than P needs no turn at all);
  - corner cutting: a path within P of every vertex is at most sum 2P sin(theta/2) shorter than
    the polyline (its length is convex in the vertices): each piece loses P sin(theta/2) per end;
  - stops only at program start/end, dwells (also G4 P0) and M0/M1; no jerk limit, no servo
    period; spindle, coolant, tool changes and M0 waits cost nothing.
Argued, not proven: the local two-leg picture behind R_j and R', and taking the corner cut at the
piece ends rather than at the slow vertex. --junction spec: the brief's R_j = P(1+c)/(1-c),
c = cos(theta/2), full theta, plain arc radius (tighter than a circle that fits the band: not a
valid bound); none: no corner caps; --no-cut: programmed lengths (LinuxCNC beats it on 5 of 32).

Usage: lower_bound.py [--programs LIST] [--config YAML] [--results RESULTS.json]
                      [--tolerance-um 50] [--junction tube|spec|none] [--no-cut]
                      [--rs274 rs274] [--tool-table TBL] [--json OUT] [PROGRAM ...]
"""
import argparse
import json
import math
import os
import re
import statistics
import subprocess
import sys

import yaml

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
TPC = os.path.join(ROOT, "build", "tp_compare")
CALL = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z0-9_]+)\((.*)\)\s*$")
PLANES = {"CANON_PLANE_XY": (0, 1, 2), "CANON_PLANE_XZ": (2, 0, 1), "CANON_PLANE_YZ": (1, 2, 0)}
INF = float("inf")


def canon(prog, o):
    """The canonical calls of PROG as (name, [args]); raises RuntimeError if rs274 fails."""
    r = subprocess.run([o.rs274, "-g", "-t", o.tool_table, prog], input="", capture_output=True,
                       text=True, timeout=300)
    calls = [(m.group(1), [a.strip() for a in m.group(2).split(",")])
             for m in map(CALL.match, r.stdout.splitlines()) if m]
    if r.returncode != 0 or not any(c[0] == "PROGRAM_END" for c in calls):
        msg = [ln for ln in (r.stderr + r.stdout).splitlines() if ln.strip() and not CALL.match(ln)
               and ln.strip() != "executing"]
        raise RuntimeError("rs274 exit %d: %s" % (r.returncode, " | ".join(msg)[:200]))
    return calls


def hits(x0, lo, hi):
    """Whether some x0 + m*pi lies in [lo, hi]."""
    return x0 + math.ceil((lo - x0) / math.pi) * math.pi <= hi


def unit(v):
    n = math.sqrt(sum(x * x for x in v))           # the zero vector stays zero
    return [x / n for x in v] if n > 0 else [0.0, 0.0, 0.0]


def angle(u, w):
    return math.acos(max(-1.0, min(1.0, sum(a * b for a, b in zip(u, w)))))


def path(calls, lim, o):
    """Pieces [length, v_cap, a_t, chord dir, start tangent, end tangent, move id, move length],
    stop boundaries, dwell seconds per boundary, notes."""
    vmax, acc, P = lim["vmax"], lim["acc"], o.tolerance_um / 1000.0
    an = math.sqrt(sum(a * a for a in acc))
    pos, k, feed, plane, mid = [0.0] * 3, 1.0, 0.0, PLANES["CANON_PLANE_XY"], 0
    pieces, stops, dwell, notes = [], set(), {}, set()

    def caps(umin, umax, arc):
        axis = [vmax[i] / umin[i] for i in range(3) if umin[i] > 1e-12]
        a_t = min(an, sum(acc[i] * umax[i] for i in range(3))) if arc else \
            min(acc[i] / umax[i] for i in range(3) if umax[i] > 1e-12)
        return min(axis + [INF]), a_t

    for name, a in calls:
        if name == "USE_LENGTH_UNITS":           # a feed keeps the units it was set in, as in LinuxCNC
            k = 25.4 if a[0].endswith("INCHES") else 1.0
            notes |= {"inch"} if k != 1.0 else set()
        elif name == "SET_FEED_RATE":
            feed = float(a[0]) * k / 60.0
        elif name == "SET_FEED_MODE" and a[-1] != "0":
            notes.add("feed mode %s ignored" % a[-1])
        elif name == "SELECT_PLANE":
            plane = PLANES[a[0]]
            notes |= {a[0][-2:] + " plane"} if a[0] != "CANON_PLANE_XY" else set()
        elif name in ("DWELL", "PROGRAM_STOP", "OPTIONAL_PROGRAM_STOP"):
            stops.add(len(pieces))
            if name == "DWELL":
                dwell[len(pieces)] = dwell.get(len(pieces), 0.0) + float(a[0])
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            end = [float(x) * k for x in a[:3]]
            d = [e - s for e, s in zip(end, pos)]
            L = math.sqrt(sum(x * x for x in d))
            if L > 1e-9:
                u = unit(d)
                vc, a_t = caps([abs(x) for x in u], [abs(x) for x in u], False)
                v = lim["rapid"] if name == "STRAIGHT_TRAVERSE" else (feed if feed > 0 else INF)
                pieces.append([L, min(v, vc), a_t, u, u, u, mid, L])
                mid += 1
            pos = end
        elif name == "ARC_FEED":
            f, s_, ax = plane
            e1, e2, c1, c2, rot, e3 = (float(x) for x in a[:6])
            end = [0.0] * 3
            end[f], end[s_], end[ax], c1, c2 = e1 * k, e2 * k, e3 * k, c1 * k, c2 * k
            r0, r1 = math.hypot(pos[f] - c1, pos[s_] - c2), math.hypot(end[f] - c1, end[s_] - c2)
            a0, a1 = math.atan2(pos[s_] - c2, pos[f] - c1), math.atan2(end[s_] - c2, end[f] - c1)
            sg = 1.0 if rot > 0 else -1.0                 # rotation > 0: counterclockwise
            sweep = ((a1 - a0) * sg) % (2 * math.pi)
            sweep = (2 * math.pi if sweep < 1e-9 else sweep) + 2 * math.pi * (abs(rot) - 1)
            n = max(1, math.ceil(sweep / math.radians(2.0) - 1e-9))
            dphi, dz = sweep / n, end[ax] - pos[ax]
            p = dz / sweep                                # axis travel per radian (helix)
            h = min(sweep, math.pi) / 2
            grow = 0.0 if o.junction == "spec" else P * (1 + math.cos(h)) / (2 * math.sin(h / 2) ** 2)

            def at(j):
                phi, r = a0 + sg * j * dphi, r0 + (r1 - r0) * j / n
                q, t = [0.0] * 3, [0.0] * 3
                q[f], q[s_], q[ax] = c1 + r * math.cos(phi), c2 + r * math.sin(phi), pos[ax] + dz * j / n
                t[f], t[s_], t[ax] = -sg * r * math.sin(phi), sg * r * math.cos(phi), p
                return q, unit(t), r

            q0, t0, _ = at(0)
            for j in range(n):
                q1, t1, r = at(j + 1)
                rm = 0.5 * (r + r0 + (r1 - r0) * j / n)
                L = math.sqrt((rm * dphi) ** 2 + ((r1 - r0) / n) ** 2 + (dz / n) ** 2)
                lo, hi = sorted((a0 + sg * j * dphi, a0 + sg * (j + 1) * dphi))
                w = rm / math.hypot(rm, p)                # in-plane share of the tangent
                umin, umax = [abs(p) / math.hypot(rm, p)] * 3, [abs(p) / math.hypot(rm, p)] * 3
                for i, z, pk in ((f, 0.0, math.pi / 2), (s_, math.pi / 2, 0.0)):  # |sin|, |cos|
                    ends = (abs(t0[i]), abs(t1[i]))
                    umin[i] = 0.0 if hits(z, lo, hi) else min(ends)
                    umax[i] = w if hits(pk, lo, hi) else max(ends)
                vc, a_t = caps(umin, umax, True)
                R = (rm * rm + p * p) / rm if rm > 1e-12 else 0.0   # curvature radius of a helix
                vc = min(vc, feed if feed > 0 else INF, math.sqrt(an * (R + grow)))
                if L > 1e-12:
                    pieces.append([L, vc, a_t, unit([b - c for b, c in zip(q1, q0)]), t0, t1, mid,
                                   sweep * math.hypot(rm, p)])
                q0, t0 = q1, t1
            mid += 1
            pos = end
    return pieces, stops, dwell, an, P, notes


def junction(th, L0, L1, an, P, mode):
    if mode == "none":
        return INF
    if mode == "tube":
        th -= math.asin(min(1.0, 2 * P / L0)) + math.asin(min(1.0, 2 * P / L1))
    if th < 1e-9:
        return INF
    c, one_c = math.cos(th / 2), 2 * math.sin(th / 4) ** 2        # 1 - c without cancellation
    return math.sqrt(an * (P * (1 + c) if mode == "spec" else 2 * P) / one_c)


def piece_time(L, vc, a, v0, v1):
    vp2 = (v0 * v0 + v1 * v1) / 2 + a * L            # where the two ramps meet
    if vp2 <= vc * vc:
        vp = max(math.sqrt(vp2), v0, v1)
        return (2 * vp - v0 - v1) / a
    return (2 * vc - v0 - v1) / a + (L - (2 * vc * vc - v0 * v0 - v1 * v1) / (2 * a)) / vc


def bound(pieces, stops, dwell, an, P, o):
    n, L = len(pieces), [pc[0] for pc in pieces]
    vb = [INF] * (n + 1)
    for b in range(n + 1):
        if b == 0 or b == n:
            vb[b] = 0.0
            continue
        p0, p1 = pieces[b - 1], pieces[b]
        if p0[6] != p1[6]:                            # corner between two moves
            vb[b] = junction(angle(p0[5], p1[4]), p0[7], p1[7], an, P, o.junction)
        vb[b] = 0.0 if b in stops else min(vb[b], p0[1], p1[1])
        if not o.no_cut:                              # corner cutting within P of the vertex
            cut = P * math.sin(angle(p0[3], p1[3]) / 2)
            L[b - 1], L[b] = L[b - 1] - cut, L[b] - cut
    L = [max(0.0, x) for x in L]
    for b in range(n - 1, -1, -1):
        vb[b] = min(vb[b], math.sqrt(vb[b + 1] ** 2 + 2 * pieces[b][2] * L[b]))
    for b in range(n):
        vb[b + 1] = min(vb[b + 1], math.sqrt(vb[b] ** 2 + 2 * pieces[b][2] * L[b]))
    t = sum(piece_time(L[b], pieces[b][1], pieces[b][2], vb[b], vb[b + 1]) for b in range(n))
    t += sum(s for b, s in dwell.items() if 0 < b < n)
    return t, sum(pc[0] for pc in pieces)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("programs_args", nargs="*", metavar="PROGRAM")
    ap.add_argument("--programs", default=os.path.join(TPC, "linuxcnc", "programs.txt"))
    ap.add_argument("--config", default=os.path.join(TPC, "contourd.yaml"))
    ap.add_argument("--results", default=os.path.join(TPC, "results.json"))
    ap.add_argument("--tolerance-um", type=float, default=50.0)
    ap.add_argument("--junction", choices=("tube", "spec", "none"), default="tube")
    ap.add_argument("--no-cut", action="store_true", help="no corner-cutting length reduction")
    ap.add_argument("--rs274", default="rs274")
    ap.add_argument("--tool-table", default=os.path.join(TPC, "linuxcnc", "tp.tbl"))
    ap.add_argument("--json", metavar="OUT")
    o = ap.parse_args()
    cfg = yaml.safe_load(open(o.config))
    axes = {ax["name"].upper(): ax for ax in cfg["machine"]["axes"]}
    lim = {"vmax": [axes[n]["max_velocity_mm_min"] / 60.0 for n in "XYZ"],
           "acc": [float(axes[n]["max_accel_mm_s2"]) for n in "XYZ"],
           "rapid": cfg["program"]["rapid_mm_min"] / 60.0}
    progs = o.programs_args or [ln.strip() for ln in open(o.programs) if ln.strip()]
    res = {r["name"]: r for r in json.load(open(o.results))["programs"]} if os.path.exists(
        o.results) else {}
    rows = []
    hdr = "%-42s %9s %8s %9s %7s %9s %7s  %s" % ("program", "path mm", "bound s", "LinuxCNC",
                                                 "LC/b", "contourd", "cd/b", "notes")
    print(hdr + "\n" + "-" * len(hdr))
    for prog in progs:
        name = os.path.splitext(os.path.basename(prog))[0]
        try:
            pieces, stops, dwell, an, P, notes = path(canon(prog, o), lim, o)
        except (RuntimeError, subprocess.TimeoutExpired, ValueError, KeyError) as e:
            print("%-42s rs274/parse failed, skipped: %s" % (name, e))
            continue
        t, length = bound(pieces, stops, dwell, an, P, o)
        lc, cd = ((res.get(name, {}).get(k) or {}).get("time_s") for k in ("linuxcnc", "contourd"))
        row = {"name": name, "program": prog, "path_mm": length, "bound_s": t, "linuxcnc_s": lc,
               "contourd_s": cd, "lc_over_bound": lc / t if lc and t > 0 else None,
               "cd_over_bound": cd / t if cd and t > 0 else None, "notes": sorted(notes)}
        rows.append(row)
        f = lambda v, fmt="%.3f": fmt % v if v is not None else "-"
        print("%-42s %9.1f %8.3f %9s %7s %9s %7s  %s" % (name[:42], length, t, f(lc), f(
            row["lc_over_bound"]), f(cd), f(row["cd_over_bound"]), ", ".join(sorted(notes))))
    both = [r for r in rows if r["lc_over_bound"] and r["cd_over_bound"]]
    print("\njunction model %s, corner cutting %s, P = %g um; %d programs" % (
        o.junction, "off" if o.no_cut else "on", o.tolerance_um, len(rows)))
    if both:
        tb, tl, tc = (sum(r[k] for r in both) for k in ("bound_s", "linuxcnc_s", "contourd_s"))
        print("median LinuxCNC/bound %.3f, median contourd/bound %.3f; totals: bound %.1f s, "
              "LinuxCNC %.1f s (%.3f), contourd %.1f s (%.3f)" % (
                  statistics.median(r["lc_over_bound"] for r in both),
                  statistics.median(r["cd_over_bound"] for r in both), tb, tl, tl / tb, tc, tc / tb))
        ok = [r["name"] for r in both if r["lc_over_bound"] >= 1 / 0.90]
        print("LinuxCNC/bound < 1/0.90 = %.3f (0.90x LinuxCNC impossible): %d of %d; possible only "
              "on: %s" % (1 / 0.90, len(both) - len(ok), len(both), ", ".join(ok) or "none"))
    if o.json:
        json.dump({"junction": o.junction, "cut": not o.no_cut, "tolerance_um": o.tolerance_um,
                   "limits": lim, "rows": rows}, open(o.json, "w"), indent=1)


if __name__ == "__main__":
    sys.exit(main())
