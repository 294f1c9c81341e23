use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::{protobuf_enum, protobuf_form};

/// Quality of a GNSS solution as the receiver reports it. `None` means "no position: do not
/// use": a fix message with `None` carries no latitude or longitude.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum FixType {
    None,
    Single,
    Dgps,
    RtkFloat,
    RtkFixed,
}

impl FixType {
    pub fn has_position(self) -> bool {
        self != FixType::None
    }

    /// The name as it is written in a message (`rtk_fixed`).
    pub fn name(self) -> &'static str {
        match self {
            FixType::None => "none",
            FixType::Single => "single",
            FixType::Dgps => "dgps",
            FixType::RtkFloat => "rtk_float",
            FixType::RtkFixed => "rtk_fixed",
        }
    }
}

/// One GNSS solution (e.g. UBX-NAV-PVT, NMEA GGA+RMC).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct GnssFix {
    pub stamp_ns: u64,
    pub fix_type: FixType,
    /// Satellites used in the solution.
    pub satellites: u8,
    /// Horizontal dilution of precision (dimensionless).
    #[serde(default)]
    pub hdop: Option<f64>,
    #[serde(default)]
    pub latitude_deg: Option<f64>,
    #[serde(default)]
    pub longitude_deg: Option<f64>,
    /// Height above the WGS84 ellipsoid.
    #[serde(default)]
    pub altitude_m: Option<f64>,
    /// Height above mean sea level (the geoid), as the receiver reported it (NMEA GGA, UBX
    /// hMSL); absent where the source gives only the ellipsoidal height.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub altitude_msl_m: Option<f64>,
    /// Position covariance in the local east/north/up frame, row-major 3×3, m².
    #[serde(default)]
    pub position_covariance_enu_m2: Option<[f64; 9]>,
    /// Speed over ground.
    #[serde(default)]
    pub speed_mps: Option<f64>,
    /// Course over ground, clockwise from true north.
    #[serde(default)]
    pub course_rad: Option<f64>,
}

protobuf_enum!(FixType {
    None,
    Single,
    Dgps,
    RtkFloat,
    RtkFixed
});

protobuf_form!(GnssFix {
    stamp_ns,
    fix_type,
    satellites,
    hdop,
    latitude_deg,
    longitude_deg,
    altitude_m,
    altitude_msl_m,
    position_covariance_enu_m2,
    speed_mps,
    course_rad,
});
