#!/usr/bin/env python3
"""Talk to `activesense geocom-sim` with clients that are not ours (docs/GEOCOM.md).

1. Raw sockets, byte strings written from the GeoCOM Reference Manual's syntax
   (TPS1200/TS30/TM30 v1.50, section 2.3), no code of ours.
2. GeoComPy (pip install geocompy), without and with its CRC-16 checksum option.

Usage: python3 independent_client.py PATH/TO/activesense PLAN.json
Prints every exchange and exits non-zero on the first mismatch.
"""
import re
import socket
import subprocess
import sys
import math

exe, plan = sys.argv[1], sys.argv[2]
sim = subprocess.Popen(
    [exe, "geocom-sim", "--plan", plan, "--listen", "tcp:127.0.0.1:0", "--edm-ms", "0"],
    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
line = sim.stdout.readline()
port = int(re.search(r"tcp:127\.0\.0\.1:(\d+)", line).group(1))
print("simulator:", line.strip())

import atexit
atexit.register(sim.kill)
fail = 0
def check(cond, what):
    global fail
    print(("ok   " if cond else "FAIL ") + what)
    fail += 0 if cond else 1

# --- 1. raw sockets, following the manual --------------------------------------------
s = socket.create_connection(("127.0.0.1", port), timeout=5)
f = s.makefile("rwb")
def ask(req):
    f.write(b"\n" + req.encode() + b"\r\n"); f.flush()
    rep = f.readline().decode().rstrip("\r\n")
    print("   ", req, "->", rep)
    return rep

r = ask("%R1Q,0:")                       # COM_NullProc, no transaction id
check(r == "%R1P,0,0:0", "COM_NullProc without TrId answers %R1P,0,0:0")
r = ask("%R1Q,5004,7:")                  # CSV_GetInstrumentName, TrId 7
check(re.fullmatch(r'%R1P,0,7:0,"[^"]*"', r) is not None, "CSV_GetInstrumentName: quoted string, TrId echoed")
r = ask("%R1Q,17021,1:1")                # BAP_SetTargetType(BAP_REFL_LESS)
check(r == "%R1P,0,1:0", "BAP_SetTargetType reflectorless")
r = ask("%R1Q,9027,2:1.0,1.5707963267948966,0,0,0")  # AUT_MakePositioning
check(r == "%R1P,0,2:0", "AUT_MakePositioning")
r = ask("%R1Q,2107,3:1")                 # TMC_GetAngle5
hz, v = map(float, r.split(":")[1].split(",")[1:3])
check(abs(hz - 1.0) < 1e-9 and abs(v - math.pi / 2) < 1e-9, "TMC_GetAngle5 reads the positioned Hz, V (rad)")
r = ask("%R1Q,2008,4:1,1")               # TMC_DoMeasure(TMC_DEF_DIST, TMC_AUTO_INC)
check(r == "%R1P,0,4:0", "TMC_DoMeasure")
r = ask("%R1Q,2108,5:5000,1")            # TMC_GetSimpleMea
rc, *vals = r.split(":")[1].split(",")
check(rc in ("0", "1292") and len(vals) == 3, "TMC_GetSimpleMea: rc, Hz, V, slope distance")
r = ask("%R1Q,2008,6:3,1")               # TMC_DoMeasure(TMC_CLEAR)
check(r == "%R1P,0,6:0", "TMC_DoMeasure(TMC_CLEAR)")
r = ask("%R1Q,4242,8:")                  # no such RPC
check(r.startswith("%R1P,3081,8:"), "unknown RPC: GRC_COM_PROC_UNAVAIL")
f.close()
s.close()

# --- 2. GeoComPy ----------------------------------------------------------------------
from geocompy.communication import open_socket
from geocompy.geo import GeoCom
for checksum in (False, True):
    with open_socket("127.0.0.1", port, "tcp") as conn:
        tps = GeoCom(conn, checksum=checksum)
        tag = f"GeoComPy (checksum={checksum})"
        r = tps.csv.get_instrument_name(); print("   ", r)
        check(r.error == 0 and isinstance(r.params, str), f"{tag}: CSV_GetInstrumentName")
        r = tps.csv.get_serial_number(); print("   ", r)
        check(r.error == 0 and r.params == 4242424, f"{tag}: CSV_GetInstrumentNo")
        r = tps.bap.set_target_type("DIRECT"); print("   ", r)
        check(r.error == 0, f"{tag}: BAP_SetTargetType")
        r = tps.aut.turn_to(2.0, math.pi / 2); print("   ", r)
        check(r.error == 0, f"{tag}: AUT_MakePositioning")
        r = tps.tmc.get_angle(); print("   ", r)
        check(r.error == 0 and abs(float(r.params[0]) - 2.0) < 1e-9, f"{tag}: TMC_GetAngle5")
        r = tps.tmc.do_measurement(); print("   ", r)
        check(r.error == 0, f"{tag}: TMC_DoMeasure")
        r = tps.tmc.get_simple_measurement(); print("   ", r)
        check(r.error in (0, 1292), f"{tag}: TMC_GetSimpleMea")
        r = tps.bap.measure_distance_angle(); print("   ", r)
        check(r.error in (0, 1292), f"{tag}: BAP_MeasDistanceAngle")
        r = tps.tmc.get_station(); print("   ", r)
        check(r.error == 0, f"{tag}: TMC_GetStation")
        r = tps.tmc.do_measurement("CLEAR"); print("   ", r)
        check(r.error == 0, f"{tag}: TMC_DoMeasure(TMC_CLEAR)")
        r = tps.tmc.set_azimuth(0.5); print("   ", r)
        check(r.error == 0, f"{tag}: TMC_SetOrientation")
        r = tps.tmc.get_angle(); print("   ", r)
        check(r.error == 0 and abs(float(r.params[0]) - 0.5) < 1e-9, f"{tag}: Hz reads the set orientation")

sim.kill()
print("FAILED" if fail else "all checks passed", f"({fail} failures)")
sys.exit(1 if fail else 0)
