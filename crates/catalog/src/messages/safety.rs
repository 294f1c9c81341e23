use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// The safety view of one epoch of a positioning pipeline (source 002): which checks ran and
/// passed, the first that failed and why, whether the position may be used, and then the safe
/// interval along the track that contains the true position with the pipeline's stated
/// confidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SafetyStatus {
    pub stamp_ns: u64,
    /// True when every check passed: the position may be used, as `safe_interval`.
    pub usable: bool,
    /// Every check of the epoch, in the order they ran (S1 sensor diagnosis, S3 divergence,
    /// S4 map, S5 odometry).
    pub checks: Vec<SafetyCheck>,
    /// The first check that failed (`s1_gnss`, `s3a_variance`, …), if one did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_failure: Option<String>,
    /// Why it failed, in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// `U_safe` (S6), when usable.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe_interval: Option<SafeInterval>,
}

/// One check of one epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SafetyCheck {
    /// `s1_gnss`, `s1_axle_1`, `s1_axle_2`, `s1_map`, `s3a_variance`, `s3b_innovation`,
    /// `s3c_covariance`, `s4_map`, `s5_odometry`.
    pub check: String,
    pub passed: bool,
    /// The tested quantity and its limit, where the check compares one with the other. For
    /// `s1_gnss`, which has no limit: the σ (m) the receiver reported for the last fix S1
    /// accepted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limit: Option<f64>,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Passed in a degraded mode (railfuse's, `degraded = true`): what was left out (a faulty
    /// axle, a fix beside the track) and why the interval still holds without it, or, for
    /// `s3c_covariance`, how far the interval widened.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degraded: Option<String>,
}

impl SafetyCheck {
    /// Passed degraded with an input left out: a fault named. A wide interval (`s3c_covariance`
    /// degraded) leaves nothing out and names none.
    pub fn left_out(&self) -> bool {
        self.degraded.is_some() && self.check != "s3c_covariance"
    }
}

/// `U_safe = [d − ησ − m, d + ησ + m]` along the track (S6).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SafeInterval {
    /// The estimated chainage d.
    pub chainage_m: f64,
    /// Its standard deviation σ.
    pub chainage_std_m: f64,
    pub low_m: f64,
    pub high_m: f64,
}

impl SafeInterval {
    pub fn contains(&self, chainage_m: f64) -> bool {
        (self.low_m..=self.high_m).contains(&chainage_m)
    }
}

protobuf_form!(SafetyStatus {
    stamp_ns,
    usable,
    checks,
    first_failure,
    reason,
    safe_interval,
});
protobuf_form!(SafetyCheck {
    check,
    passed,
    value,
    limit,
    reason,
    degraded
});
protobuf_form!(SafeInterval {
    chainage_m,
    chainage_std_m,
    low_m,
    high_m
});
