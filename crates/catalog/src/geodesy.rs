//! WGS-84 geodetic (latitude, longitude, ellipsoidal height), Earth-centred Earth-fixed (ECEF)
//! and local east/north/up coordinates around a track origin. Thin wrappers over `map_3d`, in
//! degrees at the interface (as receivers report them); checked against pyproj to the
//! millimetre over 100 km (tests/interop/numerics.rs).

use map_3d::Ellipsoid;
use serde::{Deserialize, Serialize};

/// ECEF `x, y, z` (m) of a geodetic point given in degrees and metres.
pub fn geodetic_to_ecef(latitude_deg: f64, longitude_deg: f64, altitude_m: f64) -> (f64, f64, f64) {
    map_3d::geodetic2ecef(
        latitude_deg.to_radians(),
        longitude_deg.to_radians(),
        altitude_m,
        Ellipsoid::WGS84,
    )
}

/// Latitude, longitude (degrees) and ellipsoidal height (m) of an ECEF point.
pub fn ecef_to_geodetic(x_m: f64, y_m: f64, z_m: f64) -> (f64, f64, f64) {
    let (lat, lon, alt) = map_3d::ecef2geodetic(x_m, y_m, z_m, Ellipsoid::WGS84);
    (lat.to_degrees(), lon.to_degrees(), alt)
}

/// The geodetic origin of a local ENU frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct GeodeticOrigin {
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub altitude_m: f64,
}

impl GeodeticOrigin {
    /// Latitude, longitude (degrees) and altitude (m) of a local `east, north, up` point.
    pub fn to_geodetic(&self, east_m: f64, north_m: f64, up_m: f64) -> (f64, f64, f64) {
        let (lat, lon, alt) = map_3d::enu2geodetic(
            east_m,
            north_m,
            up_m,
            self.latitude_deg.to_radians(),
            self.longitude_deg.to_radians(),
            self.altitude_m,
            Ellipsoid::WGS84,
        );
        (lat.to_degrees(), lon.to_degrees(), alt)
    }

    /// Local `east, north, up` (m) of a geodetic point given in degrees and metres.
    pub fn to_enu(
        &self,
        latitude_deg: f64,
        longitude_deg: f64,
        altitude_m: f64,
    ) -> (f64, f64, f64) {
        map_3d::geodetic2enu(
            latitude_deg.to_radians(),
            longitude_deg.to_radians(),
            altitude_m,
            self.latitude_deg.to_radians(),
            self.longitude_deg.to_radians(),
            self.altitude_m,
            Ellipsoid::WGS84,
        )
    }
}

impl GeodeticOrigin {
    /// Local `east, north, up` (m) of an ECEF point.
    pub fn ecef_to_enu(&self, x_m: f64, y_m: f64, z_m: f64) -> (f64, f64, f64) {
        map_3d::ecef2enu(
            x_m,
            y_m,
            z_m,
            self.latitude_deg.to_radians(),
            self.longitude_deg.to_radians(),
            self.altitude_m,
            Ellipsoid::WGS84,
        )
    }

    /// ECEF `x, y, z` (m) of a local `east, north, up` point.
    pub fn enu_to_ecef(&self, east_m: f64, north_m: f64, up_m: f64) -> (f64, f64, f64) {
        map_3d::enu2ecef(
            east_m,
            north_m,
            up_m,
            self.latitude_deg.to_radians(),
            self.longitude_deg.to_radians(),
            self.altitude_m,
            Ellipsoid::WGS84,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enu_round_trip_is_exact_to_a_millimetre_over_tens_of_kilometres() {
        let o = GeodeticOrigin {
            latitude_deg: 44.6551,
            longitude_deg: 10.9297,
            altitude_m: 40.0,
        };
        for &(e, n) in &[(0.0, 0.0), (1234.5, -987.0), (25_000.0, 18_000.0)] {
            let (lat, lon, alt) = o.to_geodetic(e, n, 0.0);
            let (e2, n2, u2) = o.to_enu(lat, lon, alt);
            assert!((e - e2).abs() < 1e-3 && (n - n2).abs() < 1e-3 && u2.abs() < 1e-3);
        }
        // One degree of latitude is about 111 km: catches a degrees/radians slip.
        let (lat, _, _) = o.to_geodetic(0.0, 111_000.0, 0.0);
        assert!((lat - o.latitude_deg - 1.0).abs() < 0.01);
    }
}
