"""A railfuse log rewritten as a ROS 2 bag (MCAP storage, CDR) by rosbags, as `ros2 bag record`
would have logged the same sensors, and its track as a GeoJSON line.

    ros2_bag.py IN.mcap OUT_DIR [sqlite3] [--hostile]

writes OUT_DIR/bag/ (metadata.yaml and the .mcap; with `sqlite3`, the storage before ROS 2
Jazzy: OUT_DIR/bag-sqlite3/ with a .db3) and OUT_DIR/line.geojson, and prints the message
counts per ROS topic as JSON:

- /gnss/fix (railfuse GnssFix) -> /fix         sensor_msgs/msg/NavSatFix (no fix: NO_FIX)
                               -> /fix_velocity geometry_msgs/msg/TwistWithCovarianceStamped,
                                  east/north, as the ublox driver publishes it
- /imu                         -> /imu         sensor_msgs/msg/Imu
- /radar/speed                 -> /radar       geometry_msgs/msg/TwistWithCovarianceStamped
- /odometer/N                  -> /odom/N      geometry_msgs/msg/TwistWithCovarianceStamped

Each message keeps its log time as the bag's time and its sensor time as header.stamp.

With --hostile the bag also holds what a field log can: every 100th /fix payload cut short
(counted as "truncated"), every 100th from the 50th with a NaN latitude ("nan"), and a topic
of a type railfuse does not read (/notes, std_msgs/msg/String).
"""

import json
import math
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from railfuse_messages import json_form
from pyproj import Transformer
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

STATUS = {"none": -1, "single": 0, "dgps": 1, "rtk_float": 2, "rtk_fixed": 2}


def main():
    source, out = Path(sys.argv[1]), Path(sys.argv[2])
    sqlite = "sqlite3" in sys.argv[3:]
    hostile = "--hostile" in sys.argv[3:]
    storage, bag_dir = (StoragePlugin.SQLITE3, "bag-sqlite3") if sqlite else (StoragePlugin.MCAP, "bag")
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vector3 = T["geometry_msgs/msg/Vector3"]
    Twist, TwistCov = T["geometry_msgs/msg/Twist"], T["geometry_msgs/msg/TwistWithCovariance"]

    def header(stamp_ns, frame):
        return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)

    def twist(stamp_ns, frame, speed, variance, y=0.0):
        cov = np.zeros(36)
        cov[0] = variance
        return T["geometry_msgs/msg/TwistWithCovarianceStamped"](
            header=header(stamp_ns, frame),
            twist=TwistCov(twist=Twist(linear=Vector3(x=speed, y=y, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)), covariance=cov),
        )

    counts = {}
    with open(source, "rb") as f, Writer(out / bag_dir, version=9, storage_plugin=storage) as bag:
        conns = {}

        def write(topic, msgtype, msg, log_time, cut=None):
            if topic not in conns:
                conns[topic] = bag.add_connection(topic, msgtype, typestore=ts)
            data = ts.serialize_cdr(msg, msgtype)
            bag.write(conns[topic], log_time, bytes(data[:cut]) if cut else data)
            counts[topic] = counts.get(topic, 0) + 1

        for schema, channel, m in make_reader(f).iter_messages():
            d = json_form(schema, channel, m.data)
            t = channel.topic
            if t == "/track/map":
                write_geojson(d, out / "line.geojson")
            elif t == "/gnss/fix":
                has = d["fix_type"] != "none"
                msg = navsatfix(T, header(d["stamp_ns"], "gnss"), d)
                n = counts.get("/fix", 0)
                cut = None
                if hostile and n % 100 == 0:
                    cut = 20  # the header and half the status: too short for a NavSatFix
                    counts["truncated"] = counts.get("truncated", 0) + 1
                elif hostile and n % 100 == 50:
                    msg.latitude = float("nan")
                    counts["nan"] = counts.get("nan", 0) + 1
                write("/fix", "sensor_msgs/msg/NavSatFix", msg, m.log_time, cut)
                if hostile and n % 100 == 0:
                    write("/notes", "std_msgs/msg/String", T["std_msgs/msg/String"](data="checkpoint"), m.log_time)
                if has and d.get("speed_mps") is not None:
                    v, c = d["speed_mps"], d.get("course_rad") or 0.0
                    vel = twist(d["stamp_ns"], "gnss", v * math.sin(c), 0.0, y=v * math.cos(c))
                    write("/fix_velocity", "geometry_msgs/msg/TwistWithCovarianceStamped", vel, m.log_time)
            elif t == "/imu":
                msg = imu(T, header(d["stamp_ns"], d["sensor_id"]), d)
                write("/imu", "sensor_msgs/msg/Imu", msg, m.log_time)
            elif t == "/radar/speed":
                speed = d["speed_mps"] if d["valid"] else float("nan")
                msg = twist(d["stamp_ns"], "radar", speed, d.get("speed_variance_m2ps2") or 0.0)
                write("/radar", "geometry_msgs/msg/TwistWithCovarianceStamped", msg, m.log_time)
            elif t.startswith("/odometer/"):
                msg = twist(d["stamp_ns"], d["sensor_id"], d["speed_mps"], 0.0)
                write("/odom/" + t.rsplit("/", 1)[1], "geometry_msgs/msg/TwistWithCovarianceStamped", msg, m.log_time)
    print(json.dumps(counts))


def navsatfix(T, header, d):
    """A railfuse GNSS fix as sensor_msgs/NavSatFix (zeros and no covariance without a fix)."""
    has = d["fix_type"] != "none"
    cov = d.get("position_covariance_enu_m2")
    return T["sensor_msgs/msg/NavSatFix"](
        header=header,
        status=T["sensor_msgs/msg/NavSatStatus"](status=STATUS[d["fix_type"]], service=1),
        latitude=d.get("latitude_deg") or 0.0 if has else 0.0,
        longitude=d.get("longitude_deg") or 0.0 if has else 0.0,
        altitude=d.get("altitude_m") or 0.0 if has else 0.0,
        position_covariance=np.array(cov if cov else [0.0] * 9),
        position_covariance_type=3 if cov else 0,
    )


def imu(T, header, d):
    """A railfuse IMU sample as sensor_msgs/Imu, without orientation (covariance[0] = -1)."""
    Vector3, Quaternion = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    a, w = d["specific_force_mps2"], d["angular_rate_radps"]
    return T["sensor_msgs/msg/Imu"](
        header=header,
        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.array([-1.0] + [0.0] * 8),
        angular_velocity=Vector3(x=w[0], y=w[1], z=w[2]),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=Vector3(x=a[0], y=a[1], z=a[2]),
        linear_acceleration_covariance=np.zeros(9),
    )


def write_geojson(track, path):
    o = track["origin"]
    # The map's local east/north/up frame, as railfuse defines it (ECEF -> topocentric).
    to_geodetic = Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=cart +ellps=WGS84 "
        f"+step +proj=topocentric +ellps=WGS84 +lat_0={o['latitude_deg']} +lon_0={o['longitude_deg']} +h_0={o['altitude_m']}"
    )
    coords, chainage = [], []
    for v in track["vertices"]:
        # With its height: the plane is below the ellipsoid away from the origin.
        lon, lat, h = to_geodetic.transform(v["east_m"], v["north_m"], 0.0, direction="INVERSE")
        coords.append([lon, lat, h])
        chainage.append(v["chainage_m"])
    feature = {
        "type": "Feature",
        "properties": {"name": track["name"], "chainage_m": chainage},
        "geometry": {"type": "LineString", "coordinates": coords},
    }
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))


if __name__ == "__main__":
    main()
