//! The simulated train as drawn and as installed: the drawing ([`Vehicle`], what the log
//! publishes on `/vehicle`, as a real train's documentation gives it) and the truth the
//! sensors measure from, which differs from it by installation tolerances.

use railfuse_catalog::messages::{SensorMount, Vehicle};
use railfuse_catalog::topics;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::sensors::gauss;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VehicleParams {
    /// The installation drawing.
    pub drawing: Vehicle,
    /// σ of each lever arm component's installation error, m.
    pub lever_arm_tolerance_m: f64,
    /// σ of each mounting angle's installation error, degrees.
    pub mounting_tolerance_deg: f64,
}

impl VehicleParams {
    /// A four-car EMU, 104 m: the GNSS antenna on the first car's roof 12.5 m behind the
    /// cab, the IMU on its floor, the radar and the balise, loop and eddy-current antennas
    /// under it, an odometer on each of its bogies; installed to ±3 cm and ±1.2° (1σ).
    pub fn emu() -> VehicleParams {
        let at = |topic: &str, lever_arm_m: [f64; 3]| SensorMount {
            lever_arm_m,
            ..SensorMount::at_front(topic)
        };
        VehicleParams {
            drawing: Vehicle {
                stamp_ns: 0,
                name: "simulated EMU, 4 cars".into(),
                length_m: 104.0,
                roll_per_lateral_mps2: 0.015,
                // The drawing states the tolerance the train is installed to.
                installation_std_m: 0.03,
                sensors: vec![
                    at(topics::GNSS_FIX, [-12.5, 0.0, 4.1]),
                    at(topics::IMU, [-13.0, 0.25, 1.2]),
                    at(topics::RADAR_SPEED, [-3.2, 0.0, 0.5]),
                    at(topics::ODOMETER_1, [-2.6, 0.0, 0.43]),
                    at(topics::ODOMETER_2, [-19.6, 0.0, 0.43]),
                    at(topics::BALISE, [-4.5, 0.0, 0.15]),
                    at(topics::LOOP_POSITION, [-5.5, 0.0, 0.2]),
                    at(topics::EDDY_CURRENT, [-6.0, 0.0, 0.1]),
                ],
            },
            lever_arm_tolerance_m: 0.03,
            mounting_tolerance_deg: 1.2,
        }
    }

    /// The train as installed: each lever arm and mounting angle off the drawing by a draw of
    /// its tolerance (within 2.5σ, as an inspection would pass), in the drawing's order.
    pub fn installed(&self, rng: &mut ChaCha8Rng) -> Vehicle {
        let mut draw = |sigma: f64| gauss(rng, sigma).clamp(-2.5 * sigma, 2.5 * sigma);
        let mut v = self.drawing.clone();
        for s in &mut v.sensors {
            for x in &mut s.lever_arm_m {
                *x += draw(self.lever_arm_tolerance_m);
            }
            // Along the train it stays on it.
            s.lever_arm_m[0] = s.lever_arm_m[0].min(0.0);
            for a in &mut s.mounting_deg {
                *a += draw(self.mounting_tolerance_deg);
            }
        }
        v
    }
}
