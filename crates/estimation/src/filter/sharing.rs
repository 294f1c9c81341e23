//! Information-sharing coefficients β of a federated filter: how the master's information is
//! shared back among the sub-filters (`P_i := P_g / β_i`, `Σ β_i = 1`), chosen by speed band
//! because each device's accuracy depends on speed (source 001: the INS is best slow, the
//! radar fast), and redistributed when a device fails.

/// β per device (in the pipeline's device order) for speeds below `below_mps`.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedBand {
    pub below_mps: f64,
    pub beta: Vec<f64>,
}

/// Speed bands in increasing order; the last one has `below_mps = ∞`.
#[derive(Debug, Clone, PartialEq)]
pub struct SharingTable {
    pub bands: Vec<SpeedBand>,
}

/// How a failed device's share goes to the healthy ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Redistribution {
    /// In equal parts.
    Even,
    /// In proportion to the healthy devices' own β at the current speed (their accuracy there,
    /// by the table's own reasoning).
    Accuracy,
}

const KMH: f64 = 1.0 / 3.6;

/// The devices of source 000's table, in its order.
pub const SOURCE_000_DEVICES: [&str; 2] = ["loop", "radar"];

/// The devices of source 001's table, in its order.
pub const SOURCE_001_DEVICES: [&str; 3] = ["ins", "gnss", "radar"];

/// A sharing table by name: `sharing = "…"` in a federated pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum SharingName {
    /// Equal shares, whatever the speed.
    #[default]
    Even,
    /// Source 000: α_loop 0.8 below 70 m/s, 0.5 above (devices loop, radar).
    #[cfg_attr(feature = "serde", serde(rename = "source_000"))]
    Source000,
    /// Source 001: β by speed band for devices ins, gnss, radar.
    #[cfg_attr(feature = "serde", serde(rename = "source_001"))]
    Source001,
}

impl SharingName {
    /// Its name in configs.
    pub fn key(self) -> &'static str {
        match self {
            SharingName::Even => "even",
            SharingName::Source000 => "source_000",
            SharingName::Source001 => "source_001",
        }
    }
}

impl SharingTable {
    /// Source 001's table for devices (INS, GNSS, radar): below 50 km/h 0.6/0.3/0.1, to
    /// 150 km/h 0.5/0.4/0.1, above 0.4/0.4/0.2.
    pub fn source_001() -> Self {
        Self {
            bands: vec![
                SpeedBand {
                    below_mps: 50.0 * KMH,
                    beta: vec![0.6, 0.3, 0.1],
                },
                SpeedBand {
                    below_mps: 150.0 * KMH,
                    beta: vec![0.5, 0.4, 0.1],
                },
                SpeedBand {
                    below_mps: f64::INFINITY,
                    beta: vec![0.4, 0.4, 0.2],
                },
            ],
        }
    }

    /// Source 000's coefficients for devices (loop, radar): α_loop 0.8 below 70 m/s, 0.5 above.
    pub fn source_000() -> Self {
        Self {
            bands: vec![
                SpeedBand {
                    below_mps: 70.0,
                    beta: vec![0.8, 0.2],
                },
                SpeedBand {
                    below_mps: f64::INFINITY,
                    beta: vec![0.5, 0.5],
                },
            ],
        }
    }

    /// A named table for `devices` (the pipeline's device names, in its order): source 000's
    /// needs exactly the devices loop and radar, source 001's ins, gnss and radar, in any
    /// order; the error names the devices the table needs and the ones there are.
    pub fn named(name: SharingName, devices: &[String]) -> Result<Self, String> {
        let (table, wanted): (Self, &[&str]) = match name {
            SharingName::Even => return Ok(Self::even(devices.len())),
            SharingName::Source000 => (Self::source_000(), &SOURCE_000_DEVICES),
            SharingName::Source001 => (Self::source_001(), &SOURCE_001_DEVICES),
        };
        let mut have: Vec<&str> = devices.iter().map(String::as_str).collect();
        have.sort_unstable();
        let mut need = wanted.to_vec();
        need.sort_unstable();
        if have != need {
            return Err(format!(
                "sharing = \"{}\" is for the devices {}, but this pipeline's devices are {}",
                name.key(),
                wanted.join(", "),
                devices.join(", ")
            ));
        }
        // The table's β in the pipeline's device order.
        let order: Vec<usize> = devices
            .iter()
            .map(|d| wanted.iter().position(|w| w == d).expect("the same names"))
            .collect();
        Ok(Self {
            bands: table
                .bands
                .into_iter()
                .map(|b| SpeedBand {
                    below_mps: b.below_mps,
                    beta: order.iter().map(|&i| b.beta[i]).collect(),
                })
                .collect(),
        })
    }

    pub fn even(devices: usize) -> Self {
        Self {
            bands: vec![SpeedBand {
                below_mps: f64::INFINITY,
                beta: vec![1.0 / devices as f64; devices],
            }],
        }
    }

    /// The table for `speed_mps` (its magnitude).
    pub fn at(&self, speed_mps: f64) -> &[f64] {
        let s = speed_mps.abs();
        let band = self
            .bands
            .iter()
            .find(|b| s < b.below_mps)
            .unwrap_or_else(|| self.bands.last().expect("a table has bands"));
        &band.beta
    }

    /// β at `speed_mps` with failed devices set to 0 and their share given to the healthy ones.
    /// All zero when no device is healthy.
    pub fn shares(&self, speed_mps: f64, healthy: &[bool], how: Redistribution) -> Vec<f64> {
        let base = self.at(speed_mps);
        let lost: f64 = base
            .iter()
            .zip(healthy)
            .filter(|(_, h)| !**h)
            .map(|(b, _)| b)
            .sum();
        let alive = healthy.iter().filter(|h| **h).count();
        let alive_sum: f64 = base
            .iter()
            .zip(healthy)
            .filter(|(_, h)| **h)
            .map(|(b, _)| b)
            .sum();
        base.iter()
            .zip(healthy)
            .map(|(&b, &h)| match (h, how) {
                (false, _) => 0.0,
                (true, Redistribution::Even) => b + lost / alive as f64,
                (true, Redistribution::Accuracy) if alive_sum > 0.0 => b / alive_sum,
                (true, Redistribution::Accuracy) => 1.0 / alive as f64,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_follow_the_source_and_failed_shares_are_redistributed() {
        let t = SharingTable::source_001();
        assert_eq!(t.at(40.0 / 3.6), &[0.6, 0.3, 0.1]);
        assert_eq!(t.at(-100.0 / 3.6), &[0.5, 0.4, 0.1]);
        assert_eq!(t.at(200.0 / 3.6), &[0.4, 0.4, 0.2]);
        let even = t.shares(100.0 / 3.6, &[true, false, true], Redistribution::Even);
        assert!(
            (even[0] - 0.7).abs() < 1e-12 && even[1] == 0.0 && (even[2] - 0.3).abs() < 1e-12,
            "{even:?}"
        );
        let acc = t.shares(100.0 / 3.6, &[true, false, true], Redistribution::Accuracy);
        assert!(
            (acc[0] - 0.5 / 0.6).abs() < 1e-12 && (acc[2] - 0.1 / 0.6).abs() < 1e-12,
            "{acc:?}"
        );
        assert_eq!(
            t.shares(10.0, &[false; 3], Redistribution::Even),
            vec![0.0; 3]
        );
        assert!((acc.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
