#!/usr/bin/env python3
"""How the files under data/real/ were made from the original recordings (see PROVENANCE.md).

Usage: python3 data/real/convert.py SOURCE_DATA_DIR

- Shake table (Xsens DOT CSV exports): the seven header lines and the column-name line are
  kept; of the columns only SampleTimeFine (sensor clock, µs) and Acc_X (the shaking axis,
  m/s², gravity included) are kept, Acc_X rounded to 1e-5 m/s² (the sensor's noise is about
  1e-2 m/s²). Every row is kept, the leading row of zeros included: the files are still
  exports in the sensor's format, with the clocks, lengths and offsets as recorded.
- CSMIP V2 records: the text header and the acceleration block are kept byte for byte (CRLF
  line ends included); the velocity and displacement blocks after it are dropped.
"""
import os
import sys

EVENTS = ["northridge", "sine-1.0", "sine-1.5", "sine-2.0", "bonus-event"]
SENSORS = ["ground", "floor-1", "floor-2", "floor-3"]
V2_CHANNELS = [3, 4, 7, 9, 17, 20]
HERE = os.path.dirname(os.path.abspath(__file__))


def shake_table(src):
    for event in EVENTS:
        os.makedirs(os.path.join(HERE, "shake-table", event), exist_ok=True)
        for s in SENSORS:
            path = os.path.join(src, "shake-table", "flexible-3-storey", event, s + ".csv")
            with open(path, encoding="utf-8", newline="") as f:
                lines = f.read().splitlines()
            names = lines[7].split(",")
            jt, ja = names.index("SampleTimeFine"), names.index("Acc_X")
            out = lines[:7] + ["SampleTimeFine,Acc_X"]
            for row in lines[8:]:
                if not row.strip():
                    continue
                fields = row.split(",")
                out.append("%s,%.5f" % (fields[jt], float(fields[ja])))
            dst = os.path.join(HERE, "shake-table", event, s + ".csv")
            with open(dst, "w", encoding="utf-8", newline="\n") as f:
                f.write("\n".join(out) + "\n")


def csmip(src):
    d = os.path.join(src, "csmip", "painter-street-overpass", "ferndale_28jan2015_72387946")
    os.makedirs(os.path.join(HERE, "csmip"), exist_ok=True)
    for c in V2_CHANNELS:
        name = "CHAN%03d.V2" % c
        with open(os.path.join(d, name), "rb") as f:
            lines = f.read().split(b"\n")
        npts = int(lines[15].split()[0])
        acc_lines = (npts + 7) // 8
        # lines 1..46 (header and the acceleration block's header), then the block.
        kept = lines[: 46 + acc_lines]
        with open(os.path.join(HERE, "csmip", name), "wb") as f:
            f.write(b"\n".join(kept) + b"\n")


if __name__ == "__main__":
    shake_table(sys.argv[1])
    csmip(sys.argv[1])
