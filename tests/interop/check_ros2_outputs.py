"""Decodes a refused ROS 2 bag's fused channels with mcap-ros2-support (the official ROS 2
decoder for MCAP), as `ros2 bag play`, Foxglove and PlotJuggler would read them.

    check_ros2_outputs.py FUSED.mcap PIPELINE

prints, as JSON, per channel: the count, and the first and last message's fields."""

import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main():
    path, pipeline = sys.argv[1], sys.argv[2]
    out = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topics = [f"/fused/{pipeline}/navsatfix", f"/fused/{pipeline}/odometry"]
        for schema, channel, message, ros in reader.iter_decoded_messages(topics=topics):
            entry = out.setdefault(channel.topic, {"count": 0, "schema": schema.name})
            entry["count"] += 1
            if schema.name == "sensor_msgs/msg/NavSatFix":
                fields = {
                    "stamp_ns": ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec,
                    "latitude": ros.latitude,
                    "longitude": ros.longitude,
                    "covariance": list(ros.position_covariance),
                    "covariance_type": ros.position_covariance_type,
                }
            else:
                fields = {
                    "stamp_ns": ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec,
                    "x": ros.pose.pose.position.x,
                    "y": ros.pose.pose.position.y,
                    "speed": ros.twist.twist.linear.x,
                    "speed_variance": ros.twist.covariance[0],
                }
            entry.setdefault("first", fields)
            entry["last"] = fields
    print(json.dumps(out))


if __name__ == "__main__":
    main()
