"""ROS 1 bags written and read by rosbags (and ROS 1 MCAP read by mcap-ros1-support), as a
ROS 1 tool would, to check railfuse's bag reader message for message.

    ros1_bag.py write IN.mcap OUT.bag none|bz2|lz4 [point|antenna_back|cycle|missing]
        writes a railfuse log's sensors as `rosbag record` would have logged them (ROS Noetic
        types, ROS 1 serialisation, 1 MiB chunks): /fix NavSatFix, /imu Imu, /radar
        TwistWithCovarianceStamped, /odom/N Odometry, plus /tf_static (a TFMessage placing
        every sensor frame, front_end and rear_end on base_link) and /rosout_text (std_msgs/String, a type railfuse
        does not read); prints the message count per topic (JSON).
    ros1_bag.py read BAG
        reads every message with rosbags and prints, per topic, each message's time and the
        fields railfuse takes from it (JSON).
    ros1_bag.py unindex BAG OUT.bag
        writes the bag as a recording that did not finish leaves it: cut at its index, the
        header's index_pos 0.
    ros1_bag.py read-mcap FILE.mcap
        reads an MCAP of ROS 1 channels with mcap-ros1-support's decoder, as read does.
    ros1_bag.py write-mcap IN.mcap OUT.mcap
        writes the same messages as `write` into an MCAP of ROS 1 channels (`ros1` messages,
        `ros1msg` schemas with ROS 1's definitions), as `mcap convert` makes of a bag, with the
        official mcap writer.
"""

import json
import sys
from pathlib import Path

from mcap.reader import make_reader
from rosbags.rosbag1 import Reader, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

TS = get_typestore(Stores.ROS1_NOETIC)
# tf's message is not among the typestore's; its definition as ROS 1 has it.
TS.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
STATUS = {"none": -1, "single": 0, "dgps": 1, "rtk_float": 2, "rtk_fixed": 2}


def json_messages(path):
    with open(path, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages():
            if ch.message_encoding == "json":
                yield ch.topic, m.log_time, json.loads(m.data)


def header(stamp_ns, frame):
    Time = TS.types["builtin_interfaces/msg/Time"]
    Header = TS.types["std_msgs/msg/Header"]
    return Header(seq=0, stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)


def vec(x, y, z):
    return TS.types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def quat(x, y, z, w):
    return TS.types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def nav_sat_fix(m):
    import numpy as np

    T = TS.types
    cov = m.get("position_covariance_enu_m2")
    return T["sensor_msgs/msg/NavSatFix"](
        header=header(m["stamp_ns"], "gps"),
        status=T["sensor_msgs/msg/NavSatStatus"](status=STATUS[m["fix_type"]], service=1),
        latitude=m.get("latitude_deg") or 0.0,
        longitude=m.get("longitude_deg") or 0.0,
        altitude=m.get("altitude_m") or 0.0,
        position_covariance=np.array(cov if cov else [0.0] * 9, dtype=np.float64),
        position_covariance_type=2 if cov else 0,
    )


def imu(m):
    import numpy as np

    T = TS.types
    z9 = np.zeros(9, dtype=np.float64)
    return T["sensor_msgs/msg/Imu"](
        header=header(m["stamp_ns"], "imu_link"),
        orientation=quat(0.0, 0.0, 0.0, 1.0),
        orientation_covariance=np.array([-1.0] + [0.0] * 8),
        angular_velocity=vec(*m["angular_rate_radps"]),
        angular_velocity_covariance=z9,
        linear_acceleration=vec(*m["specific_force_mps2"]),
        linear_acceleration_covariance=z9,
    )


def twist_cov(m, frame):
    import numpy as np

    T = TS.types
    cov = np.zeros(36, dtype=np.float64)
    cov[0] = m.get("speed_variance_m2ps2") or 0.01
    return T["geometry_msgs/msg/TwistWithCovarianceStamped"](
        header=header(m["stamp_ns"], frame),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=vec(m["speed_mps"], 0.0, 0.0), angular=vec(0.0, 0.0, 0.0)),
            covariance=cov,
        ),
    )


