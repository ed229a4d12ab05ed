#!/usr/bin/python3
"""Headless [DISPLAY] of tools/bench/tp_compare.sh's LinuxCNC: homes, then for each program of
$TPC_LIST (one path a line) moves to X0 Y0 Z0 by MDI, sets the HAL signal tpc-prog to the program's
index (recorded by the sampler beside X Y Z), runs the program in AUTO mode and waits for the end.
halsampler writes every servo period to $TPC_SAMPLES; $TPC_STATUS gets one line per program:
`index ok|error text`. Started by `linuxcnc tp.ini` as `driver.py -ini tp.ini`.
"""
import os
import signal
import subprocess
import sys
import time

import linuxcnc

TIMEOUT_S = float(os.environ.get("TPC_TIMEOUT_S", "900"))
s = linuxcnc.stat()
c = linuxcnc.command()
e = linuxcnc.error_channel()
status = open(os.environ["TPC_STATUS"], "w", buffering=1)
errors = []


def poll_errors():
    while True:
        m = e.poll()
        if not m:
            return
        kind, text = m
        if kind in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
            errors.append(text.replace("\n", " "))
        print("driver.py: linuxcnc: %s" % text, file=sys.stderr)


def wait_for(cond, timeout_s, what):
    t0 = time.time()
    while True:
        s.poll()
        poll_errors()
        if cond():
            return True
        if time.time() - t0 > timeout_s:
            print("driver.py: timeout waiting for %s" % what, file=sys.stderr)
            return False
        time.sleep(0.01)


def hal_sets(value):
    subprocess.run(["halcmd", "sets", "tpc-prog", str(value)], check=True)


def mdi(cmd):
    c.mode(linuxcnc.MODE_MDI)
    c.wait_complete()
    c.mdi(cmd)
    c.wait_complete()
    return wait_for(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0 and
                    s.current_vel == 0.0, 60, cmd)


def finished_or_resume():
    # M0/M1 (CAM posts put them at tool changes) pause the program; an operator would press resume.
    if s.paused or s.interp_state == linuxcnc.INTERP_PAUSED:
        c.auto(linuxcnc.AUTO_RESUME)
        return False
    return s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0


def main():
    wait_for(lambda: True, 10, "stat")
    c.state(linuxcnc.STATE_ESTOP_RESET)
    c.wait_complete()
    c.state(linuxcnc.STATE_ON)
    c.wait_complete()
    c.mode(linuxcnc.MODE_MANUAL)
    c.wait_complete()
    c.teleop_enable(0)
    c.wait_complete()
    c.home(-1)
    if not wait_for(lambda: all(s.homed[i] for i in range(3)), 30, "homing"):
        status.write("-1 error homing failed\n")
        return 1
    hal_sets(-1)
    sampler = subprocess.Popen(["halsampler", "-c", "0", "-t"],
                               stdout=open(os.environ["TPC_SAMPLES"], "w"))
    programs = [l.strip() for l in open(os.environ["TPC_LIST"]) if l.strip()]
    for i, path in enumerate(programs):
        del errors[:]
        # Each program starts like contour-sim's: at X0 Y0 Z0, no offsets left by the one before.
        if not (mdi("G92.1") and mdi("G10 L2 P1 X0 Y0 Z0 R0") and mdi("G54 G21 G90 G40 G49") and
                mdi("G53 G0 X0 Y0 Z0")):
            status.write("%d error cannot return to X0 Y0 Z0: %s\n" % (i, "; ".join(errors)))
            c.abort()
            continue
        time.sleep(0.05)
        hal_sets(i)
        time.sleep(0.05)
        c.mode(linuxcnc.MODE_AUTO)
        c.wait_complete()
        c.program_open(path)
        c.wait_complete()
        c.auto(linuxcnc.AUTO_RUN, 0)
        started = wait_for(lambda: s.interp_state != linuxcnc.INTERP_IDLE, 10, "program start")
        done = started and wait_for(finished_or_resume, TIMEOUT_S, path)
        time.sleep(0.1)
        hal_sets(-1)
        time.sleep(0.05)
        poll_errors()
        if not done or errors:
            status.write("%d error %s\n" % (i, "; ".join(errors) or "timeout"))
            c.abort()
            c.wait_complete()
        else:
            status.write("%d ok\n" % i)
        if s.task_state != linuxcnc.STATE_ON:
            c.state(linuxcnc.STATE_ESTOP_RESET)
            c.state(linuxcnc.STATE_ON)
            c.wait_complete()
    time.sleep(0.5)
    sampler.send_signal(signal.SIGINT)
    sampler.wait(timeout=10)
    c.state(linuxcnc.STATE_OFF)
    return 0


if __name__ == "__main__":
    try:
        rc = main()
    except Exception as ex:  # reported, then LinuxCNC shuts down when we exit
        status.write("-1 error driver: %s\n" % ex)
        rc = 1
    sys.exit(rc)
