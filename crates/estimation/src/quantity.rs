//! What a measurement measures along the track: chainage, speed or acceleration, each a
//! component of the motion state in that order.

use nalgebra::RowSVector;

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Quantity {
    Chainage,
    Speed,
    Acceleration,
}

impl Quantity {
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Chainage => "chainage",
            Quantity::Speed => "speed",
            Quantity::Acceleration => "acceleration",
        }
    }

    /// Its component of the state.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The observation row on an `N`-state, if the state holds this quantity.
    pub fn h<const N: usize>(self) -> Option<RowSVector<f64, N>> {
        (self.index() < N)
            .then(|| RowSVector::from_fn(|_, j| if j == self.index() { 1.0 } else { 0.0 }))
    }

    /// The row of the motion states a sensor of this quantity sees: [`h`](Self::h), and for a
    /// speed that is the mean over the window `W` before its stamp, `v − a W/2` (exact under
    /// the constant-acceleration model).
    pub fn motion_row<const N: usize>(
        self,
        speed_window_s: Option<f64>,
    ) -> Option<RowSVector<f64, N>> {
        let mut h = self.h::<N>()?;
        if let (Quantity::Speed, Some(w)) = (self, speed_window_s) {
            if Quantity::Acceleration.index() < N {
                h[Quantity::Acceleration.index()] = -w / 2.0;
            }
        }
        Some(h)
    }
}
