"""The peer that `railfuse bench` runs beside `railfuse refuse`: the same job written the
obvious way in Python, with clients written by others (the official `mcap` reader and writer,
filterpy's KalmanFilter and RTS smoother, mcap-protobuf-support for protobuf channels).

    python bench/peer_refuse.py IN.mcap PIPELINES.toml OUT.mcap

It copies every schema, channel, message and metadata record of IN into OUT and runs every
pipeline of PIPELINES.toml over its sensors in file order, writing the records railfuse
writes for it:

- `/fused/<name>/diagnostics`, one per scalar measurement (value, variance, innovation, its
  variance, NIS, the gate's decision, the device);
- `/fused/<name>/state`, per accepted measurement, or at `output_rate_hz` (the state
  predicted to each tick);
- `/fused/<name>/smoothed` where `smoother = true`: an RTS pass (filterpy's) over the filter's
  states on a 100 Hz grid, written at the end;
- `/foxglove/fused/<name>/state`, a foxglove.LocationFix at most every 0.1 s (the chainage put
  on the track map and turned into latitude and longitude);
- `/fused/<name>/train`, the whole train at most every 0.1 s: the front end with its safe
  interval at the configuration's `confidence` (the normal quantile from the standard
  library) and the rear end the `/vehicle`'s length behind (without the ends on the globe,
  which railfuse adds).

Filters: `kalman` is one filterpy KalmanFilter on the constant-acceleration model;
`federated_kalman` one per device, each measurement updating its device's filter, fused by
information every `fusion_period_s` and reset to the fused estimate (equal shares β). GNSS fixes
become chainage by projecting them on the track map's line (variance along the track from the
fix's covariance) and a speed signed by the course. What railfuse does and the peer does not:
calibration states (`chainage_bias`, `scale_factor`, `acceleration_bias`), the speed-band β
table, the fault detector and the reorder window; so the peer does less work than railfuse,
and the ratio `railfuse bench` reports is on the peer's side. The peer writes JSON.

It scores the first pipeline's states against /truth (RMSE and maximum of position and speed
error). Prints one JSON line: messages, seconds, messages per second, the accuracy figures."""
import bisect
import json
from statistics import NormalDist
import math
import sys
import time
import tomllib

import numpy as np
from filterpy.kalman import KalmanFilter
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from mcap.writer import CompressionType, Writer

CHAINAGE, SPEED, ACCELERATION = 0, 1, 2
QUANTITY = {"chainage": CHAINAGE, "speed": SPEED, "acceleration": ACCELERATION}
NAMES = {v: k for k, v in QUANTITY.items()}
TWIN_EVERY_NS = 100_000_000
SMOOTH_EVERY_NS = 10_000_000
WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3


def decoded(decoders, schema, channel, data):
    """A message's fields by name (None for one it does not carry), JSON or protobuf."""
    if channel.message_encoding != "protobuf":
        return json.loads(data).get
    m = decoders.decoder_for("protobuf", schema)(data)

    def get(name):
        try:
            if not m.HasField(name):
                return None
        except ValueError:  # a proto3 field without presence, or a repeated one: always there
            pass
        return getattr(m, name)

    return get


class Track:
    """The track map's main line in its local east/north plane, and the way back to degrees
    (a tangent plane at the map's origin)."""

    def __init__(self, d):
        o = d("origin")
        get = (lambda k: o[k]) if isinstance(o, dict) else (lambda k: getattr(o, k))
        self.lat0, self.lon0 = get("latitude_deg"), get("longitude_deg")
        vs = d("vertices")
        vget = (lambda v, k: v[k]) if vs and isinstance(vs[0], dict) else getattr
        self.s = np.array([vget(v, "chainage_m") for v in vs])
        self.en = np.array([[vget(v, "east_m"), vget(v, "north_m")] for v in vs])
        lat = math.radians(self.lat0)
        w = math.sqrt(1 - WGS84_E2 * math.sin(lat) ** 2)
        self.r_north = WGS84_A * (1 - WGS84_E2) / w**3
        self.r_east = WGS84_A / w * math.cos(lat)

    def enu(self, lat, lon):
        return (math.radians(lon - self.lon0) * self.r_east, math.radians(lat - self.lat0) * self.r_north)

    def project(self, e, n):
        """Chainage and heading of the nearest point of the line."""
        a, b = self.en[:-1], self.en[1:]
        ab = b - a
        t = np.clip(((e - a[:, 0]) * ab[:, 0] + (n - a[:, 1]) * ab[:, 1]) / (ab * ab).sum(1), 0, 1)
        px, py = a[:, 0] + t * ab[:, 0], a[:, 1] + t * ab[:, 1]
        i = int(np.argmin((px - e) ** 2 + (py - n) ** 2))
        s = self.s[i] + t[i] * (self.s[i + 1] - self.s[i])
        return s, math.atan2(ab[i, 0], ab[i, 1])

    def degrees(self, chainage):
        e = float(np.interp(chainage, self.s, self.en[:, 0]))
        n = float(np.interp(chainage, self.s, self.en[:, 1]))
        return self.lat0 + math.degrees(n / self.r_north), self.lon0 + math.degrees(e / self.r_east)


