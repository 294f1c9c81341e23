"""The peer that `railfuse bench` runs beside `railfuse refuse`: the same job written the
obvious way in Python, with clients written by others (the official `mcap` reader and writer,
filterpy's KalmanFilter, mcap-protobuf-support for protobuf channels).

    python bench/peer_refuse.py IN.mcap PIPELINE.toml OUT.mcap

It copies every schema, channel, message and metadata record of IN into OUT, runs the first
pipeline of PIPELINE.toml (a Kalman filter on the constant-acceleration model) over the
pipeline's sensors in file order (variance fixed or from the message, NIS gate per sensor),
writes a fused state per accepted measurement to /fused/<name>/state (JSON), and scores the states
against /truth (RMSE and maximum of position and speed error). Prints one JSON line: messages,
seconds, messages per second, and the accuracy figures."""
import bisect
import json
import math
import sys
import time
import tomllib

import numpy as np
from filterpy.kalman import KalmanFilter
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from mcap.writer import CompressionType, Writer

# What each sensor schema measures: (field, state index, variance field or None, validity field).
MEASURES = {
    "railfuse.LoopPosition": ("chainage_m", 0, "variance_m2", None),
    "railfuse.BalisePassage": ("chainage_m", 0, "variance_m2", None),
    "railfuse.RadarSpeed": ("speed_mps", 1, "speed_variance_m2ps2", "valid"),
    "railfuse.Odometer": ("speed_mps", 1, None, None),
}


def decoded(decoders, schema, channel, data):
    """A message's fields by name (None for one it does not carry), JSON or protobuf."""
    if channel.message_encoding != "protobuf":
        return json.loads(data).get
    m = decoders.decoder_for("protobuf", schema)(data)

    def get(name):
        try:
            if not m.HasField(name):
                return None
        except ValueError:  # a proto3 field without presence: always there
            pass
        return getattr(m, name)

    return get


def transition(psd, dt):
    F = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = psd * np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    return F, Q


def copy_message(writer, schema_ids, channel_ids, schema, channel, message):
    """The input message copied to the output, its schema and channel registered on first use."""
    if channel.id not in channel_ids:
        if schema.id not in schema_ids:
            schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
        channel_ids[channel.id] = writer.register_channel(
            channel.topic, channel.message_encoding, schema_ids[schema.id], channel.metadata
        )
    writer.add_message(channel_ids[channel.id], message.log_time, message.data, message.publish_time, message.sequence)


def start_filter(z, r, init):
    """The filter started at the first position measurement, as railfuse's default starts."""
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.x = np.array([[z], [init.get("speed_mps", 0.0)], [init.get("acceleration_mps2", 0.0)]])
    kf.P = np.diag([r, init.get("speed_std_mps", 5.0) ** 2, init.get("acceleration_std_mps2", 1.0) ** 2])
    return kf


def errors_against_truth(states, truth_t, truth_s, truth_v):
    """Position and speed errors of every state against the truth interpolated at its stamp."""
    pos, spd = [], []
    for stamp, s, v in states:
        i = bisect.bisect_left(truth_t, stamp)
        if i == 0 or i == len(truth_t):
            continue
        w = (stamp - truth_t[i - 1]) / (truth_t[i] - truth_t[i - 1])
        pos.append(s - (truth_s[i - 1] + w * (truth_s[i] - truth_s[i - 1])))
        spd.append(v - (truth_v[i - 1] + w * (truth_v[i] - truth_v[i - 1])))
    return pos, spd


def summary(messages, fused_states, elapsed, pos, spd):
    """What `railfuse bench` reads of the peer's run: its rate and its accuracy."""
    rms = lambda e: math.sqrt(sum(x * x for x in e) / len(e)) if e else None
    return {
        "messages": messages,
        "fused_states": fused_states,
        "elapsed_s": elapsed,
        "messages_per_s": messages / elapsed,
        "position_rmse_m": rms(pos),
        "position_max_m": max(map(abs, pos), default=None),
        "speed_rmse_mps": rms(spd),
        "speed_max_mps": max(map(abs, spd), default=None),
    }


def main(inp, config_path, out):
    with open(config_path, "rb") as f:
        pipeline = tomllib.load(f)["pipeline"][0]
    name, psd = pipeline["name"], pipeline["motion"]["jerk_psd"]
    init = pipeline.get("initial", {})
    sensors = {s["topic"]: s for s in pipeline["sensor"]}
    started = time.perf_counter()
    kf, t_filter = None, None
    truth_t, truth_s, truth_v = [], [], []
    states = []  # (stamp, chainage, speed)
    messages = 0
    with open(inp, "rb") as f, open(out, "wb") as g:
        reader = make_reader(f)
        writer = Writer(g, compression=CompressionType.ZSTD)
        writer.start(profile="railfuse", library="railfuse bench peer")
        schema_ids, channel_ids, decoders = {}, {}, DecoderFactory()
        fused_schema = writer.register_schema("railfuse.FusedState", "jsonschema", b"{}")
        fused = writer.register_channel(f"/fused/{name}/state", "json", fused_schema)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            copy_message(writer, schema_ids, channel_ids, schema, channel, message)
            messages += 1
            topic = channel.topic
            if topic == "/truth":
                d = decoded(decoders, schema, channel, message.data)
                truth_t.append(d("stamp_ns")), truth_s.append(d("chainage_m")), truth_v.append(d("speed_mps"))
                continue
            sensor = sensors.get(topic)
            if sensor is None:
                continue
            field, index, var_field, valid_field = MEASURES[schema.name]
            d = decoded(decoders, schema, channel, message.data)
            z = d(field)
            r = sensor["variance"]
            if r == "message":
                r = d(var_field) if var_field else None
            if z is None or r is None or (valid_field and not d(valid_field)):
                continue
            stamp = d("stamp_ns")
            if kf is None:
                if index != 0:
                    continue
                kf = start_filter(z, r, init)
                t_filter = stamp
                continue
            dt = (stamp - t_filter) / 1e9
            if dt < 0:
                continue
            if dt > 0:
                kf.F, kf.Q = transition(psd, dt)
                kf.predict()
                t_filter = stamp
            kf.H = np.zeros((1, 3))
            kf.H[0, index] = 1.0
            kf.R = np.array([[r]])
            y = z - (kf.H @ kf.x)[0, 0]
            s = (kf.H @ kf.P @ kf.H.T)[0, 0] + r
            gate = sensor.get("gate_nis")
            if gate is not None and y * y / s > gate:
                continue
            kf.update(np.array([[z]]))
            x = kf.x.ravel()
            state = {
                "stamp_ns": stamp,
                "chainage_m": x[0],
                "speed_mps": x[1],
                "acceleration_mps2": x[2],
                "covariance": list(kf.P.ravel()),
                "source": topic,
            }
            writer.add_message(fused, message.log_time, json.dumps(state).encode(), stamp)
            states.append((stamp, x[0], x[1]))
        for m in reader.iter_metadata():
            writer.add_metadata(m.name, m.metadata)
        writer.finish()
    pos, spd = errors_against_truth(states, truth_t, truth_s, truth_v)
    elapsed = time.perf_counter() - started
    print(json.dumps(summary(messages, len(states), elapsed, pos, spd)))


if __name__ == "__main__":
    main(*sys.argv[1:4])
