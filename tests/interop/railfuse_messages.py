"""A railfuse channel's messages as the dicts of their JSON form, whichever encoding the channel
has: JSON through json.loads, protobuf through mcap-protobuf-support (the file's own
descriptors) and then the JSON form's conventions: an optional field that is not set and an
empty repeated field are left out, a railfuse enum is its snake_case word (`rtk_fixed`), a
timestamp is {sec, nsec}, and an eddy-current block's ADC counts are volts (count × step, as a
float32) in sensor_a and sensor_b (unplaned as the .proto describes, with numpy), an IMU's
counts its values (count × step)."""
import json
import re

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

_decoders = DecoderFactory()


def _enum_word(enum, number):
    """A railfuse enum value as its JSON word: FIX_TYPE_RTK_FIXED → rtk_fixed."""
    name = enum.values_by_number[number].name
    prefix = re.sub(r"(?<!^)(?=[A-Z])", "_", enum.name).upper() + "_"
    return name.removeprefix(prefix).lower()


def _value(field, value):
    if field.type == field.TYPE_MESSAGE:
        if field.message_type.full_name == "google.protobuf.Timestamp":
            return {"sec": value.seconds, "nsec": value.nanos}
        return as_json_form(value)
    if field.type == field.TYPE_ENUM and field.enum_type.full_name.startswith("railfuse."):
        return _enum_word(field.enum_type, value)
    return value


def as_json_form(msg):
    """A decoded protobuf message as the dict of its JSON form."""
    out = {}
    for field in msg.DESCRIPTOR.fields:
        value = getattr(msg, field.name)
        if field.is_repeated:
            if len(value) == 0:
                continue
            if field.message_type is not None and field.message_type.GetOptions().map_entry:
                out[field.name] = dict(value)
            else:
                out[field.name] = [_value(field, v) for v in value]
        elif field.has_presence and not msg.HasField(field.name):
            continue
        else:
            out[field.name] = _value(field, value)
    if msg.DESCRIPTOR.full_name == "railfuse.Imu":
        for counts, step, values in (("specific_force_counts", "accel_lsb_mps2", "specific_force_mps2"),
                                     ("angular_rate_counts", "gyro_lsb_radps", "angular_rate_radps")):
            if counts in out:
                out[values] = [c * out[step] for c in out.pop(counts)]
            if out.get(step) == 0.0:
                del out[step]
    if msg.DESCRIPTOR.full_name == "railfuse.EddyCurrentBlock" and out.pop("counts_i16", None):
        a, b = eddy_current_volts(msg)
        out["sensor_a"], out["sensor_b"] = [float(v) for v in a], [float(v) for v in b]
    return out


def eddy_current_volts(block):
    """The two sensors' samples of a decoded railfuse.EddyCurrentBlock as float32 volts: from
    its byte-planed 16-bit counts (low bytes of every count, then high bytes) and the step."""
    if not block.counts_i16:
        return np.float32(block.sensor_a), np.float32(block.sensor_b)
    planes = np.frombuffer(block.counts_i16, dtype=np.uint8).reshape(2, -1)
    counts = (planes[0].astype(np.uint16) | (planes[1].astype(np.uint16) << 8)).view(np.int16)
    volts = (counts.astype(np.float64) * block.volts_per_count).astype(np.float32)
    return np.split(volts, 2)


def json_form(schema, channel, data):
    """One message's payload as the dict of its JSON form."""
    if channel.message_encoding == "protobuf":
        return as_json_form(_decoders.decoder_for("protobuf", schema)(data))
    return json.loads(data)


def messages(path, topics=None):
    """(schema, channel, message, dict) for every message of the file, in log-time order."""
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(topics=topics):
            yield schema, channel, message, json_form(schema, channel, message.data)
