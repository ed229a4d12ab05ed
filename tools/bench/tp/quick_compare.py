#!/usr/bin/python3
"""Quick loop for planner work (issue 23): runs `contour-sim blend` on the tp_compare program list
with one or more --method values and prints, per program, contour-sim's duration_s / LinuxCNC's
recorded time (from an earlier tp_compare.sh results.json), path / vertex error and peak 10-ms
acceleration / limit. A benchmark helper: asserts nothing; tp_compare.sh stays the reference.

Usage: quick_compare.py --sim BIN --results RESULTS.json [--config YAML] [--methods true,lookahead]
                        [--jobs N] [--only NAME,...]
"""
import argparse
import concurrent.futures as cf
import json
import os
import statistics
import subprocess
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))


def run(sim, prog, method, config, tol_um):
    cmd = [sim, "blend", "--program", prog, "--mode", "limited", "--tolerance-um", "%g" % tol_um,
           "--config", config, "--method", method, "--max-corners", "0"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    for line in reversed(r.stdout.strip().splitlines()):
        if line.strip().startswith("{"):
            j = json.loads(line)
            j["exit"] = r.returncode
            return j
    return {"error": (r.stderr or r.stdout)[-300:], "exit": r.returncode}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sim", default=os.path.join(ROOT, "build/ci/tools/contour-sim"))
    ap.add_argument("--results", required=True, help="results.json of a tp_compare.sh run")
    ap.add_argument("--config", default=os.path.join(ROOT, "tools/bench/tp/contourd.yaml"))
    ap.add_argument("--methods", default="true,lookahead")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", default="")
    o = ap.parse_args()
    res = json.load(open(o.results))
    tol = res.get("tolerance_um", 50)
    lim = res.get("max_accel_mm_s2", [2000, 2000, 2000])
    progs = []
    for p in res["programs"]:
        if "linuxcnc" not in p or not p["linuxcnc"].get("time_s"):
            continue
        name = p["name"]
        if o.only and name not in o.only.split(","):
            continue
        path = p["program"]
        # results.json holds paths relative to the run's cwd, possibly another worktree: map them
        # onto this tree by their tests/... suffix.
        k = path.find("tests/")
        local = os.path.join(ROOT, path[k:]) if k >= 0 else path
        progs.append((name, local, p["linuxcnc"]["time_s"]))
    methods = o.methods.split(",")
    jobs = {}
    with cf.ThreadPoolExecutor(o.jobs) as ex:
        for name, path, _ in progs:
            for m in methods:
                jobs[(name, m)] = ex.submit(run, o.sim, path, m, o.config, tol)
    hdr = "%-42s" % "program" + "".join(" | %-9s %6s %5s %5s %4s" % (m[:9], "ratio", "path", "vert", "acc") for m in methods)
    print(hdr)
    ratios = {m: [] for m in methods}
    bad = []
    for name, _, lc in progs:
        row = "%-42s" % name[:42]
        for m in methods:
            j = jobs[(name, m)].result()
            if "error" in j:
                row += " | %-9s %6s %5s %5s %4s" % ("ERR", "-", "-", "-", "-")
                bad.append((name, m, j["error"]))
                continue
            r = j["duration_s"] / lc
            ratios[m].append((r, name))
            acc = max(a / l for a, l in zip(j["peak_accel_10ms_mm_s2"], lim))
            flag = "" if (j["exit"] == 0 and j["max_path_error_um"] <= tol and
                          j["max_vertex_error_um"] <= tol and acc <= 1.0) else "!"
            row += " | %9.3f %6.3f %5.1f %5.1f %4.2f%s" % (j["duration_s"], r, j["max_path_error_um"],
                                                       j["max_vertex_error_um"], acc, flag)
        print(row)
    for m in methods:
        rs = ratios[m]
        if rs:
            print("%s: median %.3f worst %.3f (%s) best %.3f  n=%d" % (
                m, statistics.median(r for r, _ in rs), max(rs)[0], max(rs)[1], min(rs)[0], len(rs)))
    for b in bad:
        print("error:", b, file=sys.stderr)


if __name__ == "__main__":
    main()