def measurements(schema, d, track):
    """(quantity, value, reported variance, valid) of each scalar a message gives."""
    if schema in ("railfuse.LoopPosition", "railfuse.BalisePassage"):
        return [(CHAINAGE, d("chainage_m"), d("variance_m2"), True)]
    if schema == "railfuse.RadarSpeed":
        return [(SPEED, d("speed_mps"), d("speed_variance_m2ps2"), bool(d("valid")))]
    if schema == "railfuse.Odometer":
        return [(SPEED, d("speed_mps"), None, True)]
    if schema == "railfuse.Imu":
        counts = d("specific_force_counts")
        ax = counts[0] * d("accel_lsb_mps2") if counts else d("specific_force_mps2")[0]
        return [(ACCELERATION, ax, None, True)]
    if schema == "railfuse.GnssFix":
        lat, lon = d("latitude_deg"), d("longitude_deg")
        if track is None or lat is None or lon is None:
            return [(CHAINAGE, math.nan, None, False), (SPEED, d("speed_mps"), None, False)]
        s, heading = track.project(*track.enu(lat, lon))
        c = list(d("position_covariance_enu_m2") or [])
        ue, un = math.sin(heading), math.cos(heading)
        var = ue * ue * c[0] + ue * un * (c[1] + c[3]) + un * un * c[4] if len(c) == 9 else None
        speed, course = d("speed_mps"), d("course_rad")
        if speed is not None and course is not None and math.cos(course - heading) < 0:
            speed = -speed
        return [(CHAINAGE, s, var, True), (SPEED, speed, None, speed is not None)]
    return []


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


def new_filter(init, z, r):
    """A filter started at the first chainage measurement, as railfuse's default starts."""
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.x = np.array([[z], [init.get("speed_mps", 0.0)], [init.get("acceleration_mps2", 0.0)]])
    kf.P = np.diag([r, init.get("speed_std_mps", 5.0) ** 2, init.get("acceleration_std_mps2", 1.0) ** 2])
    return kf


def predicted(x, P, psd, dt):
    if dt <= 0:
        return x, P
    F, Q = transition(psd, dt)
    return F @ x, F @ P @ F.T + Q


def fuse(estimates):
    """Information-weighted fusion of (x, P) pairs."""
    info = sum(np.linalg.inv(P) for _, P in estimates)
    P = np.linalg.inv(info)
    return P @ sum(np.linalg.inv(Pi) @ xi for xi, Pi in estimates), P


