use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

use crate::geodesy::GeodeticOrigin;

/// A point of the track's centre line with its chainage, and where the map has them its
/// height and cant (see [`crate::track_profile`] for how they are read between vertices).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackVertex {
    /// Distance along the line in the plane (the alignment's kilometrage), m.
    pub chainage_m: f64,
    pub east_m: f64,
    pub north_m: f64,
    /// Height of the top of rail on the centre line, m up in the local east/north/up frame (the
    /// tangent plane at the origin, as east and north are). Absent: the map has no heights
    /// and the line is taken as flat.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
    /// Cant, m: how much higher the left rail is than the right, looking towards increasing
    /// chainage (a right-hand curve's cant is positive). Absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cant_m: Option<f64>,
}

impl TrackVertex {
    /// A vertex of a flat line without cant.
    pub fn at(chainage_m: f64, east_m: f64, north_m: f64) -> TrackVertex {
        TrackVertex {
            chainage_m,
            east_m,
            north_m,
            height_m: None,
            cant_m: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackBalise {
    pub balise_id: String,
    pub chainage_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Tunnel {
    pub name: String,
    pub start_chainage_m: f64,
    pub end_chainage_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Station {
    pub name: String,
    pub chainage_m: f64,
}

/// A stretch of track whose sleepers (rail clamps) lie at one nominal spacing: one page of
/// the "electromagnetic atlas" an eddy-current sensor's sleeper count is read against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SleeperSection {
    pub start_chainage_m: f64,
    pub end_chainage_m: f64,
    /// Mean distance between sleepers in the section, m (machine-laid track: 0.60–0.65).
    pub spacing_m: f64,
}

/// A switch (turnout): irregular sleepers and rails an eddy-current sensor sees as a
/// signature of its own, and a landmark that fixes the absolute position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackSwitch {
    pub name: String,
    pub start_chainage_m: f64,
    pub end_chainage_m: f64,
}

/// Another track of the map beside the main line (a parallel track through a station, a
/// loop line), its chainage on the main line's scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackLine {
    pub name: String,
    /// Vertices in increasing chainage.
    pub vertices: Vec<TrackVertex>,
}

/// The static track map: centre line as a polyline in local east/north around `origin`, with
/// chainage at every vertex, and the surveyed infrastructure. Written once, at the start of a
/// log, so the map travels inside the file. Map matching is in [`crate::map_matching`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackMap {
    pub stamp_ns: u64,
    pub name: String,
    pub origin: GeodeticOrigin,
    /// Vertices in increasing chainage.
    pub vertices: Vec<TrackVertex>,
    pub balises: Vec<TrackBalise>,
    pub tunnels: Vec<Tunnel>,
    pub stations: Vec<Station>,
    /// Sleeper (rail clamp) spacing, m.
    pub sleeper_spacing_m: f64,
    /// Distance between cross-induction loop crossings, m, where the line has a loop.
    #[serde(default)]
    pub loop_crossing_spacing_m: Option<f64>,
    /// Other tracks beside the main line (absent where there are none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub other_tracks: Vec<TrackLine>,
    /// The sleeper layout, section by section in increasing chainage (absent: one spacing,
    /// `sleeper_spacing_m`, everywhere).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sleeper_sections: Vec<SleeperSection>,
    /// Switches on the main line, in increasing chainage.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub switches: Vec<TrackSwitch>,
    /// The distance over which cant is measured (between the rails' running circles), m;
    /// absent: 1.5, standard gauge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cant_base_m: Option<f64>,
}

impl TrackMap {
    /// A map of the main line alone: these vertices, with nothing on or beside them (no
    /// balises, tunnels, stations, other tracks or switches) and sleepers every 0.6 m.
    pub fn line(name: &str, origin: GeodeticOrigin, vertices: Vec<TrackVertex>) -> TrackMap {
        TrackMap {
            stamp_ns: 0,
            name: name.to_owned(),
            origin,
            vertices,
            balises: vec![],
            tunnels: vec![],
            stations: vec![],
            sleeper_spacing_m: 0.6,
            loop_crossing_spacing_m: None,
            other_tracks: vec![],
            sleeper_sections: Vec::new(),
            switches: Vec::new(),
            cant_base_m: None,
        }
    }

    /// East, north and heading (clockwise from north) of the main line at a chainage,
    /// interpolated along the polyline; clamped to the ends.
    pub fn locate(&self, chainage_m: f64) -> Option<(f64, f64, f64)> {
        crate::map_matching::locate_on(&self.vertices, chainage_m)
    }

