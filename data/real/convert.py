#!/usr/bin/env python3
"""How the files under data/real/ were made from the original recordings (see PROVENANCE.md).

Usage: python3 data/real/convert.py SOURCE_DATA_DIR [MDOF_CHECKOUT]

With MDOF_CHECKOUT (a checkout of chrystalchern/mdof at commit 4f0e831c) the six structures of
`unseen/` are made too, from its `notebooks/uploads` as they are there:

- `unseen/stiff-one-storey/`: the Xsens exports of `mini_shake_table/Flexible vs. Stiff/Stiff 1
  story`, kept as the shake-table files above (SampleTimeFine and Acc_X; a value the sensor
  wrote `nan` stays `nan`).
- `unseen/meloland/`: from three zipped CSMIP V2 sets of `meloland/`, the transverse channels 7
  (deck, middle of the bridge) and 11 (south embankment), kept as the V2 records above.
- `unseen/capistrano/`: from four zipped CSMIP V2 sets of `capistrano/`, the transverse channels
  4 (bent 4, bottom of column) and 10 (bent 4, deck level), kept as the V2 records above.
- `unseen/ridgecrest/`: from five zipped CSMIP V2 sets of `ridgecrest/`, the transverse channels
  4 (bent 3, south column at ground level) and 7 (bent 3, deck level), kept as above.
- `unseen/hayward/`: from eight zipped CSMIP V2 sets of `hayward/`, the transverse channels 18
  (bent 4, north column at ground level) and 20 (bent 4, north column top), kept as above.
- `unseen/crowley/`: from four zipped CSMIP V2 sets of `crowley/`, the transverse channels 4
  (centre bent, column at ground level) and 7 (centre bent, deck level), kept as above.

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
        for s in SENSORS:
            compact_xsens(
                os.path.join(src, "shake-table", "flexible-3-storey", event, s + ".csv"),
                os.path.join(HERE, "shake-table", event, s + ".csv"),
            )


def csmip(src):
    d = os.path.join(src, "csmip", "painter-street-overpass", "ferndale_28jan2015_72387946")
    os.makedirs(os.path.join(HERE, "csmip"), exist_ok=True)
    for c in V2_CHANNELS:
        name = "CHAN%03d.V2" % c
        with open(os.path.join(d, name), "rb") as f:
            raw = f.read()
        with open(os.path.join(HERE, "csmip", name), "wb") as f:
            f.write(v2_acceleration(raw))


STIFF_EVENTS = {
    "elcentro-1": "(El Centro Trial 1)",
    "elcentro-2": "(El Centro Trial 2)",
    "northridge-1": "(Northridge Trial 1)",
    "northridge-2": "(Northridge Trial 2)",
    "sine-1": "(Sine Wave Trial 1)",
    "sine-2": "(Sine Wave Trial 2)",
}
STIFF_SENSORS = {"ground": "Ground Floor", "floor-1": "Top Floor"}
MELOLAND_EVENTS = {
    "calexico-2008-11-20": "Calexico_20Nov2008_CE01336P.ZIP",
    "el-mayor-cucapah-2010-04-04": "calexico_04apr2010_14607652_CE01336P.ZIP",
    "borrego-springs-2010-07-07": "BorregoSprings_07Jul2010_CE01336P.ZIP",
}
MELOLAND_CHANNELS = [7, 11]
# The same overpass under two older earthquakes, in the V2 layout of records before about 1993
# (the sensor's azimuth, 270 degrees, for its transverse axis; 50 Hz).
MELOLAND_OLDER_EVENTS = {
    "imperial-valley-1979-10-15": "imperialvalley79_ce01336p.zip",
    "superstition-hills-1987-11-24": "superstitionhills87_ce01336p.zip",
}
CAPISTRANO_EVENTS = {
    "inglewood-2009-05-17": "Inglewood_17May2009_CE13795P.zip",
    "el-mayor-cucapah-2010-04-04": "calexico_04apr2010_14607652_CE13795P.zip",
    "ocotillo-2010-06-14": "Ocotillo_14Jun2010_CE13795P.zip",
    "borrego-springs-2010-07-07": "BorregoSprings_07Jul2010_CE13795P.zip",
}
CAPISTRANO_CHANNELS = [4, 10]
RIDGECREST_EVENTS = {
    "ridgecrest-2019-07-04": "ci38443183_ce33742p.zip",
    "ridgecrest-2019-07-06": "ci38457511_ce33742p.zip",
    "little-lake-2019-08-22": "ci38996632_ce33742p.zip",
    "searles-valley-2020-06-04": "ci39462536_ce33742p.zip",
    "lone-pine-2020-06-24": "ci39493944_ce33742p.zip",
}
RIDGECREST_CHANNELS = [4, 7]
# The Hayward bridge's sets of 2021-22 name their files in lower case (`chan018.v2`); the
# preliminary processing names no earthquake, so the records are named by their date.
HAYWARD_EVENTS = {
    "berkeley-2018-01-04": "berkeley_04jan2018_72948801_ce58658p.zip",
    "2021-04-26": "58658_007_20210426_10.09.54.P.zip",
    "2021-06-23": "58658_002_20210623_17.15.07.P.zip",
    "2021-07-23": "58658_004_20210723_08.59.25.P.zip",
    "2021-08-03": "58658_005_20210803_12.52.01.P.zip",
    "2021-10-02": "58658_003_20211002_12.22.00.P.zip",
    "2021-10-07": "58658_005_20211007_11.51.59.P.zip",
    "2022-02-15": "58658_014_20220215_12.01.04.P.zip",
}
HAYWARD_CHANNELS = [18, 20]
# Lake Crowley's two sets of 2004-09-18 are two earthquakes 41 minutes apart (the second set's
# name says `event2`); its fifth set in the source (Tom's Place 2008) is not in the checkout.
CROWLEY_EVENTS = {
    "qualeys-camp-2004-09-18-a": "QualeysCamp_18Sep2004_CE54730.ZIP",
    "qualeys-camp-2004-09-18-b": "QualeysCamp_18Sep2004_event2_CE54730.ZIP",
    "toms-place-2006-11-26": "tomsplace_26nov2006_ce54730p.zip",
    "mammoth-lakes-2007-06-12": "mammothlakes_12jun2007_ce54730p.zip",
}
CROWLEY_CHANNELS = [4, 7]


def compact_xsens(path, dst):
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
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    with open(dst, "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(out) + "\n")


def v2_acceleration(raw):
    """The text header and the acceleration block of one V2 record (bytes): lines 1–46 (the
    header and the acceleration block's own), then the block's ceil(npts / 8) lines."""
    lines = raw.split(b"\n")
    npts = int(lines[15].split()[0])
    return b"\n".join(lines[: 46 + (npts + 7) // 8]) + b"\n"


def unseen(mdof):
    import zipfile

    up = os.path.join(mdof, "notebooks", "uploads")
    stiff = os.path.join(up, "mini_shake_table", "Flexible vs. Stiff", "Stiff 1 story")
    names = []
    for event, tag in STIFF_EVENTS.items():
        for sensor, folder in STIFF_SENSORS.items():
            d = os.path.join(stiff, folder)
            (name,) = [n for n in sorted(os.listdir(d)) if n.startswith(tag)]
            compact_xsens(
                os.path.join(d, name),
                os.path.join(HERE, "unseen", "stiff-one-storey", event, sensor + ".csv"),
            )
            names.append("%s/%s.csv <- Stiff 1 story/%s/%s" % (event, sensor, folder, name))
    with open(os.path.join(HERE, "unseen", "stiff-one-storey", "ORIGINAL_NAMES.txt"), "w") as f:
        f.write("\n".join(names) + "\n")
    for folder, events, channels, out in [
        ("meloland", MELOLAND_EVENTS, MELOLAND_CHANNELS, "meloland"),
        ("meloland", MELOLAND_OLDER_EVENTS, MELOLAND_CHANNELS, "meloland"),
        ("capistrano", CAPISTRANO_EVENTS, CAPISTRANO_CHANNELS, "capistrano"),
        ("ridgecrest", RIDGECREST_EVENTS, RIDGECREST_CHANNELS, "ridgecrest"),
        ("hayward", HAYWARD_EVENTS, HAYWARD_CHANNELS, "hayward"),
        ("crowley", CROWLEY_EVENTS, CROWLEY_CHANNELS, "crowley"),
    ]:
        for event, zname in events.items():
            with zipfile.ZipFile(os.path.join(up, folder, zname)) as z:
                for c in channels:
                    name = "CHAN%03d.V2" % c
                    # The 1979 and Lake Crowley 2004 sets name their channels with two digits
                    # (`CHAN07.V2`), the Hayward sets of 2021-22 in lower case (`chan018.v2`).
                    by_upper = {n.upper(): n for n in z.namelist()}
                    member = by_upper.get(name) or by_upper["CHAN%02d.V2" % c]
                    dst = os.path.join(HERE, "unseen", out, event, name)
                    os.makedirs(os.path.dirname(dst), exist_ok=True)
                    with open(dst, "wb") as f:
                        f.write(v2_acceleration(z.read(member)))


if __name__ == "__main__":
    shake_table(sys.argv[1])
    csmip(sys.argv[1])
    if len(sys.argv) > 2:
        unseen(sys.argv[2])
