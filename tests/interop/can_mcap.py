"""Read a CAN run's MCAP with others' code: the frames channel through the official `mcap`
reader and mcap-protobuf-support (as Foxglove reads protobuf channels, from the schema the
file carries), each frame decoded by cantools with the vehicle's DBC; and the sensors
railfuse made from them in the fused output.

    python tests/interop/can_mcap.py vehicle.dbc run.mcap run.fused.mcap out.json

Writes, per made topic, cantools' value of the mapped signal at each frame (the bus time)
beside railfuse's made message at the same time: tests/can.rs compares them.
"""

import json
import sys

import cantools
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

MAPPED = {
    "/odometer/1": ("WheelSpeed", "AxleSpeed1"),
    "/odometer/2": ("WheelSpeed", "AxleSpeed2"),
    "/radar/speed": ("RadarSpeed", "GroundSpeed"),
}


def decoded(path, topics):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, proto in reader.iter_decoded_messages(topics=topics):
            yield channel.topic, schema.name, proto


def main():
    dbc, run, fused, out = sys.argv[1:5]
    db = cantools.database.load_file(dbc)
    theirs = {topic: {} for topic in MAPPED}
    frames = 0
    for _, schema, frame in decoded(run, ["/can/can0/frames"]):
        assert schema == "railfuse.CanFrame", schema
        frames += 1
        try:
            message = db.get_message_by_frame_id(frame.id)
        except KeyError:
            continue
        signals = db.decode_message(frame.id, bytes(frame.data), decode_choices=False)
        for topic, (name, signal) in MAPPED.items():
            if message.name != name:
                continue
            sig = message.get_signal_by_name(signal)
            value = signals[signal]
            if sig.maximum is not None and not (sig.minimum <= value <= sig.maximum):
                continue  # "not available": railfuse makes no reading of it either
            theirs[topic][frame.stamp_ns] = abs(value)
    ours = {topic: {} for topic in MAPPED}
    for topic, _, message in decoded(fused, list(MAPPED)):
        ours[topic][message.stamp_ns] = message.speed_mps
    result = {"frames": frames, "topics": {}}
    for topic in MAPPED:
        stamps = sorted(set(theirs[topic]) | set(ours[topic]))
        both = [t for t in stamps if t in theirs[topic] and t in ours[topic]]
        result["topics"][topic] = {
            "cantools": len(theirs[topic]),
            "railfuse": len(ours[topic]),
            "both": len(both),
            "max_difference": max((abs(theirs[topic][t] - ours[topic][t]) for t in both), default=None),
        }
    json.dump(result, open(out, "w"), indent=1)


if __name__ == "__main__":
    main()
