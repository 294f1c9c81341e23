"""NMEA and UBX streams of a moving receiver, and the fixes the receivers' own protocol
libraries read from them (pynmeagps, pyubx2), for railfuse's decoders to be compared with
field by field.

    gnss_protocols.py OUT_DIR

writes OUT_DIR/rx.nmea, OUT_DIR/rx.ubx and OUT_DIR/expected.json. The receiver drives north-
east across the equator and the prime meridian from 2024-12-31 23:58:00 UTC over midnight
and the new year, at 1 Hz, with talkers GP/GN/GL/GA/BD, fix qualities 0-6, empty fields,
the date (RMC) before or after the GGA, GSA and GST after it, and bad lines of every kind
between the epochs. Expected fixes are assembled from what pynmeagps and pyubx2 parse, one per
epoch, as a receiver reports it (gpsd's reporting cycle).
"""

import datetime as dt
import functools
import json
import math
import random
import struct
import sys
from pathlib import Path

from pynmeagps import NMEAReader
from pyubx2 import UBXReader

START = dt.datetime(2024, 12, 31, 23, 58, 0, tzinfo=dt.timezone.utc)
EPOCHS = 300
TALKERS = ["GP", "GN", "GL", "GA", "BD"]


def checksum(body):
    return "%02X" % functools.reduce(lambda a, c: a ^ c, body.encode("latin-1"), 0)


def sentence(body):
    return f"${body}*{checksum(body)}"


def dmm(value, deg_digits):
    v = abs(value)
    d = int(v)
    return f"{d:0{deg_digits}d}{(v - d) * 60:08.5f}"


def position(k):
    """South-west of (0, 0) at the start, north-east of it at the end (about 35 m/s)."""
    return -0.0005 + k * 3.3e-6 * 1.0, -0.0004 + k * 3.0e-6


def stamp_ns(t):
    return int((t - dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)).total_seconds()) * 10**9 + t.microsecond * 1000


