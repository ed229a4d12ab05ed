#!/usr/bin/python3
"""Second half of tools/bench/tp_compare.sh: plans every program with contour-sim, cuts LinuxCNC's
halsampler recording into programs, measures both against the programmed path with the same meter
(`contour-sim blend --measure`, control/path_meter.hpp: path error at and between samples, vertex
error, per-axis acceleration averaged over 10 ms), prints the table and the summary, writes
summary.md, results.json and per-program plots into the output folder.

Usage: analyse.py --out DIR --contour-sim BIN --config YAML --tolerance-um UM [--method M]
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys

import numpy as np
import yaml

MOVE_EPS_MM = 1e-7  # a sample "moves" when any axis changes by more than this (halsampler: 1e-6 digits)


def motion_span(p):
    """Index of the first sample that moved from p[0] and of the last that moved, or None."""
    d = np.abs(np.diff(p, axis=0)).max(axis=1) > MOVE_EPS_MM
    idx = np.nonzero(d)[0]
    if len(idx) == 0:
        return None
    return idx[0], idx[-1] + 1  # p[idx[0]] is the last still sample, p[idx[-1] + 1] the last moved


def acc10(p, period_s, n=10):
    """Cross-check of the meter: per-axis peak of (v[k+n] - v[k]) / (n T), v the 1-period difference."""
    if len(p) < n + 2:
        return [0.0, 0.0, 0.0]
    v = np.diff(p, axis=0) / period_s
    return (np.abs(v[n:] - v[:-n]).max(axis=0) / (n * period_s)).tolist()


def last_json(text):
    for line in reversed(text.strip().splitlines()):
        line = line.strip()
        if line.startswith("{"):
            return json.loads(line)
    return None


def programmed_path(path):
    """Programmed path for the plots only (the figures come from contour-sim's meter): G0-G3 in
    G17, G20/G21, G90/G91; arcs with I J; anything else is ignored."""
    pts = [(0.0, 0.0, 0.0)]
    verts = []
    scale, absolute, motion = 1.0, True, 0
    pos = [0.0, 0.0, 0.0]
    for raw in open(path, errors="replace"):
        line = re.sub(r"\([^)]*\)", "", raw.split(";")[0]).upper()
        words = re.findall(r"([A-Z])\s*([-+]?\d*\.?\d+)", line)
        target = list(pos)
        ij = [0.0, 0.0]
        has_xyz = False
        for w, v in words:
            v = float(v)
            if w == "G":
                if v in (0, 1, 2, 3):
                    motion = int(v)
                elif v == 20:
                    scale = 25.4
                elif v == 21:
                    scale = 1.0
                elif v == 90:
                    absolute = True
                elif v == 91:
                    absolute = False
            elif w in "XYZ":
                k = "XYZ".index(w)
                target[k] = v * scale if absolute else target[k] + v * scale
                has_xyz = True
            elif w in "IJ":
                ij["IJ".index(w)] = v * scale
        if not has_xyz:
            continue
        if motion in (2, 3) and (ij[0] or ij[1]):
            cx, cy = pos[0] + ij[0], pos[1] + ij[1]
            r = math.hypot(pos[0] - cx, pos[1] - cy)
            a0 = math.atan2(pos[1] - cy, pos[0] - cx)
            a1 = math.atan2(target[1] - cy, target[0] - cx)
            if motion == 2:
                while a1 >= a0 - 1e-12:
                    a1 -= 2 * math.pi
            else:
                while a1 <= a0 + 1e-12:
                    a1 += 2 * math.pi
            n = max(2, int(abs(a1 - a0) * r / 0.05))
            for k in range(1, n + 1):
                a = a0 + (a1 - a0) * k / n
                pts.append((cx + r * math.cos(a), cy + r * math.sin(a), pos[2] + (target[2] - pos[2]) * k / n))
        else:
            pts.append(tuple(target))
        verts.append(tuple(target))
        pos = target
    return np.array(pts), np.array(verts) if verts else np.zeros((0, 3))


def plot(name, out_png, prog, lc_p, cd_p, period_s, center, title, tol_um):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ref, verts = programmed_path(prog)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(14, 6))
    half = max(0.2, 6e-3 * tol_um)  # mm around the worst vertex: the tolerance stays visible
    def near(p):
        return np.all(np.abs(p - center) <= half, axis=1) if len(p) else np.zeros(0, bool)
    both = np.vstack([q[near(q)] for q in (lc_p, cd_p, ref) if len(q)] + [center[None, :]])
    ext = both.max(axis=0) - both.min(axis=0)
    a, b = np.argsort(ext)[::-1][:2]
    a, b = sorted((a, b))
    lab = "XYZ"
    def seg(p):
        m = near(p).astype(float)
        p = p.copy()
        p[m == 0] = np.nan  # gaps where the path leaves the window
        return p
    for p, st, lb in ((lc_p, "r.-", "LinuxCNC 2.9"), (cd_p, "b.-", "contourd")):
        q = seg(p)
        ax1.plot(q[:, a], q[:, b], st, ms=2, lw=0.7, label=lb + " (1 ms samples)")
    # programmed segments whose bounding box meets the window (the axes clip them)
    lo, hi = np.minimum(ref[:-1], ref[1:]), np.maximum(ref[:-1], ref[1:])
    hit = np.nonzero(np.all((hi >= center - half) & (lo <= center + half), axis=1))[0]
    r = np.full((3 * len(hit), 3), np.nan)
    r[0::3], r[1::3] = ref[hit], ref[hit + 1]
    ax1.plot(r[:, a], r[:, b], "k--", lw=1, label="programmed", zorder=5)
    ax1.plot([center[a]], [center[b]], "ko", mfc="none", ms=10)
    ax1.set_xlim(center[a] - half, center[a] + half)
    ax1.set_ylim(center[b] - half, center[b] + half)
    ax1.set_aspect("equal")
    ax1.set_xlabel(lab[a] + " mm")
    ax1.set_ylabel(lab[b] + " mm")
    ax1.set_title("near the worst vertex (%s)" % ", ".join("%.3f" % c for c in center))
    ax1.legend(loc="best", fontsize=8)
    for p, st, lb in ((lc_p, "r-", "LinuxCNC 2.9"), (cd_p, "b-", "contourd")):
        v = np.linalg.norm(np.diff(p, axis=0), axis=1) / period_s * 60.0
        t = np.arange(len(v)) * period_s
        step = max(1, len(v) // 40000)
        ax2.plot(t[::step], v[::step], st, lw=0.6, label=lb)
    ax2.set_xlabel("t s")
    ax2.set_ylabel("path speed mm/min")
    ax2.set_title("velocity profiles")
    ax2.legend(loc="best", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--contour-sim", required=True)
    ap.add_argument("--config", required=True)
    ap.add_argument("--tolerance-um", type=float, required=True)
    ap.add_argument("--method", default="true")
    ap.add_argument("--no-plots", action="store_true")
    o = ap.parse_args()
    cfg = yaml.safe_load(open(o.config))
    period_s = cfg.get("loop", {}).get("period_us", 1000) * 1e-6
    amax = [a["max_accel_mm_s2"] for a in cfg["machine"]["axes"]]
    tol = o.tolerance_um
    programs = [l.strip() for l in open(os.path.join(o.out, "programs.txt")) if l.strip()]
    status = {}
    for l in open(os.path.join(o.out, "linuxcnc", "status.txt")):
        k, _, rest = l.strip().partition(" ")
        status[int(k)] = rest
    raw = np.loadtxt(os.path.join(o.out, "linuxcnc", "samples.txt"), ndmin=2)
    n = raw[:, 0].astype(np.int64)
    gaps = int(np.count_nonzero(np.diff(n) != 1))
    for d in ("contourd", "linuxcnc_traj", "plots"):
        os.makedirs(os.path.join(o.out, d), exist_ok=True)
    common = ["--mode", "limited", "--tolerance-um", "%g" % tol, "--config", o.config,
              "--method", o.method, "--max-corners", "0"]
    rows = []
    for i, prog in enumerate(programs):
        name = os.path.splitext(os.path.basename(prog))[0]
        tag = "%02d_%s" % (i, name)
        row = {"program": os.path.relpath(prog), "name": name}
        # contourd
        csv = os.path.join(o.out, "contourd", tag + ".csv")
        r = subprocess.run([o.contour_sim, "blend", "--program", prog, "--csv", csv] + common,
                           capture_output=True, text=True)
        j = last_json(r.stdout)
        row["contourd_exit"] = r.returncode
        cd_p = None
        if j and "error" not in j:
            c = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(1, 2, 3), ndmin=2)
            cd_p = np.vstack([np.zeros((1, 3)), c])  # contour-sim starts at X0 Y0 Z0
            span = motion_span(cd_p)
            row["contourd"] = {"time_s": (span[1] - span[0]) * period_s if span else 0.0,
                               "motion_s": j["motion_s"],
                               "path_err_um": j["max_path_error_um"],
                               "vertex_err_um": j["max_vertex_error_um"],
                               "acc10_mm_s2": j["peak_accel_10ms_mm_s2"],
                               "worst_vertex": j.get("worst_vertex")}
            if span:
                cd_p = cd_p[span[0]:span[1] + 1]
            row["contourd"]["acc10_check_mm_s2"] = acc10(cd_p, period_s)
        else:
            row["contourd_error"] = (j or {}).get("error", r.stderr.strip()[-300:])
        # LinuxCNC
        lc_p = None
        st = status.get(i, "missing (LinuxCNC did not get to it)")
        row["linuxcnc_status"] = st
        sel = np.nonzero(raw[:, 4] == i)[0]
        if st == "ok" and len(sel):
            breaks = np.nonzero(np.diff(sel) != 1)[0]
            sel = sel[breaks[-1] + 1:] if len(breaks) else sel  # the last contiguous run
            p = raw[sel, 1:4]
            span = motion_span(p)
            if not span:
                row["linuxcnc_error"] = "reported ok but no motion recorded"
            if span:
                lc_p = p[span[0]:span[1] + 1]
                traj = os.path.join(o.out, "linuxcnc_traj", tag + ".xyz")
                np.savetxt(traj, lc_p[1:], fmt="%.6f")
                r = subprocess.run([o.contour_sim, "blend", "--program", prog, "--measure", traj] + common,
                                   capture_output=True, text=True)
                j = last_json(r.stdout)
                if j and "error" not in j:
                    row["linuxcnc"] = {"time_s": (span[1] - span[0]) * period_s,
                                       "path_err_um": j["max_path_error_um"],
                                       "vertex_err_um": j["max_vertex_error_um"],
                                       "acc10_mm_s2": j["peak_accel_10ms_mm_s2"],
                                       "worst_vertex": j.get("worst_vertex"),
                                       "acc10_check_mm_s2": acc10(lc_p, period_s),
                                       "start_mm": p[0].tolist()}
                else:
                    row["linuxcnc_error"] = (j or {}).get("error", r.stderr.strip()[-300:])
        if "contourd" in row and "linuxcnc" in row and row["linuxcnc"]["time_s"] > 0:
            row["ratio"] = row["contourd"]["time_s"] / row["linuxcnc"]["time_s"]
            if not o.no_plots and cd_p is not None and lc_p is not None:
                w = max(("contourd", "linuxcnc"), key=lambda k: row[k]["vertex_err_um"])
                center = np.array(row[w]["worst_vertex"] or [0, 0, 0], dtype=float)
                try:
                    plot(name, os.path.join(o.out, "plots", tag + ".png"), prog, lc_p, cd_p, period_s,
                         center, "%s: contourd %.3f s, LinuxCNC %.3f s (ratio %.2f); worst vertex of %s"
                         % (name, row["contourd"]["time_s"], row["linuxcnc"]["time_s"], row["ratio"], w), tol)
                except Exception as ex:  # a plot failing does not lose the figures
                    print("analyse.py: %s: plot failed: %s" % (name, ex), file=sys.stderr)
        rows.append(row)
        print_row(row, tol, amax)
    summary(rows, tol, amax, gaps, o)


def within(row, k, tol):
    return row[k]["path_err_um"] <= tol and row[k]["vertex_err_um"] <= tol


def acc_ratio(row, k, amax):
    return max(a / l for a, l in zip(row[k]["acc10_mm_s2"], amax))


HDR = ("| program | contourd s | LinuxCNC s | ratio | path err µm cd / lc | vertex err µm cd / lc "
       "| peak acc 10 ms X,Y,Z mm/s² cd | LinuxCNC |")


def fmt_row(row, tol, amax):
    cd, lc = row.get("contourd"), row.get("linuxcnc")
    def acc(k):
        return ",".join("%.0f" % a for a in row[k]["acc10_mm_s2"]) if row.get(k) else "-"
    def err(key):
        return "%s / %s" % ("%.1f" % cd[key] if cd else "-", "%.1f" % lc[key] if lc else "-")
    note = ""
    if not cd:
        note += " contourd: " + row.get("contourd_error", "?")
    elif row["contourd_exit"] != 0:
        note += " (contour-sim exit %d)" % row["contourd_exit"]
    if not lc:
        note += " LinuxCNC: " + row.get("linuxcnc_error", row["linuxcnc_status"])
    return "| %s%s | %s | %s | %s | %s | %s | %s | %s |" % (
        row["name"], note, "%.3f" % cd["time_s"] if cd else "-", "%.3f" % lc["time_s"] if lc else "-",
        "%.2f" % row["ratio"] if "ratio" in row else "-", err("path_err_um"), err("vertex_err_um"),
        acc("contourd"), acc("linuxcnc"))


printed = [False]


def print_row(row, tol, amax):
    if not printed[0]:
        print(HDR)
        print("|" + "---|" * 8)
        printed[0] = True
    print(fmt_row(row, tol, amax), flush=True)


def summary(rows, tol, amax, gaps, o):
    both = [r for r in rows if "ratio" in r]
    ratios = np.array([r["ratio"] for r in both])
    lines = []
    lines.append("Programs: %d listed, %d run by both planners; limits X,Y,Z %s mm/s², tolerance %g µm; "
                 "LinuxCNC servo-period gaps in the recording: %d"
                 % (len(rows), len(both), ",".join("%g" % a for a in amax), tol, gaps))
    if len(both):
        worst = both[int(np.argmax(ratios))]
        best = both[int(np.argmin(ratios))]
        lines.append("Time contourd / LinuxCNC: median %.2f, worst %.2f (%s), best %.2f (%s); total %.1f s / %.1f s"
                     % (float(np.median(ratios)), worst["ratio"], worst["name"], best["ratio"], best["name"],
                        sum(r["contourd"]["time_s"] for r in both), sum(r["linuxcnc"]["time_s"] for r in both)))
        for k, lab in (("contourd", "contourd"), ("linuxcnc", "LinuxCNC")):
            pe = max(r[k]["path_err_um"] for r in both)
            ve = max(r[k]["vertex_err_um"] for r in both)
            win = sum(within(r, k, tol) for r in both)
            ar = [acc_ratio(r, k, amax) for r in both]
            aw = sum(a <= 1.0 + 1e-3 for a in ar)
            dev = max(abs(x - y) for r in both for x, y in zip(r[k]["acc10_mm_s2"], r[k]["acc10_check_mm_s2"]))
            lines.append("%s: the meter's 10-ms acceleration and analyse.py's own differences of the "
                         "samples agree within %.1f mm/s²" % (lab, dev))
            lines.append("%s: within %g µm (path and vertex) %d/%d, worst path error %.1f µm, worst vertex error "
                         "%.1f µm; 10-ms acceleration within the axis limit %d/%d, worst %.2fx the limit"
                         % (lab, tol, win, len(both), pe, ve, aw, len(both), max(ar)))
    print()
    for l in lines:
        print(l)
    with open(os.path.join(o.out, "summary.md"), "w") as f:
        f.write(HDR + "\n|" + "---|" * 8 + "\n")
        for r in rows:
            f.write(fmt_row(r, tol, amax) + "\n")
        f.write("\n" + "\n\n".join(lines) + "\n")
    with open(os.path.join(o.out, "results.json"), "w") as f:
        json.dump({"tolerance_um": tol, "max_accel_mm_s2": amax, "sample_gaps": gaps, "programs": rows}, f, indent=1)
    print("\ntp_compare: %s/summary.md, results.json, plots/" % o.out)


if __name__ == "__main__":
    main()
