#!/usr/bin/python3
"""Reference side of contour-gcode-diff: runs LinuxCNC's own RS274/NGC interpreter (librs274, the
interpreter behind rs274 and AXIS's preview, through its Python module `gcode`) on one program and
prints every canonical call that moves the machine or changes what the moves mean, at full double
precision, one per line:

    <line> <CALL> <values...>

<line> is the interpreter's sequence number (the source line of the call). Lengths are converted to
mm (the module hands them over in inches); feeds in mm/min; angles in degrees; times in s.
Calls: TRAVERSE x y z | FEED x y z | ARC first_end second_end first_centre second_centre rotation
axis_end | PLANE n (1 XY, 2 YZ, 3 XZ) | FEEDRATE f | DWELL s | G5X index x y z | G92 x y z |
ROTATION deg | TLO x y z | TOOL pocket | USERM n p q | MESSAGE text.
The last line is `END <status> <line> <message>`: status 0 when the program ended normally.

Run by contour-gcode-diff with HOME set to a private scratch directory (LinuxCNC keeps its tool
table in $HOME/.tool.mmap) and with /usr/bin/python3 (Debian's, which has the module).
Usage: linuxcnc_ref.py --var FILE.var --tbl FILE.tbl [--ini FILE.ini] [--block-delete] PROGRAM
The .var and .tbl files are in mm (the module is told the machine is metric).
This script is test-only tooling: contourd never runs it.
"""
import argparse
import ctypes
import os
import sys

import gcode  # LinuxCNC's interpreter (package linuxcnc-uspace)

MM = 25.4


def read_tbl(path):
    """Tool table entries in file order, as LinuxCNC's non-random tool changer loads them
    (index 1..n); returns a list of 14-tuples for Canon.get_tool."""
    out = []
    with open(path) as f:
        for raw in f:
            line = raw.split(';', 1)[0].strip()
            if not line:
                continue
            t = dict(T=-1, D=0.0, X=0.0, Y=0.0, Z=0.0, A=0.0, B=0.0, C=0.0, U=0.0, V=0.0, W=0.0,
                     I=0.0, J=0.0, Q=0)
            for tok in line.split():
                k = tok[0].upper()
                if k in ('T', 'P', 'Q'):
                    t[k] = int(tok[1:])
                else:
                    t[k] = float(tok[1:])
            out.append((t['T'], t['X'], t['Y'], t['Z'], t['A'], t['B'], t['C'], t['U'], t['V'],
                        t['W'], t['D'], t['I'], t['J'], t['Q']))
    return out


EMPTY = (-1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0)


class Canon:
    def __init__(self, var, tools, block_delete):
        self.parameter_file = var
        self.tools = tools
        self.spindle = (0,) + EMPTY[1:]
        self.block_delete = block_delete
        self.line = 0
        self.out = []

    def emit(self, *fields):
        self.out.append(' '.join([str(self.line)] + [repr(f) if isinstance(f, float) else str(f)
                                                      for f in fields]))

    # Machine description asked by the interpreter.
    def get_external_length_units(self):
        return 1.0  # user units are mm (contourd's), so .var and .tbl values are mm

    def get_external_angular_units(self):
        return 1.0

    def get_axis_mask(self):
        return 7  # X Y Z: contourd's axes

    def get_tool(self, pocket):
        if pocket == 0:
            return self.spindle
        if 1 <= pocket <= len(self.tools):
            return self.tools[pocket - 1]
        return EMPTY

    def get_block_delete(self):
        return self.block_delete

    def check_abort(self):
        return False

    def next_line(self, linecode):
        self.line = linecode.sequence_number

    # Canonical calls that matter for the comparison.
    def straight_traverse(self, x, y, z, *rest):
        self.emit('TRAVERSE', x * MM, y * MM, z * MM)

    def straight_feed(self, x, y, z, *rest):
        self.emit('FEED', x * MM, y * MM, z * MM)

    def arc_feed(self, fe, se, fc, sc, rot, ae, *rest):
        self.emit('ARC', fe * MM, se * MM, fc * MM, sc * MM, rot, ae * MM)

    def set_plane(self, plane):
        self.emit('PLANE', plane)

    def set_feed_rate(self, f):
        self.emit('FEEDRATE', f * MM)

    def dwell(self, t):
        self.emit('DWELL', float(t))

    def set_g5x_offset(self, index, x, y, z, *rest):
        self.emit('G5X', index, x * MM, y * MM, z * MM)

    def set_g92_offset(self, x, y, z, *rest):
        self.emit('G92', x * MM, y * MM, z * MM)

    def set_xy_rotation(self, t):
        self.emit('ROTATION', float(t))

    def tool_offset(self, x, y, z, *rest):
        self.emit('TLO', x * MM, y * MM, z * MM)

    def change_tool(self, pocket):
        if pocket > 0:
            self.spindle = self.get_tool(pocket)
        self.emit('TOOL', pocket)

    def user_defined_function(self, num, p, q):
        self.emit('USERM', num + 100, float(p), float(q))

    def message(self, text):
        self.emit('MESSAGE', text.replace('\n', ' '))

    # Calls without effect on the comparison.
    def comment(self, text):
        pass

    def set_feed_mode(self, mode):
        pass

    def set_traverse_rate(self, rate):
        pass

    def straight_probe(self, *a):
        self.emit('PROBE')

    def rigid_tap(self, *a):
        self.emit('RIGIDTAP')


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--var', required=True)
    ap.add_argument('--tbl', required=True)
    ap.add_argument('--block-delete', action='store_true')
    ap.add_argument('program')
    a = ap.parse_args()
    # The interpreter looks tools up in LinuxCNC's shared tool table ($HOME/.tool.mmap): create it
    # in this process, as the rs274 driver does, and load the same .tbl into it.
    lib = ctypes.CDLL('libtooldata.so.0')
    lib._Z17tool_mmap_creatorPK13EMC_TOOL_STATi(None, 0)
    lib._Z13tooldata_initb(ctypes.c_bool(False))
    if lib._Z13tooldata_loadPKcPPc(a.tbl.encode(), None) != 0:
        print('END -1 0 cannot load tool table ' + a.tbl)
        return 2
    canon = Canon(a.var, read_tbl(a.tbl), a.block_delete)
    # G21: contourd's programs start in mm. F0: rs274 and a real machine start with feed 0 (the
    # module alone would start at 1, accepting a G1 before any F word).
    result, line = gcode.parse(a.program, canon, 'G21', 'F0')
    canon.out = [l for l in canon.out if not l.startswith('0 FEEDRATE')]
    for l in canon.out:
        print(l)
    status = 0 if result <= gcode.MIN_ERROR else result
    msg = gcode.strerror(result).replace('\n', ' ') if status else ''
    print('END %d %d %s' % (status, line, msg))
    return 0


if __name__ == '__main__':
    sys.exit(main())