BAD_LINES = [
    "$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*00",  # checksum
    "hello, not a sentence",
    sentence("GPGGA,2\u00e95959.00,4807.038,S,01131.000,W,1,08,0.9,545.4,M,46.9,M,,"),  # non-ASCII
    sentence("GPGGA,120000.00,48nan,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),  # NaN latitude
    sentence("GPRMC,120000.00,A,4807.038,N,01131.000,E,0.1,,311322,,,A"),  # month 13
    "$GPGGA,120000.00,4807.0",  # cut short
    "$" + "A" * 300 + "*00",  # too long
]


def nmea_stream(rng):
    lines, expected = [], []
    for k in range(EPOCHS):
        t = START + dt.timedelta(seconds=k)
        hms = t.strftime("%H%M%S") + ".00"
        ddmmyy = t.strftime("%d%m%y")
        lat, lon = position(k)
        talker = TALKERS[k % len(TALKERS)]
        quality = k % 7
        sats = 4 + k % 20
        alt, sep = 100.0 + k * 0.1, 46.9 if k % 5 else None
        gga = sentence(
            f"{talker}GGA,{hms},{dmm(lat, 2)},{'N' if lat >= 0 else 'S'},{dmm(lon, 3)},"
            f"{'E' if lon >= 0 else 'W'},{quality},{sats:02d},0.9,{alt:.1f},M,"
            f"{'' if sep is None else sep},M,,"
        )
        speed_kn, course = 68.0 + (k % 3), 45.0 + k % 10
        rmc = sentence(
            f"{talker}RMC,{hms},{'A' if quality else 'V'},{dmm(lat, 2)},{'N' if lat >= 0 else 'S'},"
            f"{dmm(lon, 3)},{'E' if lon >= 0 else 'W'},{speed_kn:.1f},{course:.1f},{ddmmyy},,,A"
        )
        gsa = sentence(f"{talker}GSA,A,{1 if quality == 0 else 3},01,02,03,04,,,,,,,,,1.5,0.9,1.2")
        sig = (0.01 * (1 + k % 4), 0.02 * (1 + k % 3), 0.03)
        gst_empty = k % 11 == 0
        gst = sentence(
            f"{talker}GST,{hms},0.45,0.020,0.015,77.4,"
            + (",," if gst_empty else f"{sig[0]:.3f},{sig[1]:.3f},{sig[2]:.3f}")
        )
        epoch = [gga, gsa, gst, rmc] if k % 2 else [rmc, gga, gsa, gst]
        lines.extend(epoch)
        if rng.random() < 0.2:
            lines.append(rng.choice(BAD_LINES))
        # What pynmeagps reads of this epoch's sentences.
        m = {s.identity[2:]: s for s in (NMEAReader.parse(x) for x in epoch)}
        g, r, st, sa = m["GGA"], m["RMC"], m["GST"], m["GSA"]
        when = dt.datetime.combine(r.date, g.time, tzinfo=dt.timezone.utc)
        has = g.quality in (1, 2, 3, 4, 5) and sa.navMode != 1
        valid = r.status == "A"
        expected.append(
            {
                "stamp_ns": stamp_ns(when),
                "has_position": has,
                "latitude_deg": g.lat if has else None,
                "longitude_deg": g.lon if has else None,
                "altitude_msl_m": g.alt if has else None,
                "altitude_m": g.alt + g.sep if has and g.sep != "" else None,
                "satellites": g.numSV,
                "hdop": g.HDOP,
                "speed_mps": r.spd * 1852 / 3600 if has and valid else None,
                "course_deg": r.cog if has and valid else None,
                "sigmas": None if not has or st.stdLat == "" else [st.stdLat, st.stdLong, st.stdAlt],
            }
        )
    return lines, expected


def nav_pvt(k, t, rng):
    lat, lon = position(k)
    fix_type = [3, 3, 2, 0, 3, 4][k % 6]
    flags = (1 if fix_type else 0) | (2 if k % 3 == 0 else 0) | ((k % 3) << 6)
    invalid_llh = 1 if k % 17 == 5 else 0
    payload = struct.pack(
        "<IHBBBBBBIiBBBBiiiiIIiiiiiIIHH4xihH",
        k * 1000,
        t.year, t.month, t.day, t.hour, t.minute, t.second,
        0x07,  # validDate, validTime, fullyResolved
        20, rng.randint(-500_000, 500_000),
        fix_type, flags, 0, 5 + k % 20,
        round(lon * 1e7), round(lat * 1e7), 150_000 + k, 100_000 + k,
        800 + k, 1200 + k,
        10_000, 10_000, 0, 24_000 + k, round((45.0 + k % 10) * 1e5), 300, 50_000,
        120, invalid_llh, 0, 0, 0,
    )
    return frame(0x01, 0x07, payload)


def nav_cov(k):
    cov = [0.01 * (1 + k % 5), 0.001, 0.002, 0.02 * (1 + k % 4), 0.003, 0.05]
    payload = struct.pack("<IBBB9x6f6f", k * 1000, 0, 1, 0, *cov, *([0.0] * 6))
    return frame(0x01, 0x36, payload)


def frame(cls, mid, payload):
    body = bytes([cls, mid]) + struct.pack("<H", len(payload)) + payload
    a = b = 0
    for x in body:
        a = (a + x) & 0xFF
        b = (b + a) & 0xFF
    return b"\xb5\x62" + body + bytes([a, b])


def ubx_stream(rng):
    data, expected = bytearray(), []
    for k in range(EPOCHS):
        t = START + dt.timedelta(seconds=k)
        pvt, cov = nav_pvt(k, t, rng), nav_cov(k)
        data += pvt + cov
        if rng.random() < 0.2:
            data += rng.choice([b"\x00\xffnoise", pvt[:-1] + b"\x00", b"\xb5\x62\x01\x07\x04\x00junk"])
        p, c = UBXReader.parse(pvt), UBXReader.parse(cov)
        when = dt.datetime(p.year, p.month, p.day, p.hour, p.min, p.second, tzinfo=dt.timezone.utc)
        has = bool(p.gnssFixOk) and p.fixType in (2, 3, 4) and not p.invalidLlh
        expected.append(
            {
                "stamp_ns": stamp_ns(when) + p.nano,
                "has_position": has,
                "latitude_deg": p.lat if has else None,
                "longitude_deg": p.lon if has else None,
                "altitude_m": p.height / 1000 if has else None,
                "altitude_msl_m": p.hMSL / 1000 if has else None,
                "satellites": p.numSV,
                "speed_mps": p.gSpeed / 1000 if has else None,
                "course_deg": p.headMot if has and p.gSpeed > 500 else None,
                "carr_soln": p.carrSoln,
                "diff_soln": p.diffSoln,
                # NED -> ENU, row-major, as railfuse writes it.
                "covariance_enu": [c.posCovEE, c.posCovNE, -c.posCovED, c.posCovNE, c.posCovNN, -c.posCovND, -c.posCovED, -c.posCovND, c.posCovDD] if has else None,
            }
        )
    return bytes(data), expected


def main():
    out = Path(sys.argv[1])
    rng = random.Random(26)
    lines, nmea_expected = nmea_stream(rng)
    (out / "rx.nmea").write_bytes(("\r\n".join(lines) + "\r\n").encode("utf-8"))
    data, ubx_expected = ubx_stream(rng)
    (out / "rx.ubx").write_bytes(data)
    (out / "expected.json").write_text(json.dumps({"nmea": nmea_expected, "ubx": ubx_expected}))
    print(json.dumps({"nmea_fixes": len(nmea_expected), "ubx_fixes": len(ubx_expected)}))


if __name__ == "__main__":
    main()
