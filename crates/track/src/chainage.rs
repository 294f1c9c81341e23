//! The fitted line's chainage: its origin and direction, from the first run (0 where it
//! first lies on the line, increasing the way it travels) or from the line's own
//! kilometre posts (`--origin LAT,LON`, `--chainage-at LAT,LON=KM`, the latter up to twice:
//! two posts also set the direction).

use railfuse_catalog::messages::TrackVertex;
use serde::Serialize;

use crate::report::Centreline;

/// A place on the line given in the plane, and the chainage it has there, m.
#[derive(Debug, Clone, PartialEq)]
pub struct Post {
    pub east_m: f64,
    pub north_m: f64,
    pub chainage_m: f64,
    /// As the user gave it, for messages.
    pub label: String,
}

/// A post further than this from the line is not on it, m.
const MAX_POST_OFFSET_M: f64 = 50.0;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChainageError {
    #[error("{label} lies {offset_m:.1} m from the fitted line (beyond its ends or beside it; at most {MAX_POST_OFFSET_M} m)")]
    OffTheLine { label: String, offset_m: f64 },
    #[error(
        "at most two chainage posts (--origin, --chainage-at) set the chainage; {0} were given"
    )]
    TooMany(usize),
    #[error("the two chainage posts lie at the same place on the line")]
    SamePlace,
}

/// How the provisional chainage `s` maps to the line's: `at + direction (s − from)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Placement {
    pub from_m: f64,
    pub at_m: f64,
    pub direction: f64,
    /// With two posts: the distance between them along the fitted line less the one their
    /// chainages give, m (how far the line's posts are from its length).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub posts_disagree_m: Option<f64>,
}

impl Placement {
    pub fn chainage(&self, s: f64) -> f64 {
        self.at_m + self.direction * (s - self.from_m)
    }

    /// A provisional stretch `from`–`to` placed, its ends in increasing order.
    pub fn span(&self, from_m: f64, to_m: f64) -> (f64, f64) {
        let (a, b) = (self.chainage(from_m), self.chainage(to_m));
        (a.min(b), a.max(b))
    }
}

/// Where the line's chainage starts and which way it runs.
pub fn place(c: &Centreline, posts: &[Post]) -> Result<Placement, ChainageError> {
    let (start, increasing) = c.first_run_start;
    let direction = if increasing { 1.0 } else { -1.0 };
    let on_line = |p: &Post| -> Result<f64, ChainageError> {
        let m = c
            .line
            .locate(p.east_m, p.north_m, None)
            .filter(|m| !m.beyond_end && m.lateral_m.abs() <= MAX_POST_OFFSET_M);
        m.map(|m| m.chainage_m).ok_or_else(|| {
            let offset_m = c
                .line
                .vertices
                .iter()
                .map(|v| (v.east_m - p.east_m).hypot(v.north_m - p.north_m))
                .fold(f64::MAX, f64::min);
            ChainageError::OffTheLine {
                label: p.label.clone(),
                offset_m,
            }
        })
    };
    match posts {
        [] => Ok(Placement {
            from_m: start,
            at_m: 0.0,
            direction,
            posts_disagree_m: None,
        }),
        [p] => Ok(Placement {
            from_m: on_line(p)?,
            at_m: p.chainage_m,
            direction,
            posts_disagree_m: None,
        }),
        [p, q] => {
            let (sp, sq) = (on_line(p)?, on_line(q)?);
            if sp == sq || p.chainage_m == q.chainage_m {
                return Err(ChainageError::SamePlace);
            }
            let direction = ((sq - sp) * (q.chainage_m - p.chainage_m)).signum();
            Ok(Placement {
                from_m: sp,
                at_m: p.chainage_m,
                direction,
                posts_disagree_m: Some((sq - sp).abs() - (q.chainage_m - p.chainage_m).abs()),
            })
        }
        more => Err(ChainageError::TooMany(more.len())),
    }
}

/// `vertices` with their chainage placed, in order of increasing chainage.
pub fn placed(vertices: &[TrackVertex], p: &Placement) -> Vec<TrackVertex> {
    let mut out: Vec<TrackVertex> = vertices
        .iter()
        .map(|v| TrackVertex {
            chainage_m: p.chainage(v.chainage_m),
            ..*v
        })
        .collect();
    if p.direction < 0.0 {
        out.reverse();
    }
    out
}