    /// Chainage of a GNSS fix on the main line, the fix's variance along the track (its ENU
    /// covariance turned onto the track heading), and the track heading. None for a fix
    /// without a position or off the line's ends.
    pub fn chainage_of_fix(&self, fix: &super::GnssFix) -> Option<(f64, Option<f64>, Option<f64>)> {
        let (e, n) = self.fix_east_north(fix)?;
        let (chainage, heading) = self.project(e, n)?;
        let variance = fix.position_covariance_enu_m2.map(|c| {
            let (ue, un) = (heading.sin(), heading.cos());
            ue * ue * c[0] + ue * un * (c[1] + c[3]) + un * un * c[4]
        });
        Some((chainage, variance, Some(heading)))
    }

    /// The signed distance of (east, north) from the main line, positive to the right of the
    /// direction of increasing chainage, m.
    pub fn lateral_offset(&self, east_m: f64, north_m: f64) -> Option<f64> {
        crate::map_matching::nearest_on(&self.vertices, 0..self.vertices.len(), east_m, north_m)
            .map(|m| m.lateral_m)
    }

    /// A fix's [`lateral_offset`](Self::lateral_offset); None for one without a position.
    pub fn lateral_of_fix(&self, fix: &super::GnssFix) -> Option<f64> {
        let (e, n) = self.fix_east_north(fix)?;
        self.lateral_offset(e, n)
    }

    /// Where a fix is in the map's east/north plane; None for one without a position.
    fn fix_east_north(&self, fix: &super::GnssFix) -> Option<(f64, f64)> {
        if !fix.fix_type.has_position() {
            return None;
        }
        let (lat, lon) = (fix.latitude_deg?, fix.longitude_deg?);
        let altitude = fix.altitude_m.unwrap_or(self.origin.altitude_m);
        let (e, n, _) = self.origin.to_enu(lat, lon, altitude);
        Some((e, n))
    }

    /// Chainage and track heading of the point of the main line nearest to (east, north): map
    /// matching of a position fix without memory (see [`crate::map_matching::MapMatcher`]
    /// for matching along a run). Clamped to the ends of the line.
    pub fn project(&self, east_m: f64, north_m: f64) -> Option<(f64, f64)> {
        let m = crate::map_matching::nearest_on(
            &self.vertices,
            0..self.vertices.len(),
            east_m,
            north_m,
        )?;
        Some((m.chainage_m, m.heading_rad))
    }

    /// The vertices of track `track`: 0 the main line, then the other tracks in order.
    pub fn track(&self, track: usize) -> Option<&[TrackVertex]> {
        match track {
            0 => Some(&self.vertices),
            i => self.other_tracks.get(i - 1).map(|t| t.vertices.as_slice()),
        }
    }

    /// How many tracks the map has, the main line included.
    pub fn track_count(&self) -> usize {
        1 + self.other_tracks.len()
    }

    /// Latitude and longitude (degrees) of the main line at a chainage.
    pub fn lat_lon_at(&self, chainage_m: f64) -> Option<(f64, f64)> {
        let (e, n, _) = self.locate(chainage_m)?;
        let (lat, lon, _) = self.origin.to_geodetic(e, n, 0.0);
        Some((lat, lon))
    }

    pub fn length_m(&self) -> f64 {
        self.vertices.last().map_or(0.0, |v| v.chainage_m)
    }

    /// The nominal sleeper spacing at a chainage: its section's, else the map's one spacing.
    pub fn sleeper_spacing_at(&self, chainage_m: f64) -> f64 {
        self.sleeper_sections
            .iter()
            .find(|s| (s.start_chainage_m..s.end_chainage_m).contains(&chainage_m))
            .map_or(self.sleeper_spacing_m, |s| s.spacing_m)
    }

    pub fn in_tunnel(&self, chainage_m: f64) -> Option<&Tunnel> {
        self.tunnels
            .iter()
            .find(|t| (t.start_chainage_m..=t.end_chainage_m).contains(&chainage_m))
    }
}

protobuf_form!(TrackMap {
    stamp_ns,
    name,
    origin,
    vertices,
    balises,
    tunnels,
    stations,
    sleeper_spacing_m,
    loop_crossing_spacing_m,
    other_tracks,
    sleeper_sections,
    switches,
    cant_base_m,
});
protobuf_form!(GeodeticOrigin {
    latitude_deg,
    longitude_deg,
    altitude_m
});
protobuf_form!(TrackVertex {
    chainage_m,
    east_m,
    north_m,
    height_m,
    cant_m
});
protobuf_form!(TrackBalise {
    balise_id,
    chainage_m
});
protobuf_form!(Tunnel {
    name,
    start_chainage_m,
    end_chainage_m
});
protobuf_form!(Station { name, chainage_m });
protobuf_form!(SleeperSection {
    start_chainage_m,
    end_chainage_m,
    spacing_m
});
protobuf_form!(TrackSwitch {
    name,
    start_chainage_m,
    end_chainage_m
});
protobuf_form!(TrackLine { name, vertices });
