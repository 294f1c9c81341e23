"""A rosbag2 bag split as `ros2 bag record --max-bag-duration` splits one, written by rosbags
(a library not written here): the messages of BAG cut at the given times into OUT/split_0.mcap,
OUT/split_1.mcap, … and one metadata.yaml listing every file, with each file's starting time,
duration and message count, as rosbag2 writes it.

    split_bag.py BAG OUT T1,T2,…   (Ti: seconds from the bag's first message)

rosbags' own Reader then reads OUT back, and the counts it gives are printed as JSON:
{"files": [...], "messages": N, "per_file": [...]}.
"""

import json
import shutil
import sys
from pathlib import Path

from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from ruamel.yaml import YAML


def main():
    bag, out = Path(sys.argv[1]), Path(sys.argv[2])
    cuts = [float(t) for t in sys.argv[3].split(",")]
    ts = get_typestore(Stores.ROS2_HUMBLE)
    out.mkdir(parents=True)
    with Reader(bag) as reader:
        start = reader.start_time
        bounds = [start + int(t * 1e9) for t in cuts]
        parts, writer, conns, k = [], None, {}, -1
        for conn, t, data in reader.messages():
            part = sum(1 for b in bounds if t >= b)
            while part > k:
                if writer is not None:
                    writer.close()
                k += 1
                tmp = out / f"tmp_{k}"
                writer = Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP)
                writer.open()
                conns = {}
                parts.append(tmp)
            if conn.id not in conns:
                conns[conn.id] = writer.add_connection(conn.topic, conn.msgtype, typestore=ts)
            writer.write(conns[conn.id], t, data)
        writer.close()
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    merged = None
    for i, tmp in enumerate(parts):
        info = yaml.load((tmp / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        name = f"split_{i}.mcap"
        shutil.move(tmp / info["relative_file_paths"][0], out / name)
        shutil.rmtree(tmp)
        info["files"][0]["path"] = name
        if merged is None:
            merged = info
            merged["relative_file_paths"] = [name]
            continue
        merged["relative_file_paths"].append(name)
        merged["files"].append(info["files"][0])
        merged["message_count"] += info["message_count"]
        end = max(
            f["starting_time"]["nanoseconds_since_epoch"] + f["duration"]["nanoseconds"]
            for f in merged["files"]
        )
        merged["duration"]["nanoseconds"] = end - merged["starting_time"]["nanoseconds_since_epoch"]
        counts = {t["topic_metadata"]["name"]: t for t in merged["topics_with_message_count"]}
        for t in info["topics_with_message_count"]:
            name_t = t["topic_metadata"]["name"]
            if name_t in counts:
                counts[name_t]["message_count"] += t["message_count"]
            else:
                merged["topics_with_message_count"].append(t)
    with open(out / "metadata.yaml", "w") as f:
        yaml.dump({"rosbag2_bagfile_information": merged}, f)
    with Reader(out) as check:
        messages = sum(1 for _ in check.messages())
        print(json.dumps({
            "files": merged["relative_file_paths"],
            "messages": messages,
            "per_file": [f["message_count"] for f in merged["files"]],
        }))


if __name__ == "__main__":
    main()