def odometry(m, frame):
    import numpy as np

    T = TS.types
    cov = np.zeros(36, dtype=np.float64)
    cov[0] = 0.04
    return T["nav_msgs/msg/Odometry"](
        header=header(m["stamp_ns"], "odom"),
        child_frame_id=frame,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=vec(0.0, 0.0, 0.0), orientation=quat(0.0, 0.0, 0.0, 1.0)),
            covariance=np.zeros(36, dtype=np.float64),
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=vec(m["speed_mps"], 0.0, 0.0), angular=vec(0.0, 0.0, 0.0)),
            covariance=cov,
        ),
    )


def tf_static(stamp_ns, variant="point"):
    """Where the sensor frames sit: the source log's train is a point (every sensor at its
    front end, as railfuse's simulator logs one without /vehicle), so each frame is at
    `front_end`, which with `rear_end` is placed on a `base_link` at the middle of a 20 m
    car, 0.5 m above the top of rail. Variants, to check that railfuse uses the transforms:
    `antenna_back` puts gps 12 m behind the front end and 4 m up (where the data has it at
    the front end); `cycle` makes base_link front_end's child too; `missing` leaves out the
    radar's frame."""
    T = TS.types

    def tf(child, x, y, z):
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(stamp_ns, "base_link"),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=vec(x, y, z), rotation=quat(0.0, 0.0, 0.0, 1.0)),
        )

    front = (10.0, 0.0, -0.5)
    frames = {f: front for f in ("gps", "imu_link", "radar", "wheel1", "wheel2")}
    if variant == "antenna_back":
        frames["gps"] = (-2.0, 0.0, 3.5)
    elif variant == "missing":
        del frames["radar"]
    transforms = [tf("front_end", *front), tf("rear_end", -10.0, 0.0, -0.5)]
    transforms += [tf(f, *at) for f, at in frames.items()]
    if variant == "cycle":
        back = T["geometry_msgs/msg/TransformStamped"](
            header=header(stamp_ns, "front_end"),
            child_frame_id="base_link",
            transform=T["geometry_msgs/msg/Transform"](translation=vec(-10.0, 0.0, 0.5), rotation=quat(0.0, 0.0, 0.0, 1.0)),
        )
        transforms.append(back)
    return T["tf2_msgs/msg/TFMessage"](transforms=transforms)


def write(source, out, compression, variant="point"):
    counts = {}
    writer = Writer(Path(out))
    if compression != "none":
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with writer:
        conns = {}

        def put(topic, msgtype, msg, t):
            if topic not in conns:
                latching = 1 if topic == "/tf_static" else None
                conns[topic] = writer.add_connection(topic, msgtype, typestore=TS, latching=latching)
            writer.write(conns[topic], t, TS.serialize_ros1(msg, msgtype))
            counts[topic] = counts.get(topic, 0) + 1

        sensors(source, put, variant)
    print(json.dumps(counts))


def write_mcap(source, out):
    from mcap.writer import Writer as McapWriter

    counts, channels = {}, {}
    with open(out, "wb") as f:
        writer = McapWriter(f)
        writer.start(profile="ros1", library="ros1_bag.py")

        def put(topic, msgtype, msg, t):
            if topic not in channels:
                text, _ = TS.generate_msgdef(msgtype, ros_version=1)
                name = msgtype.replace("/msg/", "/")
                schema = writer.register_schema(name=name, encoding="ros1msg", data=text.encode())
                channels[topic] = writer.register_channel(topic=topic, message_encoding="ros1", schema_id=schema)
            writer.add_message(channels[topic], log_time=t, publish_time=t, data=bytes(TS.serialize_ros1(msg, msgtype)))
            counts[topic] = counts.get(topic, 0) + 1

        sensors(source, put)
        writer.finish()
    print(json.dumps(counts))


