use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{FusedState, TrackMap, Vehicle};
use crate::protobuf::protobuf_form;

/// Where the whole train is after one of a pipeline's fused states: its front end (the
/// reference ETCS reports) with its σ and the interval that holds it at a stated confidence,
/// its rear end (the front end less the train's length), and its speed.
///
/// The interval is ETCS's confidence interval: the min and max safe front end are the
/// estimate less and plus `k σ`, `k` the two-sided Gaussian quantile of `confidence`
/// (3.89 for 0.9999); the safe rear ends are those less the length (what train integrity
/// and the release of the track behind go by).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrainPosition {
    pub stamp_ns: u64,
    /// The train's length the rear end is taken with, m.
    pub length_m: f64,
    /// The probability that the safe interval holds the true front end (two-sided).
    pub confidence: f64,
    pub front_chainage_m: f64,
    pub front_std_m: f64,
    pub min_safe_front_m: f64,
    pub max_safe_front_m: f64,
    pub rear_chainage_m: f64,
    pub min_safe_rear_m: f64,
    pub max_safe_rear_m: f64,
    pub speed_mps: f64,
    pub speed_std_mps: f64,
    /// The front and rear ends on the globe (on the track map at their chainage); absent
    /// without a map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub front: Option<TrainEnd>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rear: Option<TrainEnd>,
}

/// One end of the train on the track map: local east/north/up and the globe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrainEnd {
    pub east_m: f64,
    pub north_m: f64,
    pub up_m: f64,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub altitude_m: f64,
}

impl TrainEnd {
    /// The end at `chainage_m` on `map`'s main line (top of rail on the centre line).
    pub fn on(map: &TrackMap, chainage_m: f64) -> Option<TrainEnd> {
        let pose = map.pose_at(chainage_m)?;
        let (latitude_deg, longitude_deg, altitude_m) =
            map.origin.to_geodetic(pose.east_m, pose.north_m, pose.up_m);
        let end = TrainEnd {
            east_m: pose.east_m,
            north_m: pose.north_m,
            up_m: pose.up_m,
            latitude_deg,
            longitude_deg,
            altitude_m,
        };
        [
            latitude_deg,
            longitude_deg,
            altitude_m,
            pose.east_m,
            pose.north_m,
        ]
        .iter()
        .all(|v| v.is_finite())
        .then_some(end)
    }
}

/// The standard normal's quantile `k` with `P(|Z| ≤ k) = confidence`.
pub fn two_sided_quantile(confidence: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal};
    Normal::standard().inverse_cdf(0.5 + 0.5 * confidence)
}

impl TrainPosition {
    /// The train of `vehicle` at a pipeline's fused state (its chainage is the front end's),
    /// the interval at `confidence`; `None` for a state that is not finite.
    pub fn of(
        state: &FusedState,
        vehicle: &Vehicle,
        map: Option<&TrackMap>,
        confidence: f64,
    ) -> Option<TrainPosition> {
        let front = state.chainage_m;
        let front_std_m = state.covariance[0].max(0.0).sqrt();
        let speed_std_mps = state.covariance[4].max(0.0).sqrt();
        let finite = [front, front_std_m, state.speed_mps, speed_std_mps]
            .iter()
            .all(|v| v.is_finite());
        if !finite {
            return None;
        }
        let half = two_sided_quantile(confidence) * front_std_m;
        let rear = vehicle.rear_chainage(front);
        Some(TrainPosition {
            stamp_ns: state.stamp_ns,
            length_m: vehicle.length_m,
            confidence,
            front_chainage_m: front,
            front_std_m,
            min_safe_front_m: front - half,
            max_safe_front_m: front + half,
            rear_chainage_m: rear,
            min_safe_rear_m: rear - half,
            max_safe_rear_m: rear + half,
            speed_mps: state.speed_mps,
            speed_std_mps,
            front: map.and_then(|m| TrainEnd::on(m, front)),
            rear: map.and_then(|m| TrainEnd::on(m, rear)),
        })
    }
}

protobuf_form!(TrainPosition {
    stamp_ns,
    length_m,
    confidence,
    front_chainage_m,
    front_std_m,
    min_safe_front_m,
    max_safe_front_m,
    rear_chainage_m,
    min_safe_rear_m,
    max_safe_rear_m,
    speed_mps,
    speed_std_mps,
    front,
    rear,
});
protobuf_form!(TrainEnd {
    east_m,
    north_m,
    up_m,
    latitude_deg,
    longitude_deg,
    altitude_m,
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_interval_is_the_two_sided_quantile_of_the_confidence_times_sigma() {
        assert!((two_sided_quantile(0.9999) - 3.8906).abs() < 1e-3);
        assert!((two_sided_quantile(0.95) - 1.9600).abs() < 1e-3);
        let state = FusedState {
            stamp_ns: 1,
            chainage_m: 1000.0,
            speed_mps: 20.0,
            acceleration_mps2: 0.0,
            covariance: [0.25, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0],
            source: "/gnss/fix".into(),
            sensor_states: vec![],
            plane: None,
        };
        let train = Vehicle {
            length_m: 104.0,
            ..Vehicle::point()
        };
        let p = TrainPosition::of(&state, &train, None, 0.9999).unwrap();
        assert!((p.max_safe_front_m - (1000.0 + 3.8906 * 0.5)).abs() < 1e-3);
        assert!((p.min_safe_rear_m - (896.0 - 3.8906 * 0.5)).abs() < 1e-3);
        assert_eq!((p.front_std_m, p.speed_std_mps), (0.5, 0.1));
        assert!(p.front.is_none());
    }
}
