//! Estimators. The state and its covariance always travel together ([`StateAndCovariance`]).

mod kalman;

pub use kalman::{Innovation, KalmanFilter, StateAndCovariance};