def sensors(source, put, variant="point"):
    """A railfuse log's sensors as ROS 1 messages, handed to `put(topic, type, message, t)`."""
    first = True
    for topic, t, m in json_messages(source):
        if first:
            put("/tf_static", "tf2_msgs/msg/TFMessage", tf_static(t, variant), t)
            first = False
        if topic == "/gnss/fix":
            put("/fix", "sensor_msgs/msg/NavSatFix", nav_sat_fix(m), t)
        elif topic == "/imu":
            put("/imu", "sensor_msgs/msg/Imu", imu(m), t)
        elif topic == "/radar/speed":
            put("/radar", "geometry_msgs/msg/TwistWithCovarianceStamped", twist_cov(m, "radar"), t)
        elif topic.startswith("/odometer/"):
            n = topic.rsplit("/", 1)[1]
            put(f"/odom/{n}", "nav_msgs/msg/Odometry", odometry(m, f"wheel{n}"), t)
        elif topic == "/events":
            put("/rosout_text", "std_msgs/msg/String", TS.types["std_msgs/msg/String"](data=json.dumps(m)), t)


def fields(msgtype, msg):
    """What railfuse takes from a message, and its header time."""
    if msgtype == "tf2_msgs/msg/TFMessage":
        return {
            "transforms": [
                {
                    "parent": t.header.frame_id,
                    "child": t.child_frame_id,
                    "translation": [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
                    "rotation": [t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w],
                }
                for t in msg.transforms
            ]
        }
    if not hasattr(msg, "header"):
        return {}
    out = {"stamp_ns": msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, "frame_id": msg.header.frame_id}
    if msgtype == "sensor_msgs/msg/NavSatFix":
        out.update(latitude=msg.latitude, longitude=msg.longitude, altitude=msg.altitude, status=int(msg.status.status))
    elif msgtype == "sensor_msgs/msg/Imu":
        a, w = msg.linear_acceleration, msg.angular_velocity
        out.update(accel=[a.x, a.y, a.z], gyro=[w.x, w.y, w.z])
    elif msgtype == "geometry_msgs/msg/TwistWithCovarianceStamped":
        out.update(speed=msg.twist.twist.linear.x)
    elif msgtype == "nav_msgs/msg/Odometry":
        out.update(speed=msg.twist.twist.linear.x)
    return out


def read(path):
    topics = {}
    with Reader(Path(path)) as reader:
        for conn, t, raw in reader.messages():
            msg = TS.deserialize_ros1(raw, conn.msgtype)
            entry = fields(conn.msgtype, msg)
            entry["time_ns"] = t
            topics.setdefault(conn.topic, []).append(entry)
    print(json.dumps(topics))


def read_mcap(path):
    from mcap_ros1.decoder import DecoderFactory

    topics = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, ch, m, msg in reader.iter_decoded_messages():
            if ch.message_encoding != "ros1":
                continue
            entry = {"time_ns": m.log_time, "type": schema.name}
            if hasattr(msg, "header"):
                entry["stamp_ns"] = msg.header.stamp.secs * 10**9 + msg.header.stamp.nsecs
            if hasattr(msg, "latitude"):
                entry["latitude"] = msg.latitude
            topics.setdefault(ch.topic, []).append(entry)
    print(json.dumps(topics))


def unindex(path, out):
    data = bytearray(Path(path).read_bytes())
    key = b"index_pos="
    at = data.index(key) + len(key)
    index_pos = int.from_bytes(data[at : at + 8], "little")
    data[at : at + 8] = (0).to_bytes(8, "little")
    Path(out).write_bytes(bytes(data[:index_pos]))
    print(json.dumps({"index_pos": index_pos}))


if __name__ == "__main__":
    what = sys.argv[1]
    if what == "write":
        write(*sys.argv[2:6])
    elif what == "read":
        read(sys.argv[2])
    elif what == "write-mcap":
        write_mcap(sys.argv[2], sys.argv[3])
    elif what == "read-mcap":
        read_mcap(sys.argv[2])
    elif what == "unindex":
        unindex(sys.argv[2], sys.argv[3])
    else:
        sys.exit(f"unknown command {what}")