class Pipeline:
    def __init__(self, spec, writer, schemas):
        self.name = spec["name"]
        self.psd = spec["motion"]["jerk_psd"]
        self.init = spec.get("initial", {})
        self.federated = spec["filter"] == "federated_kalman"
        self.sensors = {s["topic"]: s for s in spec["sensor"]}
        rate = spec.get("output_rate_hz")
        self.period_ns = int(1e9 / rate) if rate else None
        fed = spec.get("federated", {})
        self.fusion_ns = int(fed.get("fusion_period_s", 1.0) * 1e9)
        self.devices = {s.get("device", "main") for s in spec["sensor"]} if self.federated else {"main"}
        self.filters = {}  # device -> [kf, stamp]
        self.next_tick = self.next_fusion = self.next_twin = self.next_smooth = None
        self.smoothing = [] if spec.get("smoother") else None  # (x, P, F, Q, stamp)
        self.states = []
        reg = lambda topic, schema, enc="json": writer.register_channel(topic, enc, schemas[schema])
        self.ch_state = reg(f"/fused/{self.name}/state", "railfuse.FusedState")
        self.ch_diag = reg(f"/fused/{self.name}/diagnostics", "railfuse.FusedDiagnostics")
        self.ch_smoothed = reg(f"/fused/{self.name}/smoothed", "railfuse.FusedState") if self.smoothing is not None else None
        self.ch_twin = reg(f"/foxglove/fused/{self.name}/state", "foxglove.LocationFix")
        self.ch_train = reg(f"/fused/{self.name}/train", "railfuse.TrainPosition")
        self.next_train = None
        self.train = (0.0, 0.9999)  # length, confidence: set by main
        self.writer = writer

    def estimate(self, stamp):
        """The pipeline's state at `stamp`: its filter, or its devices' fused."""
        each = [predicted(kf.x, kf.P, self.psd, (stamp - t) / 1e9) for kf, t in self.filters.values()]
        return each[0] if len(each) == 1 else fuse(each)

    def write_state(self, stamp, x, P, source, track):
        x = x.ravel()
        state = {"stamp_ns": stamp, "chainage_m": x[0], "speed_mps": x[1], "acceleration_mps2": x[2],
                 "covariance": list(P.ravel()), "source": source}
        self.writer.add_message(self.ch_state, stamp, json.dumps(state).encode(), stamp)
        self.states.append((stamp, x[0], x[1]))
        if track is not None and (self.next_twin is None or stamp >= self.next_twin):
            self.next_twin = stamp + TWIN_EVERY_NS
            lat, lon = track.degrees(x[0])
            fix = {"timestamp": {"sec": stamp // 10**9, "nsec": stamp % 10**9}, "frame_id": "wgs84",
                   "latitude": lat, "longitude": lon, "altitude": 0.0,
                   "position_covariance": [P[0, 0], 0, 0, 0, P[0, 0], 0, 0, 0, 0],
                   "position_covariance_type": 1}
            self.writer.add_message(self.ch_twin, stamp, json.dumps(fix).encode(), stamp)
        if self.next_train is None or stamp >= self.next_train:
            self.next_train = stamp + TWIN_EVERY_NS
            self.write_train(stamp, x, P)

    def write_train(self, stamp, x, P):
        length, confidence = self.train
        sd, sv = math.sqrt(max(P[0, 0], 0.0)), math.sqrt(max(P[1, 1], 0.0))
        half = NormalDist().inv_cdf(0.5 + 0.5 * confidence) * sd
        front, rear = x[0], x[0] - length
        train = {"stamp_ns": stamp, "length_m": length, "confidence": confidence,
                 "front_chainage_m": front, "front_std_m": sd,
                 "min_safe_front_m": front - half, "max_safe_front_m": front + half,
                 "rear_chainage_m": rear, "min_safe_rear_m": rear - half, "max_safe_rear_m": rear + half,
                 "speed_mps": x[1], "speed_std_mps": sv}
        self.writer.add_message(self.ch_train, stamp, json.dumps(train).encode(), stamp)

    def ticks(self, upto, track):
        """States at the output ticks and smoothing epochs up to `upto`."""
        if not self.filters:
            return
        if self.period_ns:
            while self.next_tick <= upto:
                x, P = self.estimate(self.next_tick)
                self.write_state(self.next_tick, x, P, "output_rate", track)
                self.next_tick += self.period_ns
        if self.smoothing is not None:
            while self.next_smooth <= upto:
                x, P = self.estimate(self.next_smooth)
                F, Q = transition(self.psd, SMOOTH_EVERY_NS / 1e9)
                self.smoothing.append((x, P, F, Q, self.next_smooth))
                self.next_smooth += SMOOTH_EVERY_NS
        if self.federated:
            while self.next_fusion <= upto:
                x, P = self.estimate(self.next_fusion)
                n = len(self.filters)
                for f in self.filters.values():
                    f[0].x, f[0].P, f[1] = x.copy(), P * n, self.next_fusion
                self.next_fusion += self.fusion_ns

    def measure(self, topic, log_time, stamp, scalars, track):
        sensor = self.sensors[topic]
        device = sensor.get("device", "main") if self.federated else "main"
        wanted = sensor.get("fields")
        self.ticks(stamp, track)
        for q, z, reported, valid in scalars:
            if wanted is not None and NAMES[q] not in wanted:
                continue
            spec = sensor["variance"]
            r = spec.get(NAMES[q]) if isinstance(spec, dict) else spec
            r = reported if r == "message" else r
            diag = {"stamp_ns": stamp, "source": topic, "device": device if self.federated else None}
            if not valid or z is None or r is None or not math.isfinite(z):
                diag["decision"] = "rejected_invalid"
                self.diagnose(stamp, diag)
                continue
            diag.update(measurement=z, measurement_variance=r)
            if not self.filters:
                if q != CHAINAGE:
                    diag["decision"] = "rejected_uninitialised"
                    self.diagnose(stamp, diag)
                    continue
                for dev in self.devices:
                    self.filters[dev] = [new_filter(self.init, z, r), stamp]
                start = (stamp // (self.period_ns or 1) + 1) * (self.period_ns or 1)
                self.next_tick = start
                self.next_smooth = (stamp // SMOOTH_EVERY_NS + 1) * SMOOTH_EVERY_NS
                self.next_fusion = stamp + self.fusion_ns
            kf, t = self.filters[device]
            dt = (stamp - t) / 1e9
            if dt < 0:
                diag["decision"] = "rejected_late"
                self.diagnose(stamp, diag)
                continue
            if dt > 0:
                kf.F, kf.Q = transition(self.psd, dt)
                kf.predict()
                self.filters[device][1] = stamp
            kf.H = np.zeros((1, 3))
            kf.H[0, q] = 1.0
            kf.R = np.array([[r]])
            y = z - kf.x[q, 0]
            s = kf.P[q, q] + r
            nis = y * y / s
            diag.update(innovation=y, innovation_variance=s, nis=nis)
            gate = sensor.get("gate_nis")
            if gate is not None and nis > gate:
                diag["decision"] = "rejected_gate"
            else:
                kf.update(np.array([[z]]))
                diag["decision"] = "accepted"
            self.diagnose(stamp, diag)
            if diag["decision"] == "accepted" and not self.period_ns:
                x, P = self.estimate(stamp)
                self.write_state(stamp, x, P, topic, track)

    def diagnose(self, stamp, diag):
        diag = {k: v for k, v in diag.items() if v is not None}
        self.writer.add_message(self.ch_diag, stamp, json.dumps(diag).encode(), stamp)

    def finish(self):
        if not self.smoothing:
            return
        kf = KalmanFilter(dim_x=3, dim_z=1)
        xs = np.array([s[0] for s in self.smoothing])
        Ps = np.array([s[1] for s in self.smoothing])
        Fs = np.array([s[2] for s in self.smoothing])
        Qs = np.array([s[3] for s in self.smoothing])
        xs, Ps, _, _ = kf.rts_smoother(xs, Ps, Fs, Qs)
        for (_, _, _, _, stamp), x, P in zip(self.smoothing, xs, Ps):
            x = x.ravel()
            state = {"stamp_ns": stamp, "chainage_m": x[0], "speed_mps": x[1], "acceleration_mps2": x[2],
                     "covariance": list(P.ravel()), "source": "smoother"}
            self.writer.add_message(self.ch_smoothed, stamp, json.dumps(state).encode(), stamp)


def copy_message(writer, schema_ids, channel_ids, schema, channel, message):
    """The input message copied to the output, its schema and channel registered on first use."""
    if channel.id not in channel_ids:
        if schema.id not in schema_ids:
            schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
        channel_ids[channel.id] = writer.register_channel(
            channel.topic, channel.message_encoding, schema_ids[schema.id], channel.metadata
        )
    writer.add_message(channel_ids[channel.id], message.log_time, message.data, message.publish_time, message.sequence)


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
        config = tomllib.load(f)
    specs = config["pipeline"]
    confidence = config.get("confidence", 0.9999)
    started = time.perf_counter()
    truth_t, truth_s, truth_v = [], [], []
    messages, track = 0, None
    with open(inp, "rb") as f, open(out, "wb") as g:
        reader = make_reader(f)
        writer = Writer(g, compression=CompressionType.ZSTD)
        writer.start(profile="railfuse", library="railfuse bench peer")
        schema_ids, channel_ids, decoders = {}, {}, DecoderFactory()
        schemas = {n: writer.register_schema(n, "jsonschema", b"{}") for n in
                   ("railfuse.FusedState", "railfuse.FusedDiagnostics", "foxglove.LocationFix",
                    "railfuse.TrainPosition")}
        pipelines = [Pipeline(spec, writer, schemas) for spec in specs]
        for p in pipelines:
            p.train = (config.get("vehicle", {}).get("length_m", 0.0), confidence)
        readers = {}  # topic -> pipelines reading it
        for p in pipelines:
            for topic in p.sensors:
                readers.setdefault(topic, []).append(p)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            copy_message(writer, schema_ids, channel_ids, schema, channel, message)
            messages += 1
            topic = channel.topic
            if topic == "/truth":
                d = decoded(decoders, schema, channel, message.data)
                truth_t.append(d("stamp_ns")), truth_s.append(d("chainage_m")), truth_v.append(d("speed_mps"))
                continue
            if topic == "/vehicle" and "vehicle" not in config:
                length = decoded(decoders, schema, channel, message.data)("length_m") or 0.0
                for p in pipelines:
                    p.train = (length, confidence)
                continue
            if topic == "/track/map":
                track = Track(decoded(decoders, schema, channel, message.data))
                continue
            if topic not in readers:
                continue
            d = decoded(decoders, schema, channel, message.data)
            scalars = measurements(schema.name, d, track)
            for p in readers[topic]:
                p.measure(topic, message.log_time, d("stamp_ns"), scalars, track)
        for p in pipelines:
            p.finish()
        for m in reader.iter_metadata():
            writer.add_metadata(m.name, m.metadata)
        writer.finish()
    pos, spd = errors_against_truth(pipelines[0].states, truth_t, truth_s, truth_v)
    elapsed = time.perf_counter() - started
    print(json.dumps(summary(messages, len(pipelines[0].states), elapsed, pos, spd)))


if __name__ == "__main__":
    main(*sys.argv[1:4])
